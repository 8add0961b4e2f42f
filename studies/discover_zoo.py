"""Closing the loop on the stand and the zoo's plants: false positives on data with no added
effect, and the oil-temperature drift / line-pressure coupling a plant's own equations carry
(issue 17, must-shows 4 and 5).

For every plant (``--plants``: the default stand and / or the zoo's plants) and seed, write
the dataset of the case, run ``clutchlab discover`` on it (its own baseline fit, the whole
library as candidates) and check what it claims:

* ``null``: the stand without its built-in effects (the base model plus the stand's noise,
  quantization, line-pressure wander and resolved dither: nothing the base model lacks) and
  every zoo plant as built (its own equations, no library effect added). Any claimed effect
  is a false positive.
* ``oil_drift``: a zoo plant with its oil_temperature law on and the oil warming from 40 to
  85 °C through every run (``--effects oil_temperature --temperature drift``). Passes when
  oil_temperature is named first with a medium-ramp RMSE drop of at least 50 %, or nothing
  is added and the residual is reported unexplained following ``oil_temp_C``.
* ``line_coupling``: a zoo plant with its supply_droop law on (line-pressure coupling).
  Passes when supply_droop is named first with a drop of at least 50 %, or unexplained
  following ``line_pressure_bar``.

Naming any other library effect fails. Prints the rule first, then one row per dataset and
the count; writes every discovery's JSON (the evidence per candidate, with the held-out
error of each training experiment) and ``CASE.json`` / ``CASE.md`` to ``--out``. Datasets
and discoveries already in ``--out`` are reused, so an interrupted study resumes.

Usage: ``python studies/discover_zoo.py --case null --out DIR [--seeds 0,1,2,3]
[--plants all] [--settings 3]``
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

RULES = {
    "null": """\
Rule (issue 17, must-show 4): over >= 20 datasets with no added effect, at most 1 claimed
effect in all. A dataset's claims are the effects `clutchlab discover` adds (its JSON's
"added"). "Unexplained" (a residual that follows a signal, no effect named) is not a claim.""",
    "oil_drift": """\
Rule (issue 17, must-show 5, oil-temperature drift): on each zoo plant, oil_temperature named
first with a medium-ramp RMSE drop >= 50 %, or nothing added and "unexplained" naming
oil_temp_C; never another library effect.""",
    "line_coupling": """\
