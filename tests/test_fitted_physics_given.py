"""``physics_fitted`` from a fit made before (``evaluate --physics-model``), never one that saw a
test experiment."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from clutchlab.errors import FitError, FitWarning
from clutchlab.physics.fit import FitSettings, PhysicsFitter
from clutchlab.validation.variants import FittedPhysics


@pytest.fixture(scope="module")
def short_fit(stand_run):
    train = list(stand_run.dataset.select(ramps=["fast"]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        fitter = PhysicsFitter(
            settings=FitSettings(progress=False, max_iter=2, staged_start=False)
        ).fit(train)
    return fitter, train


def test_given_fit_is_used_as_is(short_fit, stand_run):
    fitter, train = short_fit
    model = FittedPhysics(fitted=fitter).fit(train)
    assert model.result_ is fitter.result_
    trace = stand_run.dataset["medium_50Hz_B"]
    np.testing.assert_array_equal(model.predict(trace), fitter.predict(trace))
    # A FitResult (e.g. read from fit-physics' JSON) works the same.
    again = FittedPhysics(fitted=fitter.result_).fit(train)
    np.testing.assert_allclose(again.predict(trace), fitter.predict(trace), atol=1e-12)


def test_given_fit_on_other_experiments_is_refused(short_fit, stand_run):
    fitter, _ = short_fit
    with_test = list(stand_run.dataset.select(ramps=["fast", "medium"]))
    with pytest.raises(FitError, match="other experiments"):
        FittedPhysics(fitted=fitter).fit(with_test)
