"""Benchmark: load a 10⁶-sample experiment from CSV, Parquet and MF4 through load_dataset.

Budgets (issue 3): CSV ≤ 2 s, MF4 ≤ 1 s (median load time); Parquet is reported for
comparison. The trace is stand-like: 1000 s at 1 kHz, every canonical signal (dithered,
noisy, quantized current; command; dither amplitude and frequency; clutch, line and prime
pressure; oil temperature). "Load" is the user's path: manifest, decoding, every validation
check, Trace construction. Prints medians over ``--runs`` runs (after one warm-up).

Usage: ``python benchmarks/bench_io.py [--runs 5] [--samples 1000000]``
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from clutchlab.data import Dataset, Trace, load_dataset, save_dataset
from clutchlab.data.demodulate import demodulate_dither

BUDGETS_S = {"csv": 2.0, "parquet": None, "mf4": 1.0}


def stand_like_trace(n: int, seed: int = 0) -> Trace:
    """``n`` samples at 1 kHz of stand-like signals in canonical units."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    cmd = 550.0 - 550.0 * np.cos(2 * np.pi * t / 50.0)  # 0 → 1100 → 0 mA every 50 s
    amp = 25.0 + 200.0 * cmd / 1100.0
    current = cmd + amp * np.sin(2 * np.pi * 50.0 * t) + rng.normal(0, 2.0, n)
    pressure = np.clip(cmd / 1100.0 * 17.7, 0.0, None) + rng.normal(0, 0.025, n)
    signals = {
        "time_s": t,
        "current_mA": np.round(current / 0.5) * 0.5,
        "current_cmd_mA": cmd,
        "dither_amp_mA": amp,
        "dither_freq_Hz": np.full(n, 50.0),
        "clutch_pressure_bar": np.round(pressure, 2),
        "line_pressure_bar": np.round(17.7 + rng.normal(0, 0.1, n), 2),
        "prime_pressure_bar": np.round(0.5 + rng.normal(0, 0.04, n), 3),
        "oil_temp_C": np.round(55.0 + rng.normal(0, 0.1, n), 1),
    }
    return Trace("bench", signals, meta={"ramp": "medium", "dither_freq_Hz": 50})


def median_wall(fn, runs: int) -> float:
    fn()  # warm-up (imports, page cache)
    walls = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        walls.append(time.perf_counter() - t0)
    return statistics.median(walls)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--samples", type=int, default=1_000_000)
    args = ap.parse_args()
    if args.runs < 3:
        ap.error("--runs must be at least 3")

    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}"
    )
    trace = stand_like_trace(args.samples)
    print(
        f"trace: {len(trace)} samples ({trace.duration_s:.0f} s at 1 kHz), "
        f"{len(trace.signals)} signals; median of {args.runs} runs after one warm-up\n"
    )
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for fmt, budget in BUDGETS_S.items():
            root = Path(tmp) / fmt
            t0 = time.perf_counter()
            save_dataset(Dataset([trace]), root, format=fmt)
            write_s = time.perf_counter() - t0
            size = sum(p.stat().st_size for p in root.iterdir()) / 1e6
            loaded = load_dataset(root)[0]
            assert len(loaded) == len(trace) and loaded.signals.keys() == trace.signals.keys()
            wall = median_wall(lambda r=root: load_dataset(r), args.runs)
            rows.append((fmt, size, write_s, wall, budget))
        demod = median_wall(
            lambda: demodulate_dither(trace.get("current_mA"), 1000.0), max(args.runs // 2, 3)
        )

    print(f"{'format':8s} {'file MB':>8s} {'write s':>8s} {'load median s':>14s} {'budget s':>9s}"
          f" {'ratio':>6s}")  # fmt: skip
    ok = True
    for fmt, size, write_s, wall, budget in rows:
        ratio = f"{wall / budget:6.2f}" if budget else f"{'-':>6s}"
        print(
            f"{fmt:8s} {size:8.1f} {write_s:8.2f} {wall:14.3f} "
            f"{budget if budget else '-':>9} {ratio}"
        )
        ok &= budget is None or wall <= budget
    print(f"\ndither demodulation of the {len(trace)}-sample current: median {demod:.2f} s")
    print(f"\nload budgets (CSV <= 2 s, MF4 <= 1 s): {'PASS' if ok else 'FAIL'}")


if __name__ == "__main__":
    main()
