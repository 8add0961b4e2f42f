"""The effect library: each effect changes the pressure when on, nothing at zero strength."""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.errors import ModelError
from clutchlab.physics import EFFECTS, CircuitModel, SimulationSettings, simulate

#: Interpreted CasADi (no C compiler involved): these traces are short.
SETTINGS = SimulationSettings(compile="never")

#: An effect "changes the pressure" when the sensor output moves by more than this (bar):
#: 2.5× the stand's sensor-noise σ (0.02 bar), far above the integrator's round-off.
MIN_CHANGE_BAR = 0.05

#: "Unchanged" at zero strength (the issue's bound).
ZERO_TOL_BAR = 1e-6


@pytest.fixture(scope="module")
def base_pressure(fast_ramp_trace):
    return simulate(CircuitModel(), None, fast_ramp_trace, SETTINGS).pressure_bar


@pytest.mark.parametrize("name", sorted(EFFECTS))
def test_effect_alone_changes_pressure_and_vanishes_at_zero(name, fast_ramp_trace, base_pressure):
    model = CircuitModel().with_effects(name)
    on = simulate(model, None, fast_ramp_trace, SETTINGS).pressure_bar
    zero = model.params(**{p: 0.0 for p in EFFECTS[name].STRENGTH})
    off = simulate(model, zero, fast_ramp_trace, SETTINGS).pressure_bar
    assert np.max(np.abs(on - base_pressure)) > MIN_CHANGE_BAR
    assert np.max(np.abs(off - base_pressure)) <= ZERO_TOL_BAR


def test_at_least_ten_effects_with_signatures():
    assert len(EFFECTS) >= 10
    for cls in EFFECTS.values():
        assert len(cls.signature) > 10


def test_with_effects_returns_a_new_frozen_model():
    base = CircuitModel()
    aug = base.with_effects("sensor_lag", "flow_force")
    assert base.effect_names == ()
    assert aug.effect_names == ("sensor_lag", "flow_force")
    assert {"slag_tau", "jet_kappa"} <= {p.name for p in aug.parameters}
    assert "slag_tau" not in {p.name for p in base.parameters}
    assert aug.without_effects("sensor_lag").effect_names == ("flow_force",)
    with pytest.raises(AttributeError):
        aug.effects = ()  # frozen


def test_unknown_effect_is_a_clear_error_listing_the_known_ones():
    with pytest.raises(ModelError) as exc:
        CircuitModel().with_effects("sensor_lagg")
    msg = str(exc.value)
    assert "sensor_lagg" in msg
    for name in EFFECTS:
        assert name in msg


def test_effect_switched_on_twice_is_an_error():
    with pytest.raises(ModelError, match="twice"):
        CircuitModel().with_effects("sensor_lag").with_effects("sensor_lag")
