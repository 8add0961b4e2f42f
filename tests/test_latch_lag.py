"""The fit's latch lag stage: ``latch_pilot_lag`` from the slow and fast ramps' snaps.

With one lag for the regulated branch's pilot and the latch's, a circuit whose latch snaps
later behind a fast ramp than that lag allows leaves the solver trading the slow snaps
against the fast ones (the zoo's preisach_accumulator seed 1: slow snaps 4-6 mA late, fast
ones 8-32 mA early). The stage reads the latch pilot's lag and the two thresholds off both
rates' snaps and adds the law only where leave-one-experiment-out says they ask for it.
"""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.physics import CircuitModel, simulate
from clutchlab.physics.fit import FitSettings
from clutchlab.physics.fit.fitter import resolve_free
from clutchlab.physics.fit.latch_band import BAND_MIN_MA
from clutchlab.physics.fit.latch_lag import (
    LAG_FINISH_S,
    LAG_GAIN,
    lag_design,
    latch_lag_structure,
)
from clutchlab.physics.fit.staged import (
    _measured_latches,
    match_latch_snaps,
    ramp_rate,
    staged_start,
)
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

LAW = "latch_pilot_lag"
SETTINGS = tuple(DitherSetting(f, s) for f in (30.0, 50.0, 70.0) for s in ("A", "B", "C"))
RAMPS = (RampProfile("fast", 2.5, 0.5), RampProfile("slow", 12.0, 0.5))
#: The latch pilot's lag in the data of ``own_runs["law"]`` (ms).
TRUE_TAU_MS = 40.0


@pytest.fixture(scope="module")
def own_runs():
    """The stand's 18 experiments (fast and slow, nine dither settings) with the clutch
    pressure of clutchlab's own model: without a latch pilot lag, and with one."""
    traces = list(run_stand(StandConfig(settings=SETTINGS, ramps=RAMPS), False).dataset)
    plain = CircuitModel()
    truth = plain.default_params()
    lagged = plain.with_effects(LAW)
    with_law = lagged.params(**truth.values, llag_w=1.0, llag_tau=TRUE_TAU_MS)
    out = {}
    for name, model, params in (("plain", plain, truth), ("law", lagged, with_law)):
        out[name] = [
            tr.with_signals(clutch_pressure_bar=simulate(model, params, tr).pressure_bar)
            for tr in traces
        ]
    return out


def _matched(traces, effects=()):
    """The stage's inputs on ``traces``: clutchlab's model without the lag (and with
    ``effects``), its datasheet values, free parameters, settings and a staged start's
    record (its latch-matching Jacobian)."""
    plain = CircuitModel()
    settings = FitSettings(progress=False, regulator_lag="off")
    free = resolve_free(plain, settings)
    _, info = staged_start(plain, traces, settings, plain.default_params(), free, 20.0)
    match_latch_snaps(plain, plain.default_params(), traces, free, settings, info)
    assert info.latch_jacobian is not None, info.summary()
    model = plain.with_effects(*effects) if effects else plain
    return model, model.default_params(), free, settings, info


def test_design_delays_the_latch_on_and_advances_the_latch_off_by_the_ramp_rate(own_runs):
    traces = own_runs["plain"]
    latch = _measured_latches(traces)
    used = [tr for tr in traces if tr.name in latch][:4]
    jac = np.array([[20.0, 1.0], [2.0, 15.0]])
    a = lag_design(used, latch, jac)
    assert a.shape == (2 * len(used), 3)
    np.testing.assert_allclose(a[0::2, :2], np.tile(jac[0], (len(used), 1)))
    np.testing.assert_allclose(a[1::2, :2], np.tile(jac[1], (len(used), 1)))
    rates = np.array([ramp_rate(tr) for tr in used])
    np.testing.assert_allclose(a[0::2, 2], 1e-3 * rates)  # mA per ms: later on the rise
    np.testing.assert_allclose(a[1::2, 2], -1e-3 * rates)  # lower on the fall
    with pytest.raises(KeyError, match="no measured snap"):
        lag_design(used, {}, jac)


@pytest.mark.parametrize("which", ["plain", "law"])
def test_law_is_added_only_where_the_fast_snaps_lag_more(which, own_runs):
    traces = own_runs[which]
    model, start, free, settings, info = _matched(traces)
    chosen, params = latch_lag_structure(model, start, traces, free, settings, info)
    rec = info.latch_band
    added = LAW in chosen.effect_names
    ask = (
        rec["lag_offsets_rms_mA"] > BAND_MIN_MA
        and rec["lag_loo_mA"] < LAG_GAIN * rec["lag_loo_thresholds_mA"]
        and rec["lag_tau_linear_ms"] >= 2.0
    )
    assert added == (which == "law"), info.summary()
    assert rec["lag_experiments"] == 12.0  # three slow, nine fast
    if added:
        assert ask, rec
        assert rec["lag_offsets_after_mA"] < 0.3 * rec["lag_offsets_rms_mA"], rec
        assert params["llag_w"] == 1.0
        assert params["llag_tau"] == pytest.approx(TRUE_TAU_MS, rel=0.3)
        assert "structure: latch_pilot_lag" in info.summary()
    else:
        assert rec["lag_offsets_rms_mA"] < 1.0, rec  # the model's own snaps
        assert chosen is model and params is start
        assert "latch lag: not added" in info.summary()


def test_not_run_after_a_stage_that_matched_the_latch(own_runs):
    """The band and rate stages re-match the thresholds to the snaps themselves."""
    model, start, free, settings, info = _matched(own_runs["law"], ("latch_dither_band",))
    chosen, params = latch_lag_structure(model, start, own_runs["law"], free, settings, info)
    assert chosen is model and params is start
    assert "names latch_dither_band (its stage matched the latch)" in info.summary()


def test_not_run_without_time_for_its_finish(own_runs):
    """The law's new state needs its sensitivity code compiled for the result (~9 s cold)."""
    model, start, free, settings, info = _matched(own_runs["law"])
    budget = LAG_FINISH_S - 1.0
    chosen, params = latch_lag_structure(
        model, start, own_runs["law"], free, settings, info, budget
    )
    assert chosen is model and params is start
    assert "latch lag: no time left" in info.summary()
