"""Exploration (training-side held-back rates only; no medium ramp): the hybrid's form choice
by leave-one-experiment-out in which every form's latch decision is the one fitted on all
training experiments (the held-out experiment's switches stay known), so the folds score
the pressure models, not a latch law's transfer of a setting's switch to the other rate.
Compared with the pooled LOEO of the library against the forms' RMSE on the 5 s + 20 s ramps
(stored by studies/hybrid_form_rates.py).

Prints its rule first. Usage: ``python studies/hybrid_form_shared_decision.py --data DIR
--forms F.json[,G.json] --out OUT.json PLANT:SEED ...`` (``DIR`` holds the rates datasets
and their ``*.fit.json``; ``F.json`` the output of ``hybrid_form_rates.py``; rows with the
library's residual latch decision are read).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from clutchlab.data import load_dataset
from clutchlab.physics.fit import PhysicsFitter
from clutchlab.residual_ml import HybridModel, PhysicsPredictor

RULE = """Rule (fixed before the run): the shared-decision LOEO is worth building if its pick is
within 1.02x of the best form on strictly more datasets than the library's pooled LOEO and
never > 1.02x where the pooled LOEO's pick was within 1.02x."""


def swap(model, full):
    model.classifier_, model.decision_ = full.classifier_, full.decision_
    model.single_state_ = full.single_state_


class Shared(HybridModel):
    """The library's folds, with every fold model's latch decision fitted on all traces."""

    def _fold_model(self, form, traces, outputs, train):
        full = getattr(self, "_full", {})
        if form not in full:
            full[form] = super()._fold_model(form, traces, outputs, list(range(len(traces))))
            self._full = full
        model = super()._fold_model(form, traces, outputs, train)
        swap(model, full[form])
        return model


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument(
        "--forms", required=True, help="outputs of hybrid_form_rates.py, comma separated"
    )
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("items", nargs="+", help="PLANT:SEED")
    args = ap.parse_args(argv)
    print(RULE, flush=True)
    stored = {
        (r["plant"], r["seed"]): r
        for f in args.forms.split(",")
        for r in json.loads(Path(f).read_text())
        if r.get("residual_latch") in (None, "classifier")
    }
    rows = []
    for item in args.items:
        _one(item, args.data, stored, rows)
        args.out.write_text(json.dumps(rows, indent=1))
    good = sum(r["regret"] <= 1.02 for r in rows)
    good_pooled = sum(r["pooled_regret"] <= 1.02 for r in rows)
    lost = [f"{r['plant']} s{r['seed']}" for r in rows if r["regret"] > 1.02 >= r["pooled_regret"]]
    met = good > good_pooled and not lost
    print(
        f"within 1.02x of the best: shared {good}, pooled {good_pooled} of {len(rows)}; "
        f"lost where pooled was within: {lost or 'none'}; rule {'met' if met else 'not met'}"
    )
    return 0


def _one(item: str, data: Path, stored: dict, rows: list) -> None:
    plant, seed = item.rsplit(":", 1)
    seed = int(seed)
    path = data / f"{plant}_rates_s{seed}"
    phys = PhysicsPredictor.from_fitter(
        PhysicsFitter.load(data / f"{plant}_rates_s{seed}.fit.json")
    )
    train = list(load_dataset(path).select(ramps=["fast", "slow"]))
    m = Shared(physics=phys, form="auto")
    phys_out = [m._outputs(phys, t, tuple(m._residual()._builder().names)) for t in train]
    scores = m._loeo_scores(train, phys_out)
    st = stored[(plant, seed)]
    truth = st["held_back_rmse"]
    best = min(truth.values())
    pick = min(scores, key=scores.get)
    pooled = st["picks"]["pooled"]
    row = dict(
        plant=plant,
        seed=seed,
        shared=scores,
        pooled=st["criteria"]["pooled"],
        truth=truth,
        pick=pick,
        regret=truth[pick] / best,
        pooled_pick=pooled,
        pooled_regret=truth[pooled] / best,
    )
    rows.append(row)
    print(
        f"{plant:22s} s{seed} shared LOEO "
        + " ".join(f"{k} {v:.3f}" for k, v in scores.items())
        + f" | pick {pick} ({row['regret']:.2f}); pooled {pooled} ({row['pooled_regret']:.2f})",
        flush=True,
    )


if __name__ == "__main__":
    raise SystemExit(main())
