"""Per-experiment held-out errors behind discovery's leave-one-experiment-out verdict.

On a stand folder (default: the default stand written by ``clutchlab stand``): fit the base
model on the training ramps, screen sensor_lag and transport_delay on the pre-fit subset,
refine each on every training experiment (as ``discover`` does), and print for each the
linearized held-out error per training experiment minus the reference's, how many
experiments it lowers, the summed error against the reference's, ΔBIC and the test-ramp RMSE
(printed, never used). Diagnosis only: no decision is taken here.

Usage: ``python studies/discover_loeo_per_experiment.py STAND [--candidates a,b]``
"""

from __future__ import annotations

import argparse

import numpy as np

from clutchlab.data import load_dataset
from clutchlab.physics import CircuitModel
from clutchlab.physics.fit import resolve_free
from clutchlab.validation.discover import DiscoverySettings
from clutchlab.validation.discover.loop import _confirm, _split, _state
from clutchlab.validation.discover.refit import run_fit
from clutchlab.validation.discover.residuals import loeo_errors
from clutchlab.validation.discover.scoring import score_candidates
from clutchlab.validation.discover.screen import screen_refit, screening


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stand", help="dataset folder")
    ap.add_argument("--candidates", default="sensor_lag,transport_delay")
    args = ap.parse_args()
    settings = DiscoverySettings(progress=False)
    train, test = _split(load_dataset(args.stand), settings)
    model = CircuitModel()
    fit = run_fit(model, train, settings, resolve_free(model, settings.fit), None)
    current = _state(fit, train, test, settings, True)
    ref = loeo_errors(current.residual)
    test_rmse = current.test["rmse_bar"]
    print(f"reference: summed held-out error {ref.sum():.3f} bar², test {test_rmse:.4f} bar")
    screen = screening(current, train, settings)
    if screen is None:
        raise SystemExit("the training data fit in the screening budget: nothing to screen")
    names = [c for c in args.candidates.split(",") if c]
    scores = score_candidates(
        names, current.model, current.params, screen.traces, screen.residual, settings.fit
    )
    for s in scores:
        screened = screen_refit(s, current, screen, settings)
        state = _confirm(
            s, current, current.residual.kept_rss, train, test, settings, screened=screened
        )
        if state is None:
            print(f"{s.effect}: refit failed ({s.refit.get('status')})")
            continue
        d = loeo_errors(state.residual) - ref
        print(
            f"{s.effect}: summed {ref.sum() + d.sum():.3f} bar², ΔBIC {s.refit['delta_bic']:.1f}, "
            f"lower in {int((d < 0).sum())} of {len(d)} experiments, test "
            f"{state.test['rmse_bar']:.4f} bar"
        )
        print("   per experiment (candidate − reference, bar²): " + str(np.round(d, 3).tolist()))


if __name__ == "__main__":
    main()
