"""The ``latch_line_threshold`` flexible law: latch thresholds that follow line pressure.

A latch valve balanced against line pressure (the zoo's stribeck_supply: thresholds
proportional to line) snaps and releases at currents that follow the line pressure's wander;
clutchlab's datasheet latch does not. The law moves the thresholds by ``r_on`` / ``r_off``
bar per bar of line above ``p_ref``; the fit's latch band stage reads the two slopes off
the slow ramps' snaps and adds the law only where leave-one-experiment-out asks for it.
Identity at its defaults and units are checked for every flexible law in
``test_structure_laws``.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from latch_support import switch_currents

from clutchlab.errors import FitWarning
from clutchlab.physics import CircuitModel, simulate
from clutchlab.physics.effects import FLEXIBLE_LAWS, LatchLineThreshold
from clutchlab.physics.fit import FitSettings, PhysicsFitter
from clutchlab.physics.fit.fitter import resolve_free
from clutchlab.physics.fit.latch_band import (
    LINE_MIN_BAR,
    band_design,
    latch_band_structure,
    line_design,
)
from clutchlab.physics.fit.staged import (
    _line,
    _measured_latches,
    match_latch_snaps,
    quasi_static_traces,
    staged_start,
)
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

LAW = "latch_line_threshold"
MODEL = CircuitModel().with_effects(LAW)
SLOW = (RampProfile("slow", 12.0, 0.5),)
SETTINGS = tuple(DitherSetting(f, s) for f in (30.0, 50.0, 70.0) for s in ("A", "B", "C"))


@pytest.fixture(scope="module")
def fast_trace():
    cfg = StandConfig(settings=(DitherSetting(50.0, "B"),), ramps=(RampProfile("fast", 2.5, 0.5),))
    return next(iter(run_stand(cfg, False).dataset))


def _with_line(trace, line_bar: float):
    signals = dict(trace.signals)
    signals["line_pressure_bar"] = np.full(len(trace), line_bar)
    return type(trace)(trace.name, signals, meta=dict(trace.meta))


def _switch_currents(trace, **values) -> tuple[float, float]:
    """Latch-on and latch-off currents (mA) of the law's model at ``values``."""
    return switch_currents(MODEL, trace, **values)


def test_higher_line_moves_the_snap_and_the_release_later_by_their_own_slopes(fast_trace):
    at_ref = _with_line(fast_trace, 17.7)
    above = _with_line(fast_trace, 18.0)
    # at the reference line pressure the law does nothing
    moved = _switch_currents(at_ref, llt_r_on=1.0, llt_r_off=1.0, llt_p_ref=17.7)
    assert moved == pytest.approx(_switch_currents(at_ref), abs=0.5)
    # 0.3 bar above it, each slope moves its own switch later, and more than the other
    # switch (the smooth valve is part-open near its release: r_on acts there too, less)
    on0, off0 = _switch_currents(above, llt_p_ref=17.7)
    on1, off1 = _switch_currents(above, llt_r_on=1.0, llt_p_ref=17.7)
    on2, off2 = _switch_currents(above, llt_r_off=1.0, llt_p_ref=17.7)
    assert on1 - on0 > 15.0 and on1 - on0 > 1.5 * (off1 - off0), (on0, on1, off0, off1)
    assert off2 - off0 > 8.0 and off2 - off0 > 1.5 * (on2 - on0), (on0, on2, off0, off2)


def test_its_two_slopes_are_what_a_fit_frees_and_only_on_a_fit_already_made():
    from clutchlab.physics.fit.structure import STRUCTURES
    from clutchlab.validation.discover.alternatives import alternatives_for

    cls = FLEXIBLE_LAWS[LAW]
    assert cls is LatchLineThreshold
    assert cls.fit_parameters() == ("llt_r_on", "llt_r_off")  # p_ref is held
    assert cls.WARM_ONLY and not cls.HELD_SWITCH
    assert all(LAW not in laws for laws in STRUCTURES.values())
    free = ("vfs_K_m", "latch_F0")
    assert LAW not in [a.law for a in alternatives_for(CircuitModel(), free, 9)]


#: The law's slopes in the line-referenced data below.
TRUE_SLOPES = {"llt_r_on": 1.0, "llt_r_off": 0.6, "llt_p_ref": 17.7}


@pytest.fixture(scope="module")
def line_latch():
    """The stand's slow ramps (their line pressure wanders, ~0.1 bar), with the clutch
    pressure of the datasheet model whose latch thresholds follow line (``TRUE_SLOPES``):
    the mechanism test of the stage, which must find the law and its slopes. (On the zoo's
    stribeck_supply, whose thresholds are proportional to line, the held-back error fell
    by 35-64 % on three seeds: BENCHMARKS, session 58.)"""
    traces = list(run_stand(StandConfig(settings=SETTINGS, ramps=SLOW), False).dataset)
    out = []
    for tr in traces:
        p = simulate(MODEL, MODEL.params(**TRUE_SLOPES), tr).pressure_bar
        out.append(tr.with_signals(clutch_pressure_bar=p))
    return out


