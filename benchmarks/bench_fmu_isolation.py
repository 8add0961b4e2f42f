"""Benchmark: the cost of running an imported FMU isolated in a child process (the default).

Anchor: the same FMU in this process, same run. The Reference FMU ``Feedthrough``
(``../shared/third_party``) on a medium-ramp stand trace (23 s at 1 kHz), and optionally an
FMU exported by clutchlab (``--fmu``). Prints the median wall time of each and the ratio.

Usage: ``python benchmarks/bench_fmu_isolation.py [--runs 7]``
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from pathlib import Path

from clutchlab.physics.fmu import FmuPhysics
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

FEEDTHROUGH = Path(__file__).resolve().parents[1].parent / "shared/third_party/Feedthrough.fmu"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=7)
    args = ap.parse_args()
    config = StandConfig(
        settings=(DitherSetting(50.0, "B"),), ramps=(RampProfile("medium", 10.0, 1.0),)
    )
    trace = run_stand(config, progress=False).dataset[0]
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    )
    print(f"FMU: {FEEDTHROUGH.name}; trace {trace.name}: {len(trace)} samples")
    kw = {
        "input_map": {"Float64_continuous_input": "current_mA"},
        "output": "Float64_continuous_output",
    }
    medians = {}
    for isolate in (False, True):
        physics = FmuPhysics(FEEDTHROUGH, isolate=isolate, **kw)
        physics.predict(trace)  # warm-up: extraction cache, library load
        times = []
        for _ in range(args.runs):
            t0 = time.perf_counter()
            physics.predict(trace)
            times.append(time.perf_counter() - t0)
        medians[isolate] = statistics.median(times)
        label = "isolated (forked child)" if isolate else "in process (anchor)"
        print(f"{label:26s} median {medians[isolate] * 1000:8.1f} ms over {args.runs} runs")
    extra = medians[True] - medians[False]
    print(
        f"ratio isolated / in process: {medians[True] / medians[False]:.2f} "
        f"(+{extra * 1000:.1f} ms per experiment)"
    )


if __name__ == "__main__":
    main()
