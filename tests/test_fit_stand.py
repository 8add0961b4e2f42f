"""Physics fit on the stand's default dataset, scored on the unseen medium ramp (slow).

Issue 4, must-show 2: trained on the fast and slow experiments only, the fitted model
must cut the RMSE of the dither-period-averaged pressure on the medium ramp by at least
50 % against the default-parameter model. Takes about two minutes on 2 cores.
"""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.data import dither_period_mean, dither_period_samples, pressure_metrics
from clutchlab.physics import CircuitModel, simulate
from clutchlab.physics.fit import FitSettings, PhysicsFitter
from clutchlab.physics.stand import StandConfig, run_stand

pytestmark = pytest.mark.slow


def _period_mean_rmse(traces, model, params) -> float:
    measured, predicted = [], []
    for trace in traces:
        n = dither_period_samples(trace)
        measured.append(dither_period_mean(trace.get("clutch_pressure_bar"), n))
        predicted.append(dither_period_mean(simulate(model, params, trace).pressure_bar, n))
    return pressure_metrics(np.concatenate(measured), np.concatenate(predicted))["rmse_bar"]


def test_fit_on_training_ramps_halves_the_medium_ramp_error():
    dataset = run_stand(StandConfig(), progress=False).dataset
    fitter = PhysicsFitter(settings=FitSettings(progress=False))
    fitter.fit(dataset.select(ramps=["fast", "slow"]))  # the medium ramp is never seen
    assert fitter.result_.success
    assert not any(name.startswith("medium") for name in fitter.result_.train)

    medium = list(dataset.select(ramps=["medium"]))
    before = _period_mean_rmse(medium, CircuitModel(), None)
    after = _period_mean_rmse(medium, fitter.model_, fitter.params_)
    print(f"medium-ramp RMSE: default {before:.4f} bar, fitted {after:.4f} bar")
    assert after <= 0.5 * before
