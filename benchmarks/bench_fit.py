"""Benchmark: multi-experiment physics fit on all training experiments of the default stand.

Budget (DESIGN §7): ≤ 120 s wall on 2 cores (median of 3). Also prints the RMSE of the
dither-period-mean pressure reached on the unseen medium ramp, default vs fitted model
(the fit never sees the medium ramp), and, with ``--decimation``, how the residual
decimation changes the fitted model's medium-ramp RMSE.

With ``--zoo``, the same fit (default settings, staged start, 120 s limit) is also run
on every plant of the zoo (``clutchlab stand --plant NAME``, seed ``--zoo-seed``), and a
table gives each plant's wall time, status, structure and medium-ramp RMSE beside the
default stand's.

Usage: ``python benchmarks/bench_fit.py [--runs 3] [--data DIR] [--decimation 1,10,50]
[--zoo [--zoo-seed 0] [--zoo-dir DIR]]``
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from clutchlab.data import dither_period_mean as period_mean
from clutchlab.data import dither_period_samples, load_dataset
from clutchlab.errors import FitError
from clutchlab.physics import CircuitModel, simulate
from clutchlab.physics.fit import FitSettings, PhysicsFitter
from clutchlab.physics.stand import StandConfig, write_stand
from clutchlab.validation import pressure_metrics


def medium_rmse(dataset, model, params) -> float:
    ys, yh = [], []
    for trace in dataset.select(ramps=["medium"]):
        n = dither_period_samples(trace)
        ys.append(period_mean(trace.get("clutch_pressure_bar"), n))
        yh.append(period_mean(simulate(model, params, trace).pressure_bar, n))
    return pressure_metrics(np.concatenate(ys), np.concatenate(yh))["rmse_bar"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--data", default="bench-stand", help="stand dataset (written if absent)")
    ap.add_argument("--method", default=None, help="single_shooting or multiple_shooting")
    ap.add_argument("--decimation", default="", help="comma-separated decimations to compare")
    ap.add_argument("--zoo", action="store_true", help="also fit every plant of the zoo")
    ap.add_argument("--zoo-seed", type=int, default=0, help="seed of the zoo's units")
    ap.add_argument("--zoo-dir", default="bench-zoo", help="zoo datasets (written if absent)")
    args = ap.parse_args()

    data = Path(args.data)
    if not (data / "manifest.json").exists():
        write_stand(data, StandConfig(), progress=False, overwrite=True)
    ds = load_dataset(data)
    train = ds.select(ramps=["fast", "slow"])
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    )
    print(
        f"training: {len(train)} experiments, {sum(len(t) for t in train)} samples "
        f"({sum(t.duration_s for t in train):.0f} s at 1 kHz); test: medium ramp"
    )
    kw = {"progress": False} | ({"method": args.method} if args.method else {})
    walls, res = [], None
    for _ in range(args.runs):
        t0 = time.perf_counter()
        try:
            res = PhysicsFitter(settings=FitSettings(**kw)).fit(ds).result_
        except FitError as exc:  # not converged: report it, score the best iterate
            res = exc.result
            print(f"run did not converge: {exc}")
        walls.append(time.perf_counter() - t0)
    rmse_default = medium_rmse(ds, CircuitModel(), None)
    rmse_fit = medium_rmse(ds, res.model(), res.params())
    med = statistics.median(walls)
    print(f"\nfit wall times (s): {', '.join(f'{w:.1f}' for w in walls)}")
    print(
        f"median {med:.1f} s  (budget 120 s; ratio {med / 120:.2f}): "
        f"{'PASS' if med <= 120 else 'FAIL'}"
    )
    print(f"status: {res.status}; Jacobian evaluations: {len(res.cost_history)}")
    print(
        f"medium-ramp RMSE (dither-period mean): default {rmse_default:.4f} bar, fitted "
        f"{rmse_fit:.4f} bar, reduction {100 * (1 - rmse_fit / rmse_default):.1f} %"
    )
    print("\n" + res.table())
    if args.decimation:
        print(f"\n{'decimate':>8s} {'wall (s)':>9s} {'medium RMSE (bar)':>18s}")
        for d in (int(x) for x in args.decimation.split(",")):
            t0 = time.perf_counter()
            try:
                r = PhysicsFitter(settings=FitSettings(**kw, decimate=d)).fit(ds).result_
            except FitError as exc:
                r = exc.result
            wall = time.perf_counter() - t0
            print(f"{d:8d} {wall:9.1f} {medium_rmse(ds, r.model(), r.params()):18.4f}")
    if args.zoo:
        zoo_rows(args, kw, ("stand", med, res, rmse_default, rmse_fit))


def zoo_rows(args, kw, stand_row) -> None:
    """One fit per zoo plant (seed ``--zoo-seed``); a table beside the stand's median run."""
    import warnings

    from clutchlab.errors import FitWarning
    from clutchlab.physics.stand.plants import PlantConfig, plant_names

    rows = [stand_row]
    for name in plant_names():
        data = Path(args.zoo_dir) / f"{name}_s{args.zoo_seed}"
        if not (data / "manifest.json").exists():
            write_stand(data, PlantConfig(name, seed=args.zoo_seed), progress=False, overwrite=True)
        zds = load_dataset(data)
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FitWarning)
            res = PhysicsFitter(settings=FitSettings(**kw, time_limit_s=120.0)).fit(zds).result_
        wall = time.perf_counter() - t0
        rows.append(
            (
                name,
                wall,
                res,
                medium_rmse(zds, CircuitModel(), None),
                medium_rmse(zds, res.model(), res.params()),
            )
        )
    print(
        f"\n{'circuit':22s} {'wall (s)':>8s} {'default':>8s} {'fitted':>8s} {'ratio':>6s}  "
        "structure / status"
    )
    for name, wall, res, d, f in rows:
        structure = ",".join(res.effects) or "base"
        print(f"{name:22s} {wall:8.1f} {d:8.4f} {f:8.4f} {f / d:6.2f}  {structure} / {res.status}")


if __name__ == "__main__":
    main()
