"""``--regulator-lag`` off / auto, physics fit scored on held-back 5 s + 20 s ramps (issue 16).

Uses the training-side-rates datasets of ``studies/latch_event.py`` (``PLANT_rates_sN`` in
``--data``); the 10 s medium ramp is not in them. Prints its rule first. Usage:
``python studies/regulator_lag_rates.py --data DIR [--seeds 0,1] PLANT [PLANT ...]``
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

RULE = (
    "rule (fixed first): --regulator-lag auto becomes the default only if, on every circuit "
    "and seed checked where auto adds the reg_pilot_lag law, its physics RMSE on the 5 s + "
    "20 s ramps is lower than off's; where auto does not add the law both fits have the "
    "same structure and are listed, not compared"
)


def main(argv: list[str] | None = None) -> int:
    from clutchlab.data import load_dataset
    from clutchlab.physics.fit import PhysicsFitter
    from clutchlab.validation import FittedPhysics, Protocol

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True, help="folder of the rates datasets")
    ap.add_argument("--seeds", default="0", help="comma-separated seeds (default 0)")
    ap.add_argument("--modes", default="off,auto", help="which fits to run (default off,auto)")
    ap.add_argument("plants", nargs="+")
    args = ap.parse_args(argv)
    print(RULE, flush=True)
    runs = [(p, int(s)) for s in args.seeds.split(",") for p in args.plants]
    for plant, seed in runs:
        data = args.data / f"{plant}_rates_s{seed}"
        pr = Protocol(load_dataset(data), train=("fast", "slow"), test=("r5", "r20"))
        for mode in args.modes.split(","):
            fit = args.data / f"{plant}_rates_s{seed}.reglag_{mode}.fit.json"
            cmd = [sys.executable, "-m", "clutchlab.cli", "fit-physics", str(data)]
            cmd += ["--regulator-lag", mode, "--out", str(fit), "--quiet"]
            t0 = time.time()
            res = subprocess.run(cmd, capture_output=True, text=True)
            wall = time.time() - t0
            fitter = PhysicsFitter.load(fit)
            model, _ = pr.fit(FittedPhysics(fitted=fitter))
            s = pr.score("physics_fitted", model, std_for=())
            print(
                f"{plant} s{seed} {mode}: exit {res.returncode}, {wall:.0f} s, effects "
                f"{fitter.model_.effect_names}, 5 s + 20 s RMSE {s.metrics['rmse_bar']:.3f} bar, "
                f"latch off {s.metrics['latch_off_err_mA']:.1f} mA",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
