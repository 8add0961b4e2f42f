"""Benchmark: design-sweep throughput (points/s) with 1 and 2 local workers, and their ratio.

Spec: ``examples/sweep_vfs_design.toml`` (fast stand ramp + a 300 → 700 mA step per point,
six design variables, Latin hypercube) with ``--points`` points. Each run is a complete
``run_sweep`` into a fresh results file (worker start-up, storage and consolidation
included, figures excluded); medians over ``--runs`` runs after one warm-up. Also prints the
per-point cost (median wall and CPU seconds of one point inside a worker) and what a
10⁵-point study takes on N workers at the measured 2-worker efficiency.

Usage: ``python benchmarks/bench_sweep.py [--runs 3] [--points 200]``
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import statistics
import tempfile
from pathlib import Path

from clutchlab.physics.design import SamplingSpec, load_spec, run_sweep

SPEC = Path(__file__).resolve().parents[1] / "examples" / "sweep_vfs_design.toml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--points", type=int, default=200)
    ap.add_argument("--spec", default=str(SPEC))
    args = ap.parse_args()

    spec = load_spec(args.spec)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
        f", load average {os.getloadavg()[0]:.1f} at start"
    )
    print(
        f"spec: {args.spec}, {args.points} points, scenario ramps "
        f"{[r.label for r in spec.scenario.ramps]}, step {spec.scenario.step is not None}"
    )
    results: dict[int, list[float]] = {1: [], 2: []}
    share: dict[int, list[float]] = {1: [], 2: []}
    cpu_w: dict[int, list[float]] = {1: [], 2: []}
    wall_pt: list[float] = []
    cpu_pt: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        for run in range(args.runs + 1):  # run 0: warm-up (compiled model cache, imports)
            for workers in (1, 2):
                # A different seed per run: nothing is skipped, no caching across runs.
                s = dataclasses.replace(spec, sampling=SamplingSpec("lhs", args.points, run))
                out = Path(tmp) / f"w{workers}_r{run}.parquet"
                res = run_sweep(s, out, workers=workers, progress=False, figures=False)
                if res.n_failed:
                    print(f"  note: {res.n_failed} failed points in run {run}")
                if run == 0:
                    continue
                results[workers].append(res.points_per_s)
                # CPU the workers got: Σ CPU-s of the points / (wall · workers).
                share[workers].append(res.table["cpu_s"].sum() / (res.wall_s * workers))
                cpu_w[workers] += list(res.table["cpu_s"])
                wall_pt += list(res.table["wall_s"])
                cpu_pt += list(res.table["cpu_s"])
                print(
                    f"  run {run} workers {workers}: {res.wall_s:6.2f} s, "
                    f"{res.points_per_s:5.2f} points/s, workers busy {share[workers][-1]:.0%} "
                    "of their wall time"
                )
    med = {w: statistics.median(v) for w, v in results.items()}
    ratio = med[2] / med[1]
    print(f"\nmedian throughput, 1 worker : {med[1]:.2f} points/s")
    print(f"median throughput, 2 workers: {med[2]:.2f} points/s")
    print(f"ratio 2 / 1 workers         : {ratio:.2f} (ideal 2.00)")
    for w in (1, 2):
        print(
            f"workers {w}: median CPU per point {statistics.median(cpu_w[w]):.3f} s, "
            f"median busy share {statistics.median(share[w]):.0%} (100 % = a core each)"
        )
    c_wall, c_cpu = statistics.median(wall_pt), statistics.median(cpu_pt)
    print(f"per point (median, inside a worker): {c_wall:.3f} s wall, {c_cpu:.3f} s CPU")
    eff = min(ratio / 2.0, 1.0)
    print(f"\n10^5 points at {c_cpu:.3f} CPU-s per point (T = 1e5 · c / (N · e)):")
    print(f"  {'workers':>8s} {'e = 1 (idle cores)':>20s} {f'e = {eff:.2f} (measured)':>22s}")
    for n in (1, 2, 8, 32, 128):
        ideal = 1e5 * c_cpu / n
        real = ideal / (eff if n > 1 else 1.0)
        print(f"  {n:8d} {ideal / 3600:18.2f} h {real / 3600:20.2f} h")


if __name__ == "__main__":
    main()
