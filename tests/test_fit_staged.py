"""Staged start of the physics fit: quasi-static data, static stage, latch thresholds."""

from __future__ import annotations

import time
import warnings

import numpy as np
import pytest

from clutchlab.data import Trace, dither_period_mean, dither_period_samples
from clutchlab.errors import FitWarning
from clutchlab.physics import CircuitModel, integrator, simulate
from clutchlab.physics.fit import FitSettings, PhysicsFitter
from clutchlab.physics.fit import sensitivity as sensitivity_mod
from clutchlab.physics.fit.fitter import resolve_free
from clutchlab.physics.fit.staged import (
    StagedStart,
    free_latch_structure,
    match_latch_snaps,
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


def test_staged_start_does_not_depend_on_the_compile_cache(zoo_small, monkeypatch):
    """On an empty compile cache the model's code compiles inside the staged start (beside
    the main stages' code, compiling in the background). Its result must be a warm cache's:
    compiling does not count against its stages' time limits."""
    model = CircuitModel()
    settings = FitSettings(progress=False)
    free = resolve_free(model, settings)
    start = model.default_params()
    t0 = time.perf_counter()
    warm, _ = staged_start(model, zoo_small, settings, start, free, 120.0)
    limit = 2.0 * (time.perf_counter() - t0) + 2.0  # the static stage's limit below
    original, slow_calls = integrator.load_or_compile, []

    def slow_first_compile(*args, **kwargs):  # the first compile outlasts the whole limit
        if not slow_calls:
            slow_calls.append(args[1])
            time.sleep(limit)
        return original(*args, **kwargs)

    monkeypatch.setattr(integrator, "load_or_compile", slow_first_compile)
    monkeypatch.setattr(sensitivity_mod, "load_or_compile", slow_first_compile)
    integrator.chunk_function.cache_clear()
    sensitivity_mod.sensitivity_chunk.cache_clear()
    try:
        cold, info = staged_start(model, zoo_small, settings, start, free, limit)
    finally:
        integrator.chunk_function.cache_clear()
        sensitivity_mod.sensitivity_chunk.cache_clear()
    assert slow_calls, "no code was compiled: the test did not exercise a cold cache"
    assert {n: cold[n] for n in free} == {n: warm[n] for n in free}
    assert not any("time limit" in note for note in info.notes), info.notes


def test_no_staged_start_with_a_user_start(zoo_small):
    model = CircuitModel()
    fitter = PhysicsFitter(
        model, FitSettings(progress=False, max_iter=1, time_limit_s=20), model.default_params()
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        fitter.fit(zoo_small)
    assert fitter.staged_ is None


def _snap_currents(model, params, trace):
    """Latch-on / latch-off nominal current (mA) of the model's own simulated snaps."""
    y = simulate(model, params, trace).pressure_bar
    k_on, k_off = measured_latch_indices(trace.with_signals(clutch_pressure_bar=y))
    i = dither_period_mean(trace.get("current_cmd_mA"), dither_period_samples(trace))
    return np.array([i[k_on], i[k_off]])


def _measured_currents(trace):
    k_on, k_off = measured_latch_indices(trace)
    i = dither_period_mean(trace.get("current_cmd_mA"), dither_period_samples(trace))
    return np.array([i[k_on], i[k_off]])


@pytest.mark.parametrize("law", ["spring", "thresholds"])
def test_latch_snaps_are_matched_on_a_circuit_that_is_not_ours(zoo_small, law):
    """The threshold reading alone leaves the model's snaps tens of mA off on this plant;
    the matching brings both within a few mA, judged by a fresh simulation."""
    model = CircuitModel()
    settings = FitSettings(progress=False)
    free = resolve_free(model, settings)
    params, info = staged_start(model, zoo_small, settings, model.default_params(), free, 30.0)
    if law == "thresholds":
        model, params = free_latch_structure(model, params, info)
        free = resolve_free(model, settings)
    slow = zoo_small[1]
    measured = _measured_currents(slow)
    before = np.abs(_snap_currents(model, params, slow) - measured)
    matched = match_latch_snaps(model, params, zoo_small, free, settings, info)
    after = np.abs(_snap_currents(model, matched, slow) - measured)
    assert after.max() <= max(3.0, 0.3 * before.max()), (before, after)
    rec = info.latch_match_mA
    assert rec["simulations"] <= 7
    # the matching simulates with the fit's 2 substeps, the check with the default 4
    assert np.allclose([abs(rec["on_after"]), abs(rec["off_after"])], after, atol=1.0)
    assert "latch snaps matched" in info.summary()
    moved = {n for n in matched if matched[n] != params[n]}
    latch = {"spring": {"latch_F0", "latch_k"}, "thresholds": {"lthr_p_on", "lthr_p_off"}}[law]
    assert moved and moved <= latch


@pytest.fixture(scope="module")
def known_latch():
    """Data from clutchlab's own model with a stiffer, weaker latch spring."""
    from clutchlab.physics.stand import StandConfig, run_stand

    cfg = StandConfig(
        builtin_effects=False,
        settings=(DitherSetting(50.0, "A"),),
        ramps=RAMPS,
        seed=3,
        overrides={"latch_F0": 27.0, "latch_k": 3.0},
    )
    return list(run_stand(cfg, progress=False).dataset)


def test_latch_snap_matching_recovers_a_known_latch(known_latch):
    """Data from clutchlab's own model with a stiffer, weaker latch spring: started from the
    datasheet latch, the matching finds spring values that snap where the data do."""
    model = CircuitModel()
    data = known_latch
    settings = FitSettings(progress=False)
    free = resolve_free(model, settings)
    info = StagedStart(static_experiments=[data[1].name])  # the datasheet curve is the truth
    matched = match_latch_snaps(model, model.default_params(), data, free, settings, info)
    slow = data[1]
    err = np.abs(_snap_currents(model, matched, slow) - _measured_currents(slow))
    assert err.max() <= 2.0, (err, info.latch_match_mA)
    assert abs(info.latch_match_mA["on_before"]) > 5.0


@pytest.mark.parametrize("halvings", [0, 4])
def test_a_step_onto_a_bound_is_halved_not_the_end(known_latch, monkeypatch, halvings):
    """With the spring rate bounded at 2.22 N/mm the first Newton step (to 2.25) is clipped.
    Stopping there (the matching before session 59, ``halvings=0``) leaves the snaps where
    they were; halving the step moves them most of the way (the data's own spring rate,
    2.3 N/mm when matched unbounded, is out of bounds)."""
    from clutchlab.physics.fit import staged

    monkeypatch.setattr(staged, "_MATCH_HALVINGS", halvings)
    model = CircuitModel()
    settings = FitSettings(progress=False, bounds={"latch_k": (0.2, 2.22)})
    free = resolve_free(model, settings)
    info = StagedStart(static_experiments=[known_latch[1].name])
    matched = match_latch_snaps(model, model.default_params(), known_latch, free, settings, info)
    rec = info.latch_match_mA
    before = max(abs(rec["on_before"]), abs(rec["off_before"]))
    after = max(abs(rec["on_after"]), abs(rec["off_after"]))
    assert before > 10.0, rec
    if halvings:
        assert after < 0.5 * before, rec
        assert 2.0 < matched["latch_k"] < 2.22
    else:
        assert after == before and matched["latch_k"] == 2.0, rec  # nothing matched


def test_latch_snap_matching_leaves_a_fixed_latch_and_a_model_without_snaps(zoo_small):
    model = CircuitModel()
    settings = FitSettings(progress=False, free=("vfs_K_m", "reg_F0"))
    start = model.default_params()
    info = StagedStart()
    assert match_latch_snaps(model, start, zoo_small, settings.free, settings, info) is start
    assert info.latch_match_mA == {}
    # Without a static stage nothing is matched.
    free = resolve_free(model, FitSettings(progress=False))
    assert match_latch_snaps(model, start, zoo_small, free, settings, info) is start
    assert any("no static stage" in n for n in info.notes)
    # A model that never reaches line pressure cannot be matched: kept, and said so.
    info = StagedStart(static_experiments=[zoo_small[1].name])
    weak = start.replace(vfs_K_m=model.default_params().spec("vfs_K_m").lower)
    kept = match_latch_snaps(model, weak, zoo_small, free, settings, info)
    assert kept is weak
    assert any("does not snap" in n for n in info.notes)
