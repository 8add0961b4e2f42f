"""A latch valve that cannot latch (latch_d2 ≤ latch_d1, or a spring too stiff for the
area step) is accepted within its bounds, but with a ParameterWarning naming the values."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from clutchlab.errors import ParameterWarning
from clutchlab.physics import CircuitModel, ParameterSet, drive_trace, knot_profile, simulate
from clutchlab.physics import parameters as parameters_module
from clutchlab.physics.components import latch_snap_problem

MODEL = CircuitModel()


@pytest.fixture(autouse=True)
def _fresh_once_registry(monkeypatch):
    """Each test sees the warning as a new process would (it is given once per process)."""
    monkeypatch.setattr(parameters_module, "_WARNED", set())


def test_no_differential_area_warns_naming_both_diameters():
    params = MODEL.default_params()
    with pytest.warns(ParameterWarning) as record:
        bad = params.replace(latch_d2=5.0)
    assert bad["latch_d2"] == 5.0  # accepted: a design sweep may mean it
    text = str(record[0].message)
    assert "latch_d2 = 5 mm" in text and "latch_d1 = 6 mm" in text
    assert "cannot latch" in text and "p_off" in text and "p_on" in text
    assert record[0].filename == __file__  # points at the user's line, not clutchlab's


def test_a_spring_too_stiff_for_the_area_step_warns_too():
    with pytest.warns(ParameterWarning, match="too small for the spring"):
        MODEL.params(latch_d2=6.2, latch_k=20.0)


def test_it_is_given_once_per_process():
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        MODEL.params(latch_d2=5.0)
        MODEL.params(latch_d2=5.5)
    assert sum(issubclass(w.category, ParameterWarning) for w in record) == 1


def test_latching_sets_and_fit_iterates_do_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error", ParameterWarning)
        MODEL.default_params()
        MODEL.params(latch_d2=8.0)
        MODEL.params(latch_d1=5.0, latch_d2=6.5)  # smaller valve, still a snap
        bad = MODEL.default_params().vector()
        bad[[p.name for p in MODEL.parameters].index("latch_d2")] = 5.0
        ParameterSet.from_vector(MODEL.parameters, bad)  # a fitter's iterate: no warning


def test_the_check_agrees_with_the_simulated_valve():
    """The warned set does not latch in simulation; the default one does."""
    t, i = knot_profile([0.0, 0.5, 10.5, 11.0, 21.0], [0.0, 0.0, 1100.0, 1100.0, 0.0])
    trace = drive_trace(t, i, dither_amp_mA=100.0, dither_freq_Hz=50.0)
    good = MODEL.default_params()
    assert latch_snap_problem(good) is None
    with pytest.warns(ParameterWarning):
        bad = good.replace(latch_d2=5.0)
    assert latch_snap_problem(bad) is not None
    latched = simulate(MODEL, good, trace).outputs["latch_state"]
    unlatched = simulate(MODEL, bad, trace).outputs["latch_state"]
    assert np.max(latched) > 0.99
    assert np.max(unlatched) < 0.5


def test_free_thresholds_law_is_judged_on_its_thresholds():
    model = CircuitModel().with_effects("latch_free_thresholds")
    with warnings.catch_warnings():
        warnings.simplefilter("error", ParameterWarning)
        model.params(latch_d2=5.0)  # the law's thresholds, not the areas, decide
    with pytest.warns(ParameterWarning, match="lthr_p_off is not below"):
        model.params(lthr_p_on=8.0, lthr_p_off=9.0)


def test_a_fits_own_probes_do_not_warn():
    """The staged start's threshold stage and snap matching build parameter sets on the way
    (a small stand gave latch_k·stroke = 9.3 N, a valve without snap, and the user read
    "the latch valve cannot latch" for values they never wrote): quiet inside a fit."""
    from clutchlab.physics.fit.staged import staged_start
    from clutchlab.physics.parameters import quiet_design_checks, without_design_checks

    with warnings.catch_warnings():
        warnings.simplefilter("error", ParameterWarning)
        with without_design_checks():
            MODEL.params(latch_d2=5.0)
        quiet_design_checks(lambda: MODEL.params(latch_d2=5.0))()
    from clutchlab.physics.fit import PhysicsFitter
    from clutchlab.validation.discover import discover

    # the staged start, the fit and the discovery (its strength probes of a latch effect gave
    # "p_off 9.28 > p_on 9.27 bar" on a stand whose fitted valve latches) are quiet
    for fn in (staged_start, PhysicsFitter.fit, discover):
        assert getattr(fn, "__wrapped__", None) is not None, fn
    with pytest.warns(ParameterWarning):  # outside, the user's own set still warns
        MODEL.params(latch_d2=5.0)
