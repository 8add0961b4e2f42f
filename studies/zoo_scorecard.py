"""Scorecard of the physics fit and the hybrid on the plant zoo and the stand (issue 16).

For every plant of the zoo and the default stand, and every seed: write the dataset,
run ``clutchlab fit-physics`` (its exit status and wall time, measured outside), then
``clutchlab evaluate`` with that fit (``--physics-model``) for physics_default,
physics_fitted, paper_svc_gp and hybrid, scored on the medium ramp, which nothing is
chosen on. Prints the decision rule first, then one row per plant and seed with the
issue's checks, then the spread per plant; writes everything to ``--out``/scorecard.json
and scorecard.md.

Usage: ``python studies/zoo_scorecard.py --out DIR [--seeds 0,1,2] [--plants all]
[--variants physics_default,physics_fitted]``
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

RULES = """\
Checks (issue 16; the medium ramp is only scored, never used for a choice):
  fitted<=0.5*default   physics_fitted RMSE <= 0.5 x physics_default (zoo plants)
  fitted<=0.15          physics_fitted RMSE <= 0.15 bar (zoo plants); <= 0.035 bar (stand)
  fit<=120s             fit-physics wall time <= 120 s on this machine, exit status 0
  hybrid<=1.02*min      hybrid RMSE <= 1.02 x min(physics_fitted, paper_svc_gp)
  stand hybrid          hybrid RMSE <= 0.030 bar on the stand
RMSE: dither-period-mean clutch pressure on the 9 medium-ramp experiments (bar).
"fitted: e² in latch window": the share of physics_fitted's squared error within 0.15 s of a
measured latch snap or release (latch timing), beside its RMSE in the regulated region."""

VARIANTS = ("physics_default", "physics_fitted", "paper_svc_gp", "hybrid")


def _run(cmd: list[str]) -> tuple[int, float, str]:
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True)
    return res.returncode, time.perf_counter() - t0, res.stdout + res.stderr


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "clutchlab.cli", *args]


def score(
    plant: str,
    seed: int,
    work: Path,
    previous: dict | None = None,
    variants: tuple[str, ...] = VARIANTS,
) -> dict:
    data = work / f"{plant}_s{seed}"
    if not (data / "manifest.json").exists():
        code, _, out = _run(
            _cli("stand", "--plant", plant, "--seed", str(seed), "--out", str(data), "--quiet")
        )
        if code:
            raise SystemExit(f"stand {plant} seed {seed} failed:\n{out}")
    fit = work / f"{plant}_s{seed}.fit.json"
    if previous is not None and fit.exists():  # --reevaluate: the fit as measured before
        code, wall, out = previous["fit_exit"], previous["fit_wall_s"], ""
    else:
        code, wall, out = _run(_cli("fit-physics", str(data), "--out", str(fit), "--quiet"))
    row = {"plant": plant, "seed": seed, "fit_exit": code, "fit_wall_s": wall}
    if code == 0:
        doc = json.loads(fit.read_text())
        row |= {
            "fit_status": doc["status"],
            "converged": doc["success"],
            "structure": doc["effects"],
        }
    else:
        row["fit_error"] = out[-2000:]
    report = work / f"{plant}_s{seed}.eval"
    args = ["evaluate", str(data), "--out", str(report), "--quiet", "--no-classifiers"]
    args += ["--variants", ",".join(variants)]
    if code == 0:
        args += ["--physics-model", str(fit)]
    ecode, ewall, eout = _run(_cli(*args))
    row["eval_exit"], row["eval_wall_s"] = ecode, ewall
    metrics = report / "metrics.json"
    if metrics.exists():
        doc = json.loads(metrics.read_text())
        row["rmse_bar"] = {
            v: doc["variants"][v]["rmse_bar"] for v in variants if v in doc["variants"]
        }
        # where physics_fitted's error lies: its share in the latch window (latch timing)
        pm = doc["details"].get("physics_fitted", {}).get("period_mean", {})
        row["fitted_latch_window_share"] = pm.get("sq_error_share_latch_window")
        row["fitted_regulated_rmse_bar"] = pm.get("rmse_regulated_bar")
        d = doc["details"].get("hybrid", {})
        row["hybrid_form"] = d.get("residual_form")
        row["hybrid_form_loeo_rmse_bar"] = d.get("residual_form_loeo_rmse_bar")
        row["failed"] = doc.get("failed", {})
    else:
        row["eval_error"] = eout[-2000:]
    return row


def checks(row: dict) -> dict[str, bool]:
    """The issue's checks on the variants the row has (``--variants``)."""
    r = row.get("rmse_bar", {})
    if not {"physics_default", "physics_fitted"} <= set(r):
        return {"complete": False}
    stand = row["plant"] == "stand"
    c = {"fit<=120s": row["fit_exit"] == 0 and row["fit_wall_s"] <= 120.0}
    hybrid = {"hybrid", "paper_svc_gp"} <= set(r)
    if hybrid:
        c["hybrid<=1.02*min"] = r["hybrid"] <= 1.02 * min(r["physics_fitted"], r["paper_svc_gp"])
    if stand:
        c["fitted<=0.035"] = r["physics_fitted"] <= 0.035
        if hybrid:
            c["hybrid<=0.030"] = r["hybrid"] <= 0.030
    else:
        c["fitted<=0.5*default"] = r["physics_fitted"] <= 0.5 * r["physics_default"]
        c["fitted<=0.15"] = r["physics_fitted"] <= 0.15
    return c


