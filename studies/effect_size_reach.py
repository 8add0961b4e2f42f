"""Which outcome-blind effect-size rows could pass at all: the null floor and the named refit.

Issue 17's must-show 3 asks, for each library effect at the outcome-blind size of
``studies/discover_effect_size.py``, that discovery names it first and that the medium-ramp
RMSE (dither-period mean) drops by at least half. A discovery can only do that when the
augmented model *can* halve the error. This study measures that bound per effect, apart
from how well discovery searches:

* **null floor** — the discovery's own baseline fit on the same discovery stand (same
  settings, ramps and noise seed) with no effect switched on: what the base model scores
  on the medium ramp when nothing is missing (latch-snap timing on a dithered pilot,
  integration step, the model driven by the measured current);
* **truth oracle** — the stand's truth model and truth parameters, simulated as the
  medium ramp is scored (from the measured current, the default step), and also at the
  fit's 2 and the stand's 8 substeps and from the current command at 8 (``--oracle-only``
  prints just these): how much of the medium error the step and the drive decide;
* **named refit** — the refit a discovery would make had it named the true effect: the
  discovery's baseline fit, then the effect added with its fit parameters freed beside the
  base ones, started at the baseline plus the effect's *truth* values (more than a
  discovery knows) and, where that is the better start by the training residual, at zero
  strength; the full fit settings (not the screening's). Medium RMSE before → after.

A row is *in reach* when the named refit's medium drop is at least
:data:`~clutchlab.validation.discover.scenarios.MAX_ERROR_RATIO`'s half. A row out of reach
fails on the model or the fit, not on discovery's look. Nothing is chosen here; the medium
ramp is only scored, and the start of the named refit is picked on the training residual.

Usage::

    python studies/effect_size_reach.py [--effects a,b] [--substeps N] [--seed S]
                                        [--oracle-only] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from dataclasses import replace

import numpy as np

from clutchlab.errors import ClutchlabError
from clutchlab.physics import CircuitModel, SimulationSettings
from clutchlab.physics.effects import EFFECTS
from clutchlab.physics.fit import resolve_free
from clutchlab.physics.stand import run_stand
from clutchlab.validation.discover import DiscoverySettings
from clutchlab.validation.discover.effect_size import calibrate_effect_size
from clutchlab.validation.discover.loop import _split, period_mean_metrics
from clutchlab.validation.discover.refit import candidate_free, run_fit
from clutchlab.validation.discover.scenarios import MAX_ERROR_RATIO, discovery_stand


def _rmse(model, params, traces) -> float:
    return period_mean_metrics(model, params, traces)[0]["rmse_bar"]


#: Simulation settings of the truth oracle's columns (label → settings).
ORACLE_STEPS = {
    "2 substeps": SimulationSettings(substeps=2),
    "4 (scored)": SimulationSettings(),
    "8": SimulationSettings(substeps=8),
    "8, command": SimulationSettings(substeps=8, drive="command"),
}


def truth_oracle(run, traces) -> dict[str, float]:
    """Medium RMSE (bar, dither-period mean) of the stand's truth at each of
    :data:`ORACLE_STEPS` (inf where the simulation fails; a diverging step that does not
    raise shows as pressures far outside the circuit's range, with a SimulationWarning)."""
    out = {}
    for label, sim in ORACLE_STEPS.items():
        try:
            out[label] = period_mean_metrics(run.model, run.params, traces, sim)[0]["rmse_bar"]
        except ClutchlabError:
            out[label] = float("inf")
    return out


def sized_stand(effect: str, seed: int = 1):
    """The discovery stand with ``effect`` at its outcome-blind size (calibrated at the
    cases' seed 1, as the must-show defines it) and noise seed ``seed``, and that size."""
    size = calibrate_effect_size(effect)
    config = discovery_stand(
        (effect,), n_settings=size.n_settings, overrides=size.overrides, seed=seed
    )
    return run_stand(config, progress=False), size


def _baseline(dataset, settings: DiscoverySettings):
    """The discovery's baseline fit (base model, datasheet start) and the train / test split."""
    train, test = _split(dataset, settings)
    model = CircuitModel()
    fit = run_fit(model, train, settings, resolve_free(model, settings.fit), None, budget_ok=True)
    return fit, train, test


def null_floor(n_settings: int, settings: DiscoverySettings, seed: int = 1) -> float:
    """Medium RMSE (bar) of the baseline fit on the discovery stand without any effect."""
    run = run_stand(discovery_stand((), n_settings=n_settings, seed=seed), progress=False)
    fit, _, test = _baseline(run.dataset, settings)
    return _rmse(fit.model(), fit.params(), test)


def named_refit(effect: str, settings: DiscoverySettings, seed: int = 1) -> dict:
    """The truth oracle and the named refit of ``effect`` at its outcome-blind size."""
    run, size = sized_stand(effect, seed)
    base, train, test = _baseline(run.dataset, settings)
    oracle = truth_oracle(run, test)
    cand = CircuitModel().with_effects(effect)
    own = [p.name for p in cand.parameters if p.name not in set(base.params())]
    truth = {k: run.params[k] for k in own}
    starts = {"truth": dict(base.params()) | truth}
    if any(truth[k] != 0.0 for k in EFFECTS[effect].STRENGTH if k in truth):
        starts["zero strength"] = starts["truth"] | dict.fromkeys(EFFECTS[effect].STRENGTH, 0.0)
    free = candidate_free(tuple(base.free), effect)
    refits = {
        label: run_fit(cand, train, settings, free, cand.params(**vals), budget_ok=True)
        for label, vals in starts.items()
    }
    train_after = {k: _rmse(cand, r.params(), train) for k, r in refits.items()}
    label = min(train_after, key=train_after.__getitem__)
    ref = refits[label]
    before = _rmse(base.model(), base.params(), test)
    after = _rmse(cand, ref.params(), test)
    return {
        "effect": effect,
        "n_settings": size.n_settings,
        "at_bound": size.at_bound,
        "truth": truth,
        "oracle_bar": oracle,
        "train_rmse_bar": [_rmse(base.model(), base.params(), train), train_after[label]],
        "test_rmse_bar": [before, after],
        "drop_pct": 100.0 * (1.0 - after / before),
        "start": label,
        "fitted": {k: ref.params()[k] for k in own},
        "status": ref.status,
        "in_reach": after <= MAX_ERROR_RATIO * before,
    }


def _oracle_text(oracle: dict[str, float]) -> str:
    return " / ".join(f"{v:.4f}" if np.isfinite(v) else "diverges" for v in oracle.values())


def _oracle_only(wanted: list[str], settings: DiscoverySettings, seed: int) -> None:
    print(f"| effect | truth oracle, medium RMSE (bar) at {' / '.join(ORACLE_STEPS)} |")
    print("|---|---|")
    for effect in wanted:
        if effect == "none":  # the discovery stand without any effect
            run, bound = run_stand(discovery_stand((), seed=seed), progress=False), ""
        else:
            run, size = sized_stand(effect, seed)
            bound = " (bound)" if size.at_bound else ""
        test = [t for t in run.dataset if t.ramp in settings.test_ramps]
        print(f"| {effect}{bound} | {_oracle_text(truth_oracle(run, test))} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--effects", default="", help="comma-separated subset (default: all)")
    ap.add_argument("--substeps", type=int, default=None, help="fit substeps (default: the fit's)")
    ap.add_argument(
        "--oracle-only",
        action="store_true",
        help="only the truth oracle, no fits ('none' in --effects: the stand without effect)",
    )
    ap.add_argument("--seed", type=int, default=1, help="stand noise seed (the cases': 1)")
    ap.add_argument("--json", help="write the rows here (rewritten after each effect)")
    args = ap.parse_args()
    wanted = [e for e in args.effects.split(",") if e] or sorted(EFFECTS)
    settings = DiscoverySettings(progress=False, max_effects=1)
    if args.substeps:
        settings = replace(settings, fit=replace(settings.fit, substeps=args.substeps))
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}; fit substeps {settings.fit.substeps}; seed {args.seed}"
    )
    if args.oracle_only:
        _oracle_only(wanted, settings, args.seed)
        return
    floors = {}
    out: dict = {"null_floor_bar": floors, "rows": []}
    print(
        f"| effect | null floor (bar) | truth oracle (bar; {' / '.join(ORACLE_STEPS)}) | "
        "named refit: train RMSE (bar) | medium RMSE (bar) | drop | start | status | "
        "in reach | s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for effect in wanted:
        t0 = time.perf_counter()
        row = named_refit(effect, settings, args.seed)
        n = row["n_settings"]
        if n not in floors:
            floors[n] = null_floor(n, settings, args.seed)
        row["null_floor_bar"] = floors[n]
        row["wall_s"] = time.perf_counter() - t0
        out["rows"].append(row)
        if args.json:
            with open(args.json, "w", encoding="utf-8") as f:
                json.dump(out, f, indent=2)
        tr, te = row["train_rmse_bar"], row["test_rmse_bar"]
        print(
            f"| {effect}{' (bound)' if row['at_bound'] else ''} | {floors[n]:.4f} | "
            f"{_oracle_text(row['oracle_bar'])} | {tr[0]:.4f} → {tr[1]:.4f} | "
            f"{te[0]:.4f} → {te[1]:.4f} | {row['drop_pct']:.1f} % | {row['start']} | "
            f"{row['status']} | {'yes' if row['in_reach'] else 'no'} | {row['wall_s']:.0f} |",
            flush=True,
        )
    reach = sum(r["in_reach"] for r in out["rows"])
    print(f"in reach when named: {reach} of {len(out['rows'])}")


if __name__ == "__main__":
    main()
