"""The ``latch_on_lag`` law and the fit's latch lag stage.

A latch that trips on a lagging pressure snaps later behind a fast rising ramp than the
model's latch, and releases on its own spring: with one pair of thresholds the solver trades
the slow ramps' snaps against the fast ones' (the zoo's preisach_accumulator seed 1: slow
snaps 4-6 mA late, fast ones 8-32 mA early). The law delays the latch-on in proportion to
the rising command's rate and leaves the release alone; the stage reads it and the two
thresholds off both rates' snaps and adds it only where leave-one-experiment-out says they
ask for it. Identity at its default and smoothness are checked for every flexible law in
``test_structure_laws``.
"""

from __future__ import annotations

import numpy as np
import pytest
from latch_support import matched_stage_inputs, own_model_runs, switch_currents

from clutchlab.physics import CircuitModel
from clutchlab.physics.effects import FLEXIBLE_LAWS
from clutchlab.physics.fit.latch_band import BAND_MIN_MA
from clutchlab.physics.fit.latch_lag import (
    LAG_FINISH_S,
    LAG_GAIN,
    lag_design,
    latch_lag_structure,
)
from clutchlab.physics.fit.staged import (
    _measured_latches,
    quasi_static_traces,
    ramp_rate,
    snap_offsets_each,
)

LAW = "latch_on_lag"
MODEL = CircuitModel().with_effects(LAW)
#: The law in the data of ``own_runs["law"]`` (bar per A/s of rising ramp).
TRUE_R = 0.6


@pytest.fixture(scope="module")
def own_runs():
    """The stand's 18 experiments with the clutch pressure of clutchlab's own model: without
    the law, and with it."""
    return own_model_runs(MODEL, lolag_r=TRUE_R)


def test_it_delays_the_latch_on_with_the_ramp_rate_and_leaves_the_release(own_runs):
    moved = {}
    traces = {tr.name: tr for tr in own_runs["plain"]}
    for ramp in ("fast", "slow"):
        tr = traces[f"{ramp}_50Hz_B"]
        on0, off0 = switch_currents(MODEL, tr)
        on1, off1 = switch_currents(MODEL, tr, lolag_r=0.5)
        assert off1 == pytest.approx(off0, abs=0.5), (ramp, off0, off1)  # release: not moved
        moved[ramp] = on1 - on0
    # later on the rise, ~5x more on the fast ramp (its rate is ~5x the slow one's)
    assert moved["fast"] > 10.0 and moved["fast"] > 3.0 * moved["slow"] > 0.0, moved


def test_it_is_added_to_a_fit_already_made_only():
    from clutchlab.physics.fit.structure import STRUCTURES
    from clutchlab.validation.discover.alternatives import alternatives_for

    cls = FLEXIBLE_LAWS[LAW]
    assert cls.WARM_ONLY and not cls.HELD_SWITCH
    assert cls.fit_parameters() == ("lolag_r",)
    assert all(LAW not in laws for laws in STRUCTURES.values())
    assert LAW not in [a.law for a in alternatives_for(CircuitModel(), ("vfs_K_m",), 9)]


def test_design_moves_the_latch_on_with_the_ramp_rate_only(own_runs):
    traces = own_runs["plain"]
    latch = _measured_latches(traces)
    used = [tr for tr in traces if tr.name in latch][:4]
    jac = np.array([[20.0, 1.0], [2.0, 15.0]])
    a = lag_design(used, latch, jac)
    assert a.shape == (2 * len(used), 3)
    np.testing.assert_allclose(a[0::2, :2], np.tile(jac[0], (len(used), 1)))
    np.testing.assert_allclose(a[1::2, :2], np.tile(jac[1], (len(used), 1)))
    rates = np.array([ramp_rate(tr) for tr in used])
    np.testing.assert_allclose(a[0::2, 2], jac[0, 0] * 1e-3 * rates)  # the on threshold's
    np.testing.assert_allclose(a[1::2, 2], 0.0)  # the release: not moved
    with pytest.raises(KeyError, match="no measured snap"):
        lag_design(used, {}, jac)


_matched = matched_stage_inputs


@pytest.mark.parametrize("which", ["plain", "law"])
def test_law_is_added_only_where_the_fast_snaps_ask(which, own_runs):
    traces = own_runs[which]
    model, start, free, settings, info = _matched(traces)
    chosen, params = latch_lag_structure(model, start, traces, free, settings, info)
    rec = info.latch_band
    added = LAW in chosen.effect_names
    assert added == (which == "law"), info.summary()
    assert rec["lag_experiments"] == 12.0  # three slow, nine fast
    if added:
        assert rec["lag_offsets_rms_mA"] > BAND_MIN_MA, rec
        assert rec["lag_loo_mA"] < LAG_GAIN * rec["lag_loo_thresholds_mA"], rec
        assert rec["lag_offsets_after_mA"] < 0.3 * rec["lag_offsets_rms_mA"], rec
        assert params["lolag_r"] == pytest.approx(TRUE_R, rel=0.3)
        assert "structure: latch_on_lag" in info.summary()
        # the slow snaps stay matched
        slow = quasi_static_traces(traces)[:3]
        latch = _measured_latches(slow)
        after = snap_offsets_each(chosen, params, slow, latch, settings.substeps)
        assert np.sqrt(np.mean(np.square(after))) < 3.0, after
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
    traces = own_runs["law"]
    budget = LAG_FINISH_S - 1.0
    chosen, params = latch_lag_structure(model, start, traces, free, settings, info, budget)
    assert chosen is model and params is start
    assert "latch lag: no time left" in info.summary()