def markdown(rows: list[dict]) -> str:
    lines = [
        "| plant | seed | default | fitted | fitted: e² in latch window, regulated RMSE "
        "| paper_svc_gp | hybrid (form) | fit wall, status | checks failed |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        r = row.get("rmse_bar", {})

        def f(v, r=r):
            return f"{r[v]:.3f}" if v in r else "—"

        share, reg = row.get("fitted_latch_window_share"), row.get("fitted_regulated_rmse_bar")
        where = "—" if share is None or reg is None else f"{100 * share:.0f} %, {reg:.3f}"
        bad = [k for k, ok in checks(row).items() if not ok]
        status = row.get("fit_status", f"exit {row['fit_exit']}")
        lines.append(
            f"| {row['plant']} | {row['seed']} | {f('physics_default')} | {f('physics_fitted')} "
            f"| {where} | {f('paper_svc_gp')} | {f('hybrid')} ({row.get('hybrid_form', '—')}) "
            f"| {row['fit_wall_s']:.0f} s, {status} | {', '.join(bad) or 'none'} |"
        )
    return "\n".join(lines)


def main() -> None:
    from clutchlab.physics.stand.plants import plant_names

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="work folder (datasets, fits, reports)")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--plants", default="all", help="comma separated, 'all' = zoo + stand")
    ap.add_argument(
        "--reevaluate",
        action="store_true",
        help="keep the fits (and their measured wall time and exit status) recorded in "
        "OUT/scorecard.json; only evaluate again (after a change above the physics fit)",
    )
    ap.add_argument(
        "--variants",
        default=",".join(VARIANTS),
        help="variants to score (physics_default,physics_fitted for must-show 1 alone)",
    )
    args = ap.parse_args()
    print(RULES)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    )
    plants = ["stand", *plant_names()] if args.plants == "all" else args.plants.split(",")
    seeds = [int(s) for s in args.seeds.split(",")]
    work = Path(args.out)
    work.mkdir(parents=True, exist_ok=True)
    before = {}
    if args.reevaluate:
        before = {
            (r["plant"], r["seed"]): r for r in json.loads((work / "scorecard.json").read_text())
        }
    rows = []
    for plant in plants:
        for seed in seeds:
            row = score(
                plant, seed, work, before.get((plant, seed)), tuple(args.variants.split(","))
            )
            rows.append(row)
            print(markdown([row]).splitlines()[-1], flush=True)
            name = "scorecard.reevaluated.json" if args.reevaluate else "scorecard.json"
            (work / name).write_text(json.dumps(rows, indent=2))
    print("\n" + markdown(rows))
    (work / "scorecard.md").write_text(markdown(rows) + "\n")


if __name__ == "__main__":
    main()
