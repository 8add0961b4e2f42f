"""Staged start of the physics fit: quasi-static data, static stage, latch thresholds."""

from __future__ import annotations

import time
import warnings

import numpy as np
import pytest

from clutchlab.data import Trace, dither_period_mean, dither_period_samples
from clutchlab.errors import FitWarning
from clutchlab.physics import CircuitModel, simulate
from clutchlab.physics.fit import FitSettings, PhysicsFitter
from clutchlab.physics.fit.fitter import resolve_free
from clutchlab.physics.fit.staged import (
    StagedStart,
    free_latch_structure,
    measured_latch_indices,
    quasi_static_traces,
    staged_start,
)
from clutchlab.physics.stand import DitherSetting, RampProfile
from clutchlab.physics.stand.plants import PlantConfig, run_plant

RAMPS = (RampProfile("fast", 2.5, 0.5), RampProfile("slow", 10.0, 0.5))


@pytest.fixture(scope="module")
def zoo_small():
    """A zoo plant (not clutchlab's equations), one dither setting, a fast and a slow ramp."""
    cfg = PlantConfig("saturating_lugre", settings=(DitherSetting(50.0, "A"),), ramps=RAMPS, seed=5)
    return list(run_plant(cfg, progress=False).dataset)


def _rising_rmse(model, params, trace):
    k_on, _ = measured_latch_indices(trace)
    n = dither_period_samples(trace)
    y = dither_period_mean(trace.get("clutch_pressure_bar"), n)
    yh = dither_period_mean(simulate(model, params, trace).pressure_bar, n)
    i = trace.get("current_cmd_mA")
    sel = (np.arange(len(y)) < k_on - 500) & (i > 250)
    return float(np.sqrt(np.mean((y[sel] - yh[sel]) ** 2)))


def test_quasi_static_traces_are_the_slowest_by_the_data(zoo_small):
    fast, slow = zoo_small
    assert [t.name for t in quasi_static_traces([fast, slow])] == [slow.name]
    # The rate comes from the current, not the label.
    relabelled = Trace("fast_as_slow", dict(fast.signals), meta=dict(fast.meta, ramp="slow"))
    assert quasi_static_traces([relabelled, slow])[0].name == slow.name


def test_measured_latch_indices(zoo_small):
    slow = zoo_small[1]
    k_on, k_off = measured_latch_indices(slow)
    i = slow.get("current_cmd_mA")
    assert 800 < i[k_on] < 1100 and 650 < i[k_off] < i[k_on] - 50
    no_latch = slow.with_signals(
        clutch_pressure_bar=np.minimum(slow.get("clutch_pressure_bar"), 12)
    )
    assert measured_latch_indices(no_latch) is None


def test_staged_start_moves_the_static_curve_and_the_latch_toward_the_data(zoo_small):
    model = CircuitModel()
    settings = FitSettings(progress=False)
    start = model.default_params()
    free = resolve_free(model, settings)
    t0 = time.perf_counter()
    params, info = staged_start(model, zoo_small, settings, start, free, 30.0)
    assert time.perf_counter() - t0 < 60
    slow = zoo_small[1]
    before, after = _rising_rmse(model, start, slow), _rising_rmse(model, params, slow)
    assert after < 0.5 * before, (before, after)
    assert info.static_experiments == [slow.name]
    assert info.thresholds_bar is not None and info.thresholds_bar[0] > info.thresholds_bar[1]
    assert set(info.values) <= set(free) and {"latch_F0", "vfs_K_m"} <= set(info.values)
    assert "staged start" in info.summary()
    # Only free parameters move.
    fixed = [n for n in start if n not in free]
    assert all(params[n] == start[n] for n in fixed)


def test_free_latch_structure_keeps_the_start_and_sets_the_thresholds():
    model = CircuitModel()
    start = model.default_params().replace(vfs_K_m=17.0)
    info = StagedStart(thresholds_bar=(9.5, 9.3), latch_tie_violated=True)
    free_model, params = free_latch_structure(model, start, info)
    assert "latch_free_thresholds" in free_model.effect_names
    assert params["lthr_p_on"] == pytest.approx(9.5) and params["lthr_p_off"] == pytest.approx(9.3)
    assert params["vfs_K_m"] == 17.0
    assert any("latch_free_thresholds" in n for n in info.notes)


def test_tie_violation_is_detected_and_the_fit_switches_structure(zoo_small):
    """Latch-off far below latch-on (wide latch hysteresis): beyond the datasheet area ratio."""
    from clutchlab.physics.fit import staged as staged_mod

    model = CircuitModel()
    settings = FitSettings(progress=False)
    start = model.default_params()
    free = resolve_free(model, settings)
    info = StagedStart()
    slow = zoo_small[1]
    latch = {slow.name: measured_latch_indices(slow)}
    # Move the data's latch-off down to 450 mA on the falling branch.
    k_on, k_off = latch[slow.name]
    i = slow.get("current_cmd_mA")
    k_low = k_off + int(np.argmin(np.abs(i[k_off:] - 450.0)))
    latch[slow.name] = (k_on, k_low)
    staged_mod._threshold_stage(model, start, [slow], latch, settings, free, info)
    on, off = info.thresholds_bar
    assert off < 0.7 * on
    assert info.latch_tie_violated
    # The true thresholds are representable: no violation.
    info = StagedStart()
    latch[slow.name] = (k_on, k_off)
    staged_mod._threshold_stage(model, start, [slow], latch, settings, free, info)
    assert not info.latch_tie_violated


def test_fit_with_staged_start_stays_within_its_time_limit(zoo_small):
    limit = 25.0
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        fitter = PhysicsFitter(settings=FitSettings(progress=False, time_limit_s=limit))
        fitter.fit(zoo_small)
    wall = time.perf_counter() - t0
    assert wall <= limit + 3.0, wall
    assert fitter.staged_ is not None and fitter.staged_.wall_s < limit
    cost = fitter.result_.cost_history
    assert min(cost) <= cost[0]


def test_no_staged_start_with_a_user_start(zoo_small):
    model = CircuitModel()
    fitter = PhysicsFitter(
        model, FitSettings(progress=False, max_iter=1, time_limit_s=20), model.default_params()
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        fitter.fit(zoo_small)
    assert fitter.staged_ is None
