"""False positives of closing the loop on data with no added effect (issue 17, must-show 4).

For the default stand without its built-in effects (the base model plus the stand's
noise, quantization, line-pressure wander and resolved dither: nothing the base model
lacks) and every plant of the zoo as built (its own equations, no library effect added),
and every seed: write the dataset, run ``clutchlab discover`` on it (its own baseline fit,
the whole library as candidates) and count the effects it claims. Any claimed effect is a
false positive: on the stand nothing is missing, and a zoo plant carries no library effect
unless one is added with ``--effects``.

Prints the rule first, then one row per dataset, then the count; writes every discovery's
JSON (the evidence per candidate, with the held-out error of each training experiment) and
``null.json`` / ``null.md`` to ``--out``. Datasets and discoveries already in ``--out`` are
reused, so an interrupted study resumes.

Usage: ``python studies/discover_null.py --out DIR [--seeds 0,1,2,3] [--plants all]
[--settings 3]``
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

RULE = """\
Rule (issue 17, must-show 4): over >= 20 datasets with no added effect, at most 1 claimed
effect in all. A dataset's claims are the effects `clutchlab discover` adds (its JSON's
"added"). "Unexplained" (a residual that follows a signal, no effect named) is not a claim.
Nothing here reads the medium ramp except the before/after scores discover reports."""


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "clutchlab", *args]


def _run(cmd: list[str]) -> tuple[int, float, str]:
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True)
    return res.returncode, time.perf_counter() - t0, res.stdout + res.stderr


def dataset(plant: str, seed: int, settings: int, work: Path) -> Path:
    """Write (or reuse) the null dataset of ``plant`` and ``seed``."""
    data = work / f"{plant}_s{seed}"
    if (data / "manifest.json").exists():
        return data
    args = ["stand", "--plant", plant, "--seed", str(seed), "--settings", str(settings)]
    if plant == "stand":
        args.append("--no-builtin")
    code, _, out = _run(_cli(*args, "--out", str(data), "--quiet"))
    if code:
        raise SystemExit(f"stand {plant} seed {seed} failed:\n{out}")
    return data


def null_row(plant: str, seed: int, settings: int, work: Path) -> dict:
    """Discover on one null dataset; its row (claims, decisions, wall time)."""
    data = dataset(plant, seed, settings, work)
    js = work / f"{plant}_s{seed}.discover.json"
    wall = None
    if not js.exists():
        tmp = js.with_suffix(".partial.json")
        code, wall, out = _run(
            _cli(
                "discover",
                str(data),
                "--out",
                str(work / f"{plant}_s{seed}.report"),
                "--json",
                str(tmp),
                "--quiet",
            )
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
    return {
        "plant": plant,
        "seed": seed,
        "added": result["added"],
        "unexplained": result["unexplained"],
        "signature": result.get("signature", []),
        "decisions": decisions,
        "significant": [c["effect"] for c in scored],
        "train_rmse_bar": result["baseline"]["train"]["rmse_bar"],
        "wall_s": wall if wall is not None else result.get("wall_s"),
        "summary": result["summary"],
    }


def main(argv: list[str] | None = None) -> int:
    from clutchlab.physics.stand.plants import PLANTS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--seeds", default="0,1,2,3")
    ap.add_argument("--plants", default="all", help="'all' (the stand and every zoo plant)")
    ap.add_argument("--settings", type=int, default=3, help="dither settings per dataset")
    args = ap.parse_args(argv)
    plants = ["stand", *PLANTS] if args.plants == "all" else args.plants.split(",")
    seeds = [int(s) for s in args.seeds.split(",")]
    args.out.mkdir(parents=True, exist_ok=True)
    print(RULE)
    print(
        f"datasets: {plants} x seeds {seeds}, {args.settings} dither settings x 3 ramps each "
        f"(fast + slow trained, medium scored); {platform.machine()}, {os.cpu_count()} cores"
    )
    rows = []
    for plant in plants:
        for seed in seeds:
            row = null_row(plant, seed, args.settings, args.out)
            rows.append(row)
            if "error" in row:
                print(f"{plant:22s} {seed}  discover failed after {row['wall_s']:.0f} s")
                continue
            print(
                f"{plant:22s} {seed}  added {row['added'] or '-'}; significant "
                f"{row['significant'] or '-'}; {row['decisions'][-1]}; "
                f"unexplained {row['unexplained']}; {row['wall_s']:.0f} s",
                flush=True,
            )
    done = [r for r in rows if "error" not in r]
    claims = sum(len(r["added"]) for r in done)
    verdict = "met" if claims <= 1 and len(done) >= 20 else "NOT met"
    print(
        f"claimed effects: {claims} over {len(done)} null datasets "
        f"({len(rows) - len(done)} failed); rule {verdict}"
    )
    (args.out / "null.json").write_text(json.dumps({"rule": RULE, "rows": rows}, indent=1))
    lines = [
        "| plant | seed | added | significant (first iteration) | last decision | s |",
        "|---|---|---|---|---|---|",
    ]
    for r in done:
        lines.append(
            f"| {r['plant']} | {r['seed']} | {', '.join(r['added']) or '—'} | "
            f"{', '.join(r['significant']) or '—'} | {r['decisions'][-1]} | {r['wall_s']:.0f} |"
        )
    (args.out / "null.md").write_text("\n".join(lines) + "\n")
    return 0 if claims <= 1 else 1


if __name__ == "__main__":
    raise SystemExit(main())
