"""The outcome-blind size of an undeclared effect on the discovery stand (issue 7).

``calibrate_effect_size`` fixes an effect's strength from the stand's truth alone: the
multiple of its defaults at which it changes the training ramps' period-mean pressure by
0.10 bar RMS. These tests check the rule itself (a few stand runs, no fit, no discovery).
"""

from __future__ import annotations

import pytest

from clutchlab.physics import CircuitModel
from clutchlab.physics.effects import EFFECTS
from clutchlab.validation.discover.effect_size import (
    SIZE_PARAMETERS,
    TARGET_RMS_BAR,
    calibrate_effect_size,
    effect_change_rms,
    multiplier_range,
    size_parameters,
)


@pytest.mark.parametrize("effect", sorted(EFFECTS))
def test_size_parameters_stay_inside_their_bounds_over_the_multiplier_range(effect):
    specs = {p.name: p for p in CircuitModel().with_effects(effect).parameters}
    names = size_parameters(effect)
    assert names == SIZE_PARAMETERS.get(effect, tuple(EFFECTS[effect].STRENGTH))
    lo, hi = multiplier_range(effect)
    assert 0 < lo <= 1.0 <= hi
    for m in (lo, hi):
        for n in names:
            v = m * specs[n].default
            assert specs[n].lower - 1e-12 <= v <= specs[n].upper + 1e-12, (n, m, v)


def test_lags_are_sized_by_their_time_constant_and_the_delay_by_its_delay():
    assert size_parameters("sensor_lag") == ("slag_tau",)
    assert size_parameters("eddy_current_lag") == ("eddy_tau",)
    assert size_parameters("transport_delay") == ("delay_d", "delay_d0")
    assert size_parameters("supply_droop") == ("sup_r",)
    with pytest.raises(KeyError, match="unknown effect"):
        size_parameters("no_such_effect")


def test_change_is_nil_at_zero_strength_and_grows_with_it():
    zero = effect_change_rms("supply_droop", {"sup_r": 0.0})
    small = effect_change_rms("supply_droop", {"sup_r": 0.05})
    large = effect_change_rms("supply_droop", {"sup_r": 0.3})
    assert zero < 1e-4
    assert 0.005 < small < large


def test_calibration_reaches_the_target_or_stops_at_the_bound():
    size = calibrate_effect_size("supply_droop")
    assert not size.at_bound
    assert size.rms_bar == pytest.approx(TARGET_RMS_BAR, rel=0.02)
    assert size.overrides["sup_r"] == pytest.approx(size.multiplier * 0.15)
    # the recorded change is reproduced from the overrides alone
    assert effect_change_rms("supply_droop", size.overrides) == pytest.approx(size.rms_bar)
    weak = calibrate_effect_size("flow_force", target_bar=10.0)
    assert weak.at_bound and weak.rms_bar < 10.0
    assert weak.overrides["jet_kappa"] == pytest.approx(multiplier_range("flow_force")[1])