Rule (issue 17, must-show 5, line-pressure coupling): on each zoo plant, supply_droop named
first with a medium-ramp RMSE drop >= 50 %, or nothing added and "unexplained" naming
line_pressure_bar; never another library effect.""",
}

#: Per case: the stand's extra arguments and (effect, signal) a pass may name.
CASES = {
    "null": ([], None),
    "oil_drift": (
        ["--effects", "oil_temperature", "--temperature", "drift"],
        ("oil_temperature", "oil_temp_C"),
    ),
    "line_coupling": (["--effects", "supply_droop"], ("supply_droop", "line_pressure_bar")),
}


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "clutchlab", *args]


def _run(cmd: list[str]) -> tuple[int, float, str]:
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True)
    return res.returncode, time.perf_counter() - t0, res.stdout + res.stderr


def dataset(case: str, plant: str, seed: int, settings: int, work: Path) -> Path:
    """Write (or reuse) the dataset of ``case`` for ``plant`` and ``seed``."""
    data = work / f"{plant}_s{seed}"
    if (data / "manifest.json").exists():
        return data
    args = ["stand", "--plant", plant, "--seed", str(seed), "--settings", str(settings)]
    if plant == "stand" and case == "null":
        args.append("--no-builtin")
    code, _, out = _run(_cli(*args, *CASES[case][0], "--out", str(data), "--quiet"))
    if code:
        raise SystemExit(f"stand {plant} seed {seed} failed:\n{out}")
    return data


def verdict(case: str, row: dict) -> bool:
    """Whether one dataset's discovery passes the case's rule."""
    match = CASES[case][1]
    if match is None:
        return not row["added"]
    effect, signal = match
    if row["added"]:
        return row["added"][0] == effect and row["test_drop"] >= 0.5
    return row["unexplained"] and signal in row["signature"]


def case_row(case: str, plant: str, seed: int, settings: int, work: Path) -> dict:
    """Discover on one dataset; its row (claims, decisions, test drop, wall time)."""
    data = dataset(case, plant, seed, settings, work)
    js = work / f"{plant}_s{seed}.discover.json"
    wall = None
    if not js.exists():
        tmp = js.with_suffix(".partial.json")
        report = str(work / f"{plant}_s{seed}.report")
        code, wall, out = _run(
            _cli("discover", str(data), "--out", report, "--json", str(tmp), "--quiet")
        )
        if code:
            return {"plant": plant, "seed": seed, "error": out[-2000:], "wall_s": wall}
        os.replace(tmp, js)
    result = json.loads(js.read_text())
    decisions = [it.get("decision") for it in result["iterations"]]
    first = result["iterations"][0]
    scored = sorted(
        (c for c in first.get("candidates", []) if c.get("significant")),
        key=lambda c: -c.get("statistic", 0.0),
    )
    before, after = result["baseline"]["test"]["rmse_bar"], result["final"]["test"]["rmse_bar"]
    row = {
        "plant": plant,
        "seed": seed,
        "added": result["added"],
        "unexplained": result["unexplained"],
        "signature": result.get("signature", []),
        "decisions": decisions,
        "significant": [c["effect"] for c in scored],
        "train_rmse_bar": result["baseline"]["train"]["rmse_bar"],
        "test_rmse_before_bar": before,
        "test_rmse_after_bar": after,
        "test_drop": 1.0 - after / before,
        "wall_s": wall if wall is not None else result.get("wall_s"),
        "summary": result["summary"],
    }
    row["passes"] = verdict(case, row)
    return row


def main(argv: list[str] | None = None) -> int:
    from clutchlab.physics.stand.plants import PLANTS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", choices=sorted(CASES), default="null")
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--seeds", default="0,1,2,3")
    ap.add_argument("--plants", default="all", help="'all': the stand (null only) and the zoo")
    ap.add_argument("--settings", type=int, default=3, help="dither settings per dataset")
    args = ap.parse_args(argv)
    zoo = list(PLANTS)
    default = ["stand", *zoo] if args.case == "null" else zoo
    plants = default if args.plants == "all" else args.plants.split(",")
    seeds = [int(s) for s in args.seeds.split(",")]
    args.out.mkdir(parents=True, exist_ok=True)
    print(RULES[args.case])
    print(
        f"datasets: {plants} x seeds {seeds}, {args.settings} dither settings x 3 ramps each "
        f"(fast + slow trained, medium scored); {platform.machine()}, {os.cpu_count()} cores"
    )
    rows = []
    for plant in plants:
        for seed in seeds:
            row = case_row(args.case, plant, seed, args.settings, args.out)
            rows.append(row)
            if "error" in row:
                print(f"{plant:22s} {seed}  discover failed after {row['wall_s']:.0f} s")
                continue
            print(
                f"{plant:22s} {seed}  added {row['added'] or '-'}; significant "
                f"{row['significant'] or '-'}; {row['decisions'][-1]}; unexplained "
                f"{row['unexplained']} {row['signature']}; medium {row['test_rmse_before_bar']:.4f}"
                f" -> {row['test_rmse_after_bar']:.4f} bar; {row['wall_s']:.0f} s; "
                f"{'pass' if row['passes'] else 'FAIL'}",
                flush=True,
            )
    done = [r for r in rows if "error" not in r]
    claims = sum(len(r["added"]) for r in done)
    passed = sum(r["passes"] for r in done)
    if args.case == "null":
        ok = claims <= 1 and len(done) >= 20 and len(done) == len(rows)
        print(
            f"claimed effects: {claims} over {len(done)} null datasets "
            f"({len(rows) - len(done)} failed); rule {'met' if ok else 'NOT met'}"
        )
    else:
        ok = passed == len(rows)
        print(f"passed: {passed} of {len(rows)} ({len(rows) - len(done)} failed to run)")
    (args.out / f"{args.case}.json").write_text(
        json.dumps({"rule": RULES[args.case], "rows": rows}, indent=1)
    )
    lines = [
        "| plant | seed | added | significant (first iteration) | last decision | unexplained "
        "(signals) | medium RMSE before → after (bar) | s | rule |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in done:
        lines.append(
            f"| {r['plant']} | {r['seed']} | {', '.join(r['added']) or '—'} | "
            f"{', '.join(r['significant']) or '—'} | {r['decisions'][-1]} | "
            f"{'yes (' + ', '.join(r['signature']) + ')' if r['unexplained'] else 'no'} | "
            f"{r['test_rmse_before_bar']:.4f} → {r['test_rmse_after_bar']:.4f} | "
            f"{r['wall_s']:.0f} | {'pass' if r['passes'] else 'FAIL'} |"
        )
    (args.out / f"{args.case}.md").write_text("\n".join(lines) + "\n")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
