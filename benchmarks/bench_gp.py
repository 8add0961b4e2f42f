"""Benchmark: local GP and the paper pipeline against their budgets (DESIGN §7).

1. ``LocalGPRegressor`` against scikit-learn's ``GaussianProcessRegressor`` on identical
   points (n = 4000 training samples drawn from the fast + slow ramps, features I, A_d, f_d,
   dI/dt standardized, target the dither-period-mean clutch pressure), same kernel family
   and bounds (constant × RBF with per-input length scales + white noise, and constant ×
   isotropic rational quadratic + white noise), one optimizer start each; the local GP with
   its default (random) marginal-likelihood blocks and with ``block_assignment="auto"``.
   Test RMSE on 4000 other training-ramp samples. Budget: fit-time ratio ≤ 0.2 at RMSE ratio ≤ 1.05.
2. The whole ``paper_svc_gp`` pipeline (features, labels, classifier, two GPs) on all
   training samples (~8·10⁵): ≤ 60 s.
3. Batch prediction along traces (all 27 experiments, ~10⁶ samples): ≥ 10⁶ samples/s.
4. Single-sample prediction (``step_predictor``): ≤ 50 µs median.

Prints medians over ``--runs`` runs and the ratios against the anchors measured in the same
run. Usage: ``python benchmarks/bench_gp.py [--runs 3] [--data DIR] [--sk-runs 1]``
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
import warnings
from pathlib import Path

import numpy as np

from clutchlab.data import load_dataset
from clutchlab.physics.stand import StandConfig, write_stand
from clutchlab.residual_ml import (
    DIDT_FEATURES,
    FeatureBuilder,
    LocalGPRegressor,
    SVCPartitionedGP,
    step_predictor,
    target_pressure,
)


def _median_time(fn, runs: int):
    times, out = [], None
    for _ in range(runs):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def gp_vs_sklearn(train, runs: int, sk_runs: int, n: int = 4000) -> None:
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, RationalQuadratic, WhiteKernel
    from sklearn.gaussian_process.kernels import ConstantKernel as C

    fb = FeatureBuilder(DIDT_FEATURES[:4])
    X = np.concatenate([fb.build(t) for t in train])
    y = np.concatenate([target_pressure(t) for t in train])
    rng = np.random.default_rng(0)
    idx = rng.choice(X.shape[0], 2 * n, replace=False)
    tr, te = idx[:n], idx[n:]
    mu, sd = X[tr].mean(axis=0), X[tr].std(axis=0)
    Xs_tr, Xs_te = (X[tr] - mu) / sd, (X[te] - mu) / sd
    d = X.shape[1]
    print(f"\n1. LocalGPRegressor vs sklearn GaussianProcessRegressor, n = {n} (d = {d})")
    cases = [
        (
            "RBF, per-input length scales",
            C(1.0, (1e-3, 1e3)) * RBF(np.ones(d), (1e-2, 1e3)) + WhiteKernel(1e-2, (1e-8, 10)),
            {"kernel": "rbf", "ard": True},
        ),
        (
            "rational quadratic, isotropic",
            C(1.0, (1e-3, 1e3)) * RationalQuadratic(1.0, 1.0, (1e-2, 1e3), (1e-2, 1e3))
            + WhiteKernel(1e-2, (1e-8, 10)),
            {"kernel": "rq", "ard": False},
        ),
    ]
    for label, sk_kernel, ours in cases:
        sk = GaussianProcessRegressor(sk_kernel, normalize_y=True, n_restarts_optimizer=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t_sk, sk = _median_time(lambda sk=sk: sk.fit(Xs_tr, y[tr]), sk_runs)
        gp = LocalGPRegressor(**ours, random_state=0)
        t_gp, gp = _median_time(lambda gp=gp: gp.fit(Xs_tr, y[tr]), runs)
        rmse_sk = float(np.sqrt(np.mean((sk.predict(Xs_te) - y[te]) ** 2)))
        rmse_gp = float(np.sqrt(np.mean((gp.predict(Xs_te) - y[te]) ** 2)))
        print(f"  {label}:")
        print(f"    sklearn  fit {t_sk:8.2f} s (median of {sk_runs})  test RMSE {rmse_sk:.4f} bar")
        print(
            f"    local GP fit {t_gp:8.2f} s (median of {runs})  test RMSE {rmse_gp:.4f} bar"
            f"  ({gp.n_bins_} bins)"
        )
        print(
            f"    fit-time ratio {t_gp / t_sk:.3f} (budget ≤ 0.2)   "
            f"RMSE ratio {rmse_gp / rmse_sk:.3f} (budget ≤ 1.05)"
        )
        auto = LocalGPRegressor(**ours, block_assignment="auto", random_state=0)
        t_au, auto = _median_time(lambda auto=auto: auto.fit(Xs_tr, y[tr]), runs)
        rmse_au = float(np.sqrt(np.mean((auto.predict(Xs_te) - y[te]) ** 2)))
        print(
            f"    local GP, block_assignment='auto' (chose {auto.block_assignment_}): fit "
            f"{t_au:.2f} s, test RMSE {rmse_au:.4f} bar; fit-time ratio {t_au / t_sk:.3f}, "
            f"RMSE ratio {rmse_au / rmse_sk:.3f}"
        )


def pipeline(train, everything, runs: int) -> SVCPartitionedGP:
    n_train = sum(len(t) for t in train)
    print(
        f"\n2. paper_svc_gp pipeline on all {n_train} training samples ({len(train)} experiments)"
    )
    t_fit, model = _median_time(lambda: SVCPartitionedGP().fit(train), runs)
    print(f"    fit {t_fit:.2f} s (median of {runs}); budget ≤ 60 s, ratio {t_fit / 60:.2f}")
    n_all = sum(len(t) for t in everything)
    model.predict(everything[0])  # warm-up
    t_pred, _ = _median_time(lambda: [model.predict(t) for t in everything], runs)
    rate = n_all / t_pred
    print(f"\n3. batch prediction along {len(everything)} traces, {n_all} samples")
    print(
        f"    {t_pred:.3f} s (median of {runs}) = {rate / 1e6:.2f}·10⁶ samples/s; "
        f"budget ≥ 10⁶/s, ratio {rate / 1e6:.2f}"
    )
    return model


def single(model, trace, calls: int = 20000) -> None:
    step = step_predictor(model)
    F = model._trace_matrix(trace)
    pick = np.linspace(0, len(F) - 1, calls).astype(int)
    rows, line = F[pick], trace.get("line_pressure_bar")[pick]
    for x, v in zip(rows[:100], line[:100], strict=True):
        step(x, v)
    times = np.empty(calls)
    for k, (x, v) in enumerate(zip(rows, line, strict=True)):
        t0 = time.perf_counter()
        step(x, v)
        times[k] = time.perf_counter() - t0
    med = float(np.median(times)) * 1e6
    ref = {"ref": line[:500]} if step.latched_line else {}

    def ref_of(v):
        return {"ref": np.array([v])} if step.latched_line else {}

    exact = model._predict_matrix(rows[:500], path=False, return_std=False, **ref)
    steps = np.array([step(x, v) for x, v in zip(rows[:500], line[:500], strict=True)])
    print(f"\n4. single-sample prediction (step_predictor), {calls} calls")
    print(
        f"    median {med:.1f} µs, p90 {np.percentile(times, 90) * 1e6:.1f} µs; budget ≤ 50 µs, "
        f"ratio {med / 50:.2f}; max |step − batch| {np.abs(exact - steps).max():.2e} bar"
    )
    t1 = []
    for x, v in zip(rows[:200], line[:200], strict=True):
        t0 = time.perf_counter()
        model._predict_matrix(x[None, :], path=False, return_std=False, **ref_of(v))
        t1.append(time.perf_counter() - t0)
    print(
        "    (for comparison: the batch path on a 1-row array, median "
        f"{np.median(t1) * 1e6:.0f} µs)"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--sk-runs", type=int, default=1, help="runs of the (slow) sklearn fit")
    ap.add_argument("--data", default="bench-stand", help="stand dataset (written if absent)")
    ap.add_argument("--skip-sklearn", action="store_true")
    args = ap.parse_args()
    data = Path(args.data)
    if not (data / "manifest.json").exists():
        write_stand(data, StandConfig(), progress=False, overwrite=True)
    t0 = time.perf_counter()
    ds = load_dataset(data)
    t_load = time.perf_counter() - t0
    train = list(ds.select(ramps=["fast", "slow"]))
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, load average {os.getloadavg()[0]:.1f}"
    )
    print(f"dataset {data}: {len(ds)} experiments, loaded in {t_load:.2f} s")
    if not args.skip_sklearn:
        gp_vs_sklearn(train, args.runs, args.sk_runs)
    model = pipeline(train, list(ds), args.runs)
    single(model, ds.by_ramp("medium")[0])


if __name__ == "__main__":
    main()
