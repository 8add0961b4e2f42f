"""The latched plateau relative to line pressure (issue 20, build item 1), on every circuit.

For the default stand and every zoo plant, seeds 0, 1, 2 (datasets written by
``clutchlab stand``, cached in ``--data``): ``SVCPartitionedGP`` (``paper_svc_gp``) fitted
on the fast + slow ramps twice — ``latched_reference="none"`` (the paper: the latched GP
learns the pressure) and ``"line"`` (it learns the offset below line pressure) — and
scored on the medium ramp. Nothing is chosen here: the default was set before this ran,
and the medium ramp is only scored. Prints the rule first, then one row per plant and
seed, then mean and worst per plant; writes ``--out`` (JSON).

Usage: ``python studies/latched_reference.py --data /work/score1 --out latched.json``
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

RULE = """\
Decision rule (fixed before the run; the medium ramp is only scored):
  line reference kept as default if latched-plateau RMSE falls on every plant and the
  overall medium RMSE is not worse (> 1.02x) on any plant and seed.
Metrics on the scored experiments (medium ramp, or with --rates the 5 s + 20 s ramps),
dither-period mean:
  rmse       all samples (bar)
  plateau    samples where measured and predicted are both within 1 bar of line, at least
             50 ms from a snap or release of either (bar); edges: the same without the
             50 ms guard (the snap transients, i.e. latch timing, included)
  on / off   mean |latch-on| / |latch-off| current error (mA)"""

PLANTS = ("stand", "saturating_lugre", "quadratic_play", "stribeck_supply", "preisach_accumulator")


def dataset(root: Path, plant: str, seed: int) -> Path:
    path = root / f"{plant}_s{seed}"
    if not (path / "manifest.json").exists():
        cmd = [sys.executable, "-m", "clutchlab.cli", "stand", "--seed", str(seed)]
        cmd += [] if plant == "stand" else ["--plant", plant]
        subprocess.run([*cmd, "--out", str(path), "--quiet"], check=True)
    return path


def score(path: Path, test: tuple[str, ...] = ("medium",)) -> dict:
    from clutchlab.data import load_dataset
    from clutchlab.residual_ml import SVCPartitionedGP
    from clutchlab.validation import AnalysisSettings, Protocol

    data = load_dataset(path)
    protocol = Protocol(data, test=test)
    unguarded = Protocol(data, test=test, settings=AnalysisSettings(plateau_guard_s=0.0))
    out = {}
    for ref in ("none", "line"):
        model, fit_s = protocol.fit(SVCPartitionedGP(latched_reference=ref))
        s = protocol.score(f"paper_svc_gp[{ref}]", model, fit_s=fit_s, std_for=())
        d = s.details["period_mean"]
        edges = unguarded.score("edges", model, std_for=()).details["period_mean"]
        out[ref] = {
            "rmse_bar": s.metrics["rmse_bar"],
            "plateau_bar": d["latched_plateau_rmse_bar"],
            "plateau_edges_bar": edges["latched_plateau_rmse_bar"],
            "latch_on_err_mA": s.metrics["latch_on_err_mA"],
            "latch_off_err_mA": s.metrics["latch_off_err_mA"],
            "fitted_reference": model.latched_reference_,
        }
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True, help="dataset cache folder")
    ap.add_argument("--out", type=Path, required=True, help="JSON results")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--plants", default=",".join(PLANTS))
    ap.add_argument(
        "--rates",
        action="store_true",
        help="score the held-back 5 s + 20 s training-side ramps of the datasets of "
        "studies/latch_event.py instead of the medium ramp (a check that reads no test data)",
    )
    args = ap.parse_args(argv)
    print(RULE, flush=True)
    print("scored: " + ("5 s + 20 s ramps (held-back training side)" if args.rates else "medium"))
    rows = []
    print(
        f"\n{'plant':22s} seed  rmse none/line   plateau none/line   edges none/line  "
        "on none/line  off none/line"
    )
    for plant in args.plants.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            if args.rates:
                sys.path.insert(0, str(Path(__file__).parent))
                from latch_event import rates_dataset

                r = score(rates_dataset(args.data, plant, seed), test=("r5", "r20"))
            else:
                r = score(dataset(args.data, plant, seed))
            n, ln = r["none"], r["line"]
            rows.append({"plant": plant, "seed": seed, **r})
            print(
                f"{plant:22s} {seed:4d}  {n['rmse_bar']:.3f} / {ln['rmse_bar']:.3f}    "
                f"{n['plateau_bar']:.3f} / {ln['plateau_bar']:.3f}      "
                f"{n['plateau_edges_bar']:.3f} / {ln['plateau_edges_bar']:.3f}    "
                f"{n['latch_on_err_mA']:5.1f} / {ln['latch_on_err_mA']:5.1f}  "
                f"{n['latch_off_err_mA']:5.1f} / {ln['latch_off_err_mA']:5.1f}",
                flush=True,
            )
            args.out.write_text(json.dumps(rows, indent=1))
    print("\nper plant, mean (worst): plateau none -> line; rmse none -> line")
    ok = True
    for plant in dict.fromkeys(r["plant"] for r in rows):
        mine = [r for r in rows if r["plant"] == plant]

        def stat(ref, key, mine=mine):
            v = np.array([r[ref][key] for r in mine])
            return f"{v.mean():.3f} ({v.max():.3f})"

        print(
            f"  {plant:22s} plateau {stat('none', 'plateau_bar')} -> {stat('line', 'plateau_bar')}"
            f"; rmse {stat('none', 'rmse_bar')} -> {stat('line', 'rmse_bar')}"
        )
        worse = [r for r in mine if r["line"]["rmse_bar"] > 1.02 * r["none"]["rmse_bar"]]
        fell = np.mean([r["line"]["plateau_bar"] for r in mine]) < np.mean(
            [r["none"]["plateau_bar"] for r in mine]
        )
        ok &= fell and not worse
    print(f"\nrule: {'met' if ok else 'NOT met'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
