"""GP marginal-likelihood block size: the pipeline's LOEO on the training experiments only.

Usage: ``python studies/gp_block_size.py NAME[,NAME...] OUT.json [--root=DIR]`` with the
dataset folders ``DIR/NAME`` (default ``/work/runs/std``; ``clutchlab stand [--plant P]
--seed S``). Only the fast + slow ramps are loaded; the medium ramp never is.

Result (session 22, BENCHMARKS "Local GP / paper pipeline"): both candidates fail (b) on the
stand, so the default stays.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from clutchlab.data import load_dataset
from clutchlab.residual_ml import estimators as est_mod
from clutchlab.residual_ml.local_gp import LocalGPRegressor

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ml_model_choices import STANDALONE, loeo

RULE = """\
RULE (printed first, written before any pipeline number of this study was seen):
Options: CUR = (n_hyper 2000, block_size 250) [default], B500 = (2000, 500),
H1000 = (1000, 500). Score per dataset: LOEO RMSE (6 folds, ml_model_choices' fold rule) of
gp_base, gp_didt and paper_svc_gp, summed. A candidate replaces CUR only if, over the 5
datasets (stand + 4 zoo plants, seed 0; cut from seeds 0 and 1 for time after one CUR row,
stand_s0 1.1258, had been seen and no candidate row):
  (a) its total (sum over datasets) is <= 1.02 x CUR's total, and
  (b) on no dataset is its sum > 1.05 x CUR's, and
  (c) it meets bench_gp's sklearn parity (RMSE ratio <= 1.05, fit-time ratio <= 0.2) on both
      kernels (checked afterwards with benchmarks/bench_gp.py, one run, seed-0 draw).
If both candidates qualify, the one with the lower total wins."""

OPTIONS = {"CUR": {}, "B500": {"block_size": 500}, "H1000": {"n_hyper": 1000, "block_size": 500}}


def main() -> None:
    args = [a for a in sys.argv[1:] if not a.startswith("--root=")]
    root = next((a.split("=", 1)[1] for a in sys.argv[1:] if a.startswith("--root=")), None)
    root = root or "/work/runs/std"
    print(RULE, flush=True)
    out: dict = {}
    for name in args[0].split(","):
        ds = load_dataset(f"{root}/{name}")
        traces = sorted(ds.select(ramps=("fast", "slow")).experiments, key=lambda t: t.name)
        step = max(1, len(traces) // 6)
        folds = [min(len(traces) - 1, step * i + i % step) for i in range(6)]
        row = {}
        for opt, kw in OPTIONS.items():
            t0 = time.perf_counter()
            est_mod.LocalGPRegressor = lambda kw=kw, **a: LocalGPRegressor(**{**a, **kw})
            try:
                per = {label: loeo(cls(), traces, folds) for label, cls in STANDALONE}
            finally:
                est_mod.LocalGPRegressor = LocalGPRegressor
            wall = time.perf_counter() - t0
            row[opt] = {"per": per, "sum": sum(per.values()), "wall_s": wall}
            rounded = {k: round(v, 4) for k, v in per.items()}
            print(f"{name} {opt} {rounded} sum {row[opt]['sum']:.4f} {wall:.0f} s", flush=True)
        out[name] = row
        Path(args[1]).write_text(json.dumps(out, indent=1), encoding="utf-8")
    tot = {o: sum(out[n][o]["sum"] for n in out) for o in OPTIONS}
    print("totals", tot)
    for o in ("B500", "H1000"):
        worst = max(out[n][o]["sum"] / out[n]["CUR"]["sum"] for n in out)
        print(
            f"{o}: total ratio {tot[o] / tot['CUR']:.4f}, worst dataset ratio {worst:.4f}; "
            f"(a) {tot[o] <= 1.02 * tot['CUR']}, (b) {worst <= 1.05}"
        )


if __name__ == "__main__":
    main()
