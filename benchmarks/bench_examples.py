"""Benchmark: the four example scripts on a small stand dataset, all together ≤ 60 s.

Issue 19 must-show 4. Runs ``tests/test_examples.py`` (which executes each script as a user
would, in a subprocess, and checks its output) in one process, ``--runs`` times, reads each
script's wall time from the module (``CLUTCHLAB_EXAMPLE_TIMES``) and prints per-script medians
and the sum against the budget. Anchor: the budget itself.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BUDGET_S = 60.0


def one_run() -> dict[str, float]:
    with tempfile.TemporaryDirectory() as tmp:
        times = Path(tmp) / "times.json"
        res = subprocess.run(
            [sys.executable, "-m", "pytest", "-n", "0", "-q", "tests/test_examples.py"],
            cwd=ROOT,
            env={**os.environ, "CLUTCHLAB_EXAMPLE_TIMES": str(times)},
            capture_output=True,
            text=True,
        )
        if res.returncode != 0:
            sys.exit(f"the examples failed:\n{res.stdout[-3000:]}\n{res.stderr[-2000:]}")
        return json.loads(times.read_text(encoding="utf-8"))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    )
    runs = [one_run() for _ in range(args.runs)]
    names = sorted(runs[0])
    print(f"{'example':40s} {'median s':>9s}  runs")
    for name in names:
        values = [r[name] for r in runs]
        shown = ", ".join(f"{v:.1f}" for v in values)
        print(f"{name:40s} {statistics.median(values):9.2f}  {shown}")
    totals = [sum(r.values()) for r in runs]
    total = statistics.median(totals)
    verdict = "PASS" if total <= BUDGET_S else "FAIL"
    print(
        f"all four: median {total:.2f} s (runs {', '.join(f'{t:.1f}' for t in totals)}); "
        f"budget {BUDGET_S:g} s, ratio {total / BUDGET_S:.2f}: {verdict}"
    )
    return 0 if verdict == "PASS" else 1


if __name__ == "__main__":
    sys.exit(main())
