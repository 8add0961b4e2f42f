"""Benchmark: simulate the medium ramp with resolved dither; real-time factor.

Budget (DESIGN §7): ≥ 50× faster than real time on a 2-core machine (aim 200×).
Anchor: real time (the trace's duration). Prints medians over ``--runs`` runs.

Usage: ``python benchmarks/bench_simulate.py [--runs 7] [--substeps 4]``
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

from clutchlab.physics import CircuitModel, SimulationSettings, simulate
from clutchlab.physics.stand import DitherSetting, StandConfig, run_stand


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--substeps", type=int, default=4)
    args = ap.parse_args()

    stand = run_stand(StandConfig(settings=(DitherSetting(50.0, "B"),)), progress=False)
    trace = stand.dataset["medium_50Hz_B"]
    duration = trace.duration_s
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}"
    )
    print(
        f"trace: {trace.name}, {duration:.1f} s at {trace.sample_rate_Hz:.0f} Hz "
        f"({len(trace)} samples), dither {trace.meta['dither_freq_Hz']:g} Hz resolved"
    )
    rows = []
    for label, model in (("base model", CircuitModel()), ("stand model (3 effects)", stand.model)):
        for drive in ("measured", "command"):
            settings = SimulationSettings(drive=drive, substeps=args.substeps)
            simulate(model, None, trace, settings)  # compile (cached) and warm up
            walls = []
            for _ in range(args.runs):
                t0 = time.perf_counter()
                simulate(model, None, trace, settings)
                walls.append(time.perf_counter() - t0)
            med = statistics.median(walls)
            rows.append((label, drive, med, duration / med))
    print(f"\n{'model':26s} {'drive':9s} {'median wall (s)':>16s} {'x real time':>12s}")
    for label, drive, med, rtf in rows:
        print(f"{label:26s} {drive:9s} {med:16.4f} {rtf:12.1f}")
    worst = min(r[3] for r in rows)
    print(
        f"\nworst real-time factor {worst:.1f}x (budget >= 50x, aim 200x): "
        f"{'PASS' if worst >= 50 else 'FAIL'}"
    )


if __name__ == "__main__":
    main()
