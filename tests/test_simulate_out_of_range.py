"""simulate() on a design whose fixed step is too long: finite pressures of tens to 10⁴ bar
used to be returned without a word to a user simulating a design of their own."""

from __future__ import annotations

import warnings

import pytest
from test_sweep_failures import UNRESOLVED

from clutchlab.errors import ModelError, SimulationError, SimulationWarning
from clutchlab.physics import (
    CircuitModel,
    SimulationSettings,
    drive_trace,
    knot_profile,
    simulate,
)


@pytest.fixture(scope="module")
def case():
    model = CircuitModel()
    t, i = knot_profile([0, 0.5, 3.0, 3.5, 6.0], [0, 0, 1100, 1100, 0], 1000.0)
    trace = drive_trace(t, i, dither_amp_mA=120, dither_freq_Hz=50, name="fast")
    return model, model.default_params().replace(**UNRESOLVED, vfs_d_orf=0.6), trace


def test_an_unphysical_result_warns_naming_output_value_time_and_remedy(case):
    model, params, trace = case
    with pytest.warns(SimulationWarning) as record:
        res = simulate(model, params, trace)
    (w,) = record
    msg = str(w.message)
    assert msg.startswith("fast: ")
    assert "outside the range the circuit can reach [-1, 26.55] bar" in msg
    assert "raise substeps, or use method='radau'" in msg
    assert w.filename == __file__  # points at the caller, not at clutchlab
    assert res.out_of_range() == msg  # the result is still returned


def test_raise_and_ignore(case):
    model, params, trace = case
    with pytest.raises(SimulationError, match="outside the range the circuit can reach"):
        simulate(model, params, trace, SimulationSettings(out_of_range="raise"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = simulate(model, params, trace, SimulationSettings(out_of_range="ignore"))
    assert res.out_of_range() is not None


def test_the_remedy_works_and_a_sound_design_is_silent(case):
    model, params, trace = case
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fine = simulate(model, params, trace, SimulationSettings(substeps=16))
        default = simulate(model, None, trace)
    assert fine.out_of_range() is None
    assert default.out_of_range() is None


def test_an_unknown_policy_is_refused():
    with pytest.raises(ModelError, match="out_of_range 'skip' is not warn, raise or ignore"):
        SimulationSettings(out_of_range="skip")
