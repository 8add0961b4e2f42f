"""Closing the loop at one pre-declared effect size, for every library effect (issue 7).

Each library effect is switched on at the discovery stand at the size fixed by
:func:`clutchlab.validation.discover.effect_size.calibrate_effect_size` — the strength at
which it changes the training ramps' period-mean clutch pressure by 0.10 bar RMS (or its
bound) — computed from the stand's truth alone, before any discovery. Then ``discover``
runs with the base model (at most one effect), exactly as ``tests/test_discover_effects.py``
does. Printed per effect: its calibrated size, the effect named first, the winner and
runner-up of the score test, the RMSE before → after on the training ramps and on the
unseen medium ramp, and whether the case passes must-show 1 of issue 7 (named first and
medium RMSE at most half). Every effect is reported, pass or fail.

The rule (module :mod:`~clutchlab.validation.discover.effect_size`) and this script were
committed before either had been run on any discovery; nothing here is chosen on results.

Usage::

    python studies/discover_effect_size.py [--effects a,b] [--json OUT] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
from pathlib import Path

from clutchlab.physics.effects import EFFECTS
from clutchlab.validation.discover import DiscoverySettings
from clutchlab.validation.discover.scenarios import run_sized_case


def run_effect(effect: str, keep: Path | None = None) -> dict:
    """Calibrate ``effect``'s size, run the discovery case, return its measured row
    (and write the discovery's full evidence to ``keep / EFFECT.discover.json``)."""
    res, row = run_sized_case(effect, settings=DiscoverySettings(progress=False))
    if keep is not None:
        keep.mkdir(parents=True, exist_ok=True)
        res.to_json(keep / f"{effect}.discover.json")
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--effects", default="", help="comma-separated subset (default: all)")
    ap.add_argument("--json", help="write the rows here (rewritten after each effect)")
    ap.add_argument("--keep", type=Path, help="write each discovery's JSON evidence here")
    args = ap.parse_args()
    wanted = [e for e in args.effects.split(",") if e] or sorted(EFFECTS)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    )
    print(
        "| effect | size (calibrated) | RMS change, training (bar) | named first | winner "
        "(statistic / share) | runner-up | train RMSE (bar) | medium RMSE (bar) | drop | "
        "passes | wall (s) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    for effect in wanted:
        row = run_effect(effect, args.keep)
        rows.append(row)
        if args.json:
            with open(args.json, "w", encoding="utf-8") as f:
                json.dump(rows, f, indent=2)
        size = row["size"]
        truth = ", ".join(f"{k} = {v:.4g}" for k, v in size["overrides"].items())
        truth += " (bound)" if size["at_bound"] else ""
        w, r = row["winner"], row["runner_up"]
        winner = f"{w[0]} {w[1]:.1f} / {w[2]:.2f}" if w else "—"
        runner = f"{r[0]} {r[1]:.1f} / {r[2]:.2f}" if r else "—"
        tr, te = row["train_rmse_bar"], row["test_rmse_bar"]
        print(
            f"| {effect} | {truth} | {size['rms_bar']:.3f} | {row['named_first'] or '—'} | "
            f"{winner} | {runner} | {tr[0]:.4f} → {tr[1]:.4f} | "
            f"{te[0]:.4f} → {te[1]:.4f} | {row['test_drop_pct']:.0f} % | "
            f"{'yes' if row['passes'] else 'no'} | {row['wall_with_calibration_s']:.0f} |",
            flush=True,
        )
    print(f"passing: {sum(r['passes'] for r in rows)} of {len(rows)}")


if __name__ == "__main__":
    main()