@pytest.fixture(scope="module")
def stand_slow():
    return list(run_stand(StandConfig(settings=SETTINGS, ramps=SLOW), False).dataset)


def test_line_columns_are_the_threshold_columns_times_the_line_at_the_snap(line_latch):
    traces = quasi_static_traces(line_latch)
    latch = _measured_latches(traces)
    used = [tr for tr in traces if tr.name in latch]
    jac = np.array([[20.0, 1.0], [2.0, 15.0]])
    a = line_design(used, latch, jac, 17.5)
    assert a.shape == (2 * len(used), 2) == (band_design(used, latch, jac).shape[0], 2)
    for row, tr in zip(range(0, len(a), 2), used, strict=True):
        line = _line(tr, len(tr))
        on, off = latch[tr.name]
        np.testing.assert_allclose(a[row], jac[0] * (line[on] - 17.5))
        np.testing.assert_allclose(a[row + 1], jac[1] * (line[off] - 17.5))


def _stage(traces, latch_band="auto"):
    model = CircuitModel()
    settings = FitSettings(progress=False, regulator_lag="off", latch_band=latch_band)
    free = resolve_free(model, settings)
    start, info = staged_start(model, traces, settings, model.default_params(), free, 20.0)
    start = match_latch_snaps(model, start, traces, free, settings, info)
    chosen, params = latch_band_structure(model, start, traces, free, settings, info)
    return chosen, params, info


def test_the_stage_adds_the_line_law_where_the_snaps_follow_line(line_latch):
    chosen, params, info = _stage(line_latch)
    band = info.latch_band
    assert "loo_line_mA" in band, info.summary()
    assert LAW in chosen.effect_names, info.summary()
    assert band["offsets_after_mA"] < band["offsets_rms_mA"], band
    # the fitted model's Jacobian (two simulations) counted with the start's and a round's
    assert band["jacobian_simulations"] == 2.0 and band["simulations"] >= 4.0, band
    # p_ref held at the median line pressure at the snaps; the slopes read off the data
    qs = quasi_static_traces(line_latch)
    latch = _measured_latches(qs)
    at = [_line(tr, len(tr))[k] for tr in qs if tr.name in latch for k in latch[tr.name]]
    assert np.std(at) > LINE_MIN_BAR
    assert params["llt_p_ref"] == pytest.approx(np.median(at))
    # the slopes it reads off the snaps are the data's
    assert params["llt_r_on"] == pytest.approx(TRUE_SLOPES["llt_r_on"], abs=0.3)
    assert params["llt_r_off"] == pytest.approx(TRUE_SLOPES["llt_r_off"], abs=0.3)
    assert "latch_line_threshold after the solver" in info.summary()


def test_latch_band_band_does_not_offer_it(line_latch):
    """``band``: the dither band law alone (the default before session 59)."""
    chosen, _, info = _stage(line_latch, "band")
    assert "loo_line_mA" not in info.latch_band, info.summary()
    assert LAW not in chosen.effect_names


def test_without_a_logged_line_pressure_the_line_law_is_not_offered(line_latch):
    traces = []
    for tr in line_latch:
        signals = {k: v for k, v in tr.signals.items() if k != "line_pressure_bar"}
        traces.append(type(tr)(tr.name, signals, meta=dict(tr.meta)))
    chosen, _, info = _stage(traces)
    assert "loo_line_mA" not in info.latch_band, info.summary()
    assert LAW not in chosen.effect_names


def test_clutchlabs_own_latch_does_not_ask_for_it(stand_slow):
    chosen, _, info = _stage(stand_slow)
    assert "loo_line_mA" in info.latch_band, info.summary()  # its line wanders too
    assert LAW not in chosen.effect_names, info.summary()


def test_a_fit_keeps_the_law_only_when_it_lowers_the_training_rms(line_latch, tmp_path):
    settings = FitSettings(progress=False, train_ramps=("slow",), max_iter=6, refine_max_iter=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)  # a fit stopped at a limit is fine here
        fitter = PhysicsFitter(settings=settings).fit(line_latch)
    band = fitter.staged_.latch_band
    assert "loo_line_mA" in band, fitter.staged_.summary()  # the stage ran after the solver
    kept = LAW in fitter.result_.effects
    if "training_rms_after_bar" in band:
        assert kept == (band["training_rms_after_bar"] < band["training_rms_before_bar"])
    assert kept, fitter.staged_.summary()
    res = fitter.result_
    assert not set(LatchLineThreshold.FIT) & set(res.free)  # held, not fitted
    assert res.values["llt_r_on"] != 0.0
    fitter.save(tmp_path / "fit.json")
    again = PhysicsFitter.load(tmp_path / "fit.json")
    np.testing.assert_allclose(again.predict(line_latch[0]), fitter.predict(line_latch[0]))
