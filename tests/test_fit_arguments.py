"""PhysicsFitter and the ML estimators name a wrong argument instead of failing inside."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from synthetic import make_trace

from clutchlab.errors import DataError, FitError
from clutchlab.physics.fit import FitSettings, PhysicsFitter
from clutchlab.residual_ml import GPBaseline

QUICK = FitSettings(time_limit_s=1, progress=False)


@pytest.mark.parametrize(
    ("fitter", "needle"),
    [
        # AttributeError "'dict' object has no attribute 'train_ramps'" before
        (PhysicsFitter(settings={"time_limit_s": 5}), "settings must be a FitSettings or None"),
        # AttributeError "'str' object has no attribute 'default_params'" before
        (PhysicsFitter(model="sensor_lag"), "model must be a CircuitModel or None, not str"),
    ],
)
def test_constructor_arguments_of_the_wrong_type_are_named(fitter, needle):
    with pytest.raises(FitError, match=needle):
        fitter.fit([make_trace([0.0, 1.0], [0.0, 800.0])])


@pytest.mark.parametrize("path", ["stand", Path("stand")])
def test_a_path_is_refused_with_the_way_to_load_it(path):
    """fit("stand") iterated the characters: "'str' object has no attribute 'has'"."""
    with pytest.raises(FitError, match=r"not a path \('stand'\).*load_dataset\(path\)"):
        PhysicsFitter(settings=QUICK).fit(path)
    with pytest.raises(DataError, match=r"not a path \('stand'\).*load_dataset\(path\)"):
        GPBaseline().fit(path)  # "requires y to be passed" before


def test_one_trace_is_one_experiment_and_a_mixed_list_is_named():
    """fit(trace) failed with "'Trace' object is not iterable"."""
    flat = make_trace([0.0, 1.0], [0.0, 0.0])
    with pytest.raises(FitError, match=r"no excitation"):  # got as far as the data checks
        PhysicsFitter(settings=QUICK).fit(flat)
    with pytest.raises(FitError, match="expected only Traces, got also str"):
        PhysicsFitter(settings=QUICK).fit([flat, "medium_50Hz_B"])
    with pytest.raises(FitError, match="not int"):
        PhysicsFitter(settings=QUICK).fit(3)


def test_the_fit_and_the_ml_estimators_read_experiments_through_one_function():
    """PhysicsFitter._training and residual_ml had each their own path / type checks."""
    from clutchlab.data import as_traces
    from clutchlab.residual_ml import base

    assert base.as_traces is as_traces
    with pytest.raises(DataError, match=r"not int"):
        as_traces(3, arrays=False)
    assert as_traces(np.zeros((3, 2))) is None  # a feature matrix, for the ML estimators
    with pytest.raises(DataError, match=r"expected only Traces, got also int"):
        as_traces([3, 4], arrays=False)
    with pytest.raises(FitError, match="no training experiments"):
        PhysicsFitter(settings=QUICK).fit([])
