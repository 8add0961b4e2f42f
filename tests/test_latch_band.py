"""The staged start's latch band stage: ``latch_dither_band`` estimated from the snaps.

A latch that trips on its pilot only after a dwell time (the zoo's quadratic_play) snaps at
currents that move with the dither amplitude and frequency; clutchlab's own latch does
not. The stage reads the law's five parameters (with the two thresholds) off the slow
training ramps' snaps and adds the law only where leave-one-experiment-out says the
thresholds alone cannot follow them.
"""

from __future__ import annotations

import math
import time
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from clutchlab.cli_fit import _latches_where_data_do_not
from clutchlab.errors import FitError, FitWarning
from clutchlab.physics import CircuitModel, SimulationSettings, simulate
from clutchlab.physics.effects import LatchDitherBand, dither_band_terms
from clutchlab.physics.fit import FitSettings, PhysicsFitter, training_rms
from clutchlab.physics.fit.fitter import resolve_free
from clutchlab.physics.fit.latch_band import (
    BAND_GAIN,
    BAND_MIN_MA,
    band_asked,
    band_design,
    latch_band_structure,
)
from clutchlab.physics.fit.staged import (
    _measured_latches,
    latches_where_data_do_not,
    match_latch_snaps,
    never_latches,
    quasi_static_traces,
    staged_start,
)
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand
from clutchlab.physics.stand.plants import PlantConfig, run_plant

RAMPS = (RampProfile("slow", 12.0, 0.5),)
SETTINGS = tuple(DitherSetting(f, s) for f in (30.0, 50.0, 70.0) for s in ("A", "B", "C"))


@pytest.fixture(scope="module")
def stand_band():
    """clutchlab's own circuit: its latch band does not move with the dither."""
    return list(run_stand(StandConfig(settings=SETTINGS, ramps=RAMPS), False).dataset)


@pytest.fixture(scope="module")
def zoo_band():
    """A zoo plant whose latch needs its pilot beyond a threshold for a dwell time."""
    cfg = PlantConfig("quadratic_play", settings=SETTINGS, ramps=RAMPS, seed=0)
    return list(run_plant(cfg, progress=False).dataset)


def test_terms_are_the_law_and_vanish_without_dither():
    amp, freq = np.array([0.0, 40.0, 200.0]), np.array([0.0, 50.0, 70.0])
    terms = np.array(dither_band_terms(amp, freq))
    assert terms.shape == (len(LatchDitherBand.FIT), 3)
    np.testing.assert_allclose(terms[:, 0], 0.0)  # no dither: the law does nothing
    v = math.log2(math.sqrt(70.0**2 + 1.0) / 50.0)
    g, s = 200.0 / 210.0, 2.0
    np.testing.assert_allclose(terms[:, 2], [g * v, g * v * v, s, s * v, s * v * v])
    # at the reference frequency only the amplitude's own term is left
    np.testing.assert_allclose(terms[:, 1], [0.0, 0.0, 0.4, 0.0, 0.0], atol=1e-3)


def test_design_moves_latch_on_up_and_latch_off_down(stand_band):
    traces = quasi_static_traces(stand_band)
    latch = _measured_latches(traces)
    used = [tr for tr in traces if tr.name in latch]
    jac = np.array([[20.0, 1.0], [2.0, 15.0]])
    a = band_design(used, latch, jac)
    assert a.shape == (2 * len(used), 7)
    np.testing.assert_array_equal(a[0::2, :2], np.tile(jac[0], (len(used), 1)))
    np.testing.assert_array_equal(a[1::2, :2], np.tile(jac[1], (len(used), 1)))
    # a positive half-width delays the snap (on up) and advances the release (off down):
    # in each row the law's columns are (J_on − J_off) × the terms
    for row, tr in zip(range(0, len(a), 2), used, strict=True):
        terms_on = a[row, 2:] / (jac[0, 0] - jac[0, 1])
        terms_off = a[row + 1, 2:] / (jac[1, 0] - jac[1, 1])
        assert np.all(np.isfinite(terms_on)) and np.all(np.isfinite(terms_off))
        assert abs(terms_on[2]) > 0, tr.name  # every setting dithers


def _through_matching(traces, model=None, latch_band="auto"):
    model = model or CircuitModel()
    settings = FitSettings(progress=False, regulator_lag="off", latch_band=latch_band)
    free = resolve_free(model, settings)
    start, info = staged_start(model, traces, settings, model.default_params(), free, 20.0)
    start = match_latch_snaps(model, start, traces, free, settings, info)
    return model, start, free, settings, info


@pytest.mark.parametrize("which", ["stand", "zoo"])
def test_law_is_added_only_where_the_snaps_ask(which, request):
    traces = request.getfixturevalue(f"{which}_band")
    model, start, free, settings, info = _through_matching(traces)
    assert info.latch_jacobian is not None, info.summary()
    chosen, params = latch_band_structure(model, start, traces, free, settings, info)
    band = info.latch_band
    added = "latch_dither_band" in chosen.effect_names
    ask = band["loo_thresholds_mA"] > BAND_MIN_MA and (
        band["loo_law_mA"] < BAND_GAIN * band["loo_thresholds_mA"]
    )
    assert added == ask, info.summary()
    assert ("structure: latch_dither_band" in info.summary()) == added
    # the dwell-timer latch asks for it; clutchlab's own latch does not
    assert added == (which == "zoo"), info.summary()
    if added:
        assert band["offsets_after_mA"] < 0.5 * band["offsets_rms_mA"], band
        assert any(params[n] != 0.0 for n in LatchDitherBand.FIT)
    else:
        assert chosen is model and params is start
        assert "latch band: not added" in info.summary()


@pytest.fixture(scope="module")
def zoo_never():
    """The dwell-timer plant at an as-built spread (seed 2) where a large, slow dither
    (30 Hz, shape B) never lets the latch trip: slow_30Hz_B never reaches line pressure."""
    cfg = PlantConfig("quadratic_play", settings=SETTINGS, ramps=RAMPS, seed=2)
    return list(run_plant(cfg, progress=False).dataset)


def test_the_model_latching_where_the_data_never_do_is_named(zoo_never, stand_band):
    assert [tr.name for tr in zoo_never if never_latches(tr)] == ["slow_30Hz_B"]
    model = CircuitModel()
    params = model.default_params()
    # clutchlab's latch switches on the dithered pilot: it latches there
    assert latches_where_data_do_not(model, params, zoo_never) == ["slow_30Hz_B"]
    # a trace whose "measurement" is the model's own prediction latches where it does
    sim = SimulationSettings(substeps=2, out_of_range="ignore")
    own = [
        tr.with_signals(clutch_pressure_bar=simulate(model, params, tr, sim).pressure_bar)
        for tr in zoo_never
        if never_latches(tr)
    ]
    assert latches_where_data_do_not(model, params, own) == []
    # every stand experiment latches: nothing to name
    assert not any(never_latches(tr) for tr in stand_band)
    assert latches_where_data_do_not(model, params, stand_band) == []
    # the CLI's note names the same experiments of the fit's training set
    fitter = SimpleNamespace(model_=model, params_=params, settings=None)
    names = [tr.name for tr in zoo_never]
    assert _latches_where_data_do_not(fitter, zoo_never, names) == ["slow_30Hz_B"]
    others = [n for n in names if n != "slow_30Hz_B"]
    assert _latches_where_data_do_not(fitter, zoo_never, others) == []


def test_a_model_that_names_the_law_is_left_alone(zoo_band):
    named = CircuitModel().with_effects("latch_dither_band")
    model, start, free, settings, info = _through_matching(zoo_band, named)
    assert not band_asked(model, start, zoo_band, free, settings, info)
    chosen, params = latch_band_structure(model, start, zoo_band, free, settings, info)
    assert chosen is named and params is start
    assert "names latch_dither_band" in info.summary()


@pytest.mark.parametrize("which", ["stand", "zoo"])
def test_the_staged_check_agrees_with_the_stage_on_the_same_model(which, request):
    """With the band law alone (``band``) the staged start's test and the stage agree; with
    the line law offered (``auto``, both data log a wandering line) the solver's time is kept
    on both, and the stage still adds only what the snaps ask for."""
    traces = request.getfixturevalue(f"{which}_band")
    values = {}
    for latch_band in ("band", "auto"):
        model, start, free, settings, info = _through_matching(traces, latch_band=latch_band)
        asked = band_asked(model, start, traces, free, settings, info)
        assert asked == (which == "zoo" or latch_band == "auto"), info.summary()
        assert info.latch_band["staged_loo_thresholds_mA"] > 0
        assert ("staged_loo_line_mA" in info.latch_band) == (latch_band == "auto")
        chosen, params = latch_band_structure(model, start, traces, free, settings, info)
        assert ("latch_dither_band" in chosen.effect_names) == (which == "zoo")
        assert "latch_line_threshold" not in chosen.effect_names
        values[latch_band] = dict(params)
        if latch_band == "auto":  # the note gives the line law's numbers, then the band's
            note = info.notes[-1]  # the stage's (added or not)
            assert "mA with latch_line_threshold" in note, note
            assert "the band law alone, with the staged start's Jacobian" in note, note
    # the line law not chosen: auto's stage is band's exactly (the staged start's Jacobian)
    assert values["auto"] == values["band"]


def test_no_time_left_estimates_nothing(zoo_band):
    model, start, free, settings, info = _through_matching(zoo_band)
    chosen, params = latch_band_structure(model, start, zoo_band, free, settings, info, 0.0)
    assert chosen is model and params is start and "no time left" in info.summary()


def test_without_the_matching_nothing_is_estimated(zoo_band):
    model, start, free, settings, info = _through_matching(zoo_band)
    info.latch_jacobian = None  # as when the matching could not run
    chosen, params = latch_band_structure(model, start, zoo_band, free, settings, info)
    assert chosen is model and params is start and not info.latch_band


def test_settings_refuse_an_unknown_latch_band():
    with pytest.raises(FitError, match="latch_band 'maybe' is not auto, band or off"):
        FitSettings(latch_band="maybe")


@pytest.fixture(scope="module")
def zoo_fits(zoo_band):
    """The default fit on the zoo plant's slow ramps, and the same with the latch band off."""
    fits = {}
    for band in ("auto", "off"):
        settings = FitSettings(
            progress=False, train_ramps=("slow",), latch_band=band, max_iter=6, refine_max_iter=1
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FitWarning)  # a fit stopped at a limit is fine here
            fits[band] = PhysicsFitter(settings=settings).fit(zoo_band)
    return fits


def test_the_fit_keeps_the_band_only_when_it_lowers_the_training_rms(zoo_fits, zoo_band, tmp_path):
    auto, off = zoo_fits["auto"], zoo_fits["off"]
    assert "latch_dither_band" not in off.result_.effects
    band = auto.staged_.latch_band
    assert band["staged_loo_law_mA"] < BAND_GAIN * band["staged_loo_thresholds_mA"], band
    kept = "latch_dither_band" in auto.result_.effects
    assert "training_rms_after_bar" in band, auto.staged_.summary()
    assert kept == (band["training_rms_after_bar"] < band["training_rms_before_bar"])
    # the dwell-timer latch: kept, and the result is the band model's
    assert kept, auto.staged_.summary()
    res = auto.result_
    assert training_rms(res.per_experiment) == pytest.approx(band["training_rms_after_bar"])
    assert training_rms(auto.training_metrics(zoo_band)) == pytest.approx(
        band["training_rms_after_bar"], rel=1e-6
    )
    assert not set(LatchDitherBand.FIT) & set(res.free)  # held, not fitted
    assert any(res.values[n] != 0.0 for n in LatchDitherBand.FIT)
    assert set(res.std_errors) >= set(res.free)
    assert "latch band kept" in auto.staged_.summary()
    # saved and loaded as any fit (JSON), predicting the same
    auto.save(tmp_path / "fit.json")
    again = PhysicsFitter.load(tmp_path / "fit.json")
    np.testing.assert_allclose(again.predict(zoo_band[0]), auto.predict(zoo_band[0]))


def test_the_stages_time_counts_in_the_fits_when_they_keep_nothing(zoo_band, monkeypatch):
    """The result's wall time is the whole fit's, the latch stages' included, also when
    they keep nothing (it was taken before them: the scorecard's walls read ~8 s short)."""
    import clutchlab.physics.fit.fitter as fitter_module

    ended = []

    def slow_and_empty(model, params, *args, **kwargs):
        time.sleep(2.0)
        ended.append(time.perf_counter())
        return model, params

    monkeypatch.setattr(fitter_module, "latch_band_structure", slow_and_empty)
    settings = FitSettings(
        progress=False, train_ramps=("slow",), max_iter=2, refine_max_iter=1, latch_band="band"
    )
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        fitter = PhysicsFitter(settings=settings).fit(zoo_band)
    assert len(ended) == 1, fitter.staged_.summary()  # the stage ran, once
    assert "latch_dither_band" not in fitter.result_.effects
    # taken before the stage it would be at least its 2 s short of the stage's end
    assert fitter.result_.wall_s > ended[0] - t0 - 1.0
    assert fitter.result_.wall_s <= time.perf_counter() - t0


@pytest.mark.parametrize(("spread_mA", "adopted"), [(4.0, True), (1.5, False)])
def test_a_line_dependence_of_a_few_mA_is_adopted_and_noise_is_not(spread_mA, adopted):
    """The adoption test on a linearized system whose latch-on / latch-off offsets follow
    the line pressure at the snaps. stribeck_supply's fitted models leave the thresholds
    alone 4.1-5.3 mA (held-back seeds 4-8, session 60); at 5 mA the gate flipped with the
    wall clock. Offsets of 1.5 mA (the order of preisach_accumulator's) are left alone."""
    from clutchlab.physics.fit.latch_band import LINE_LAW, _asks

    rng = np.random.default_rng(0)
    n = 9
    jac = np.array([[80.0, 8.0], [10.0, 70.0]])  # mA per bar of each threshold
    line = rng.normal(0.0, 0.2, n)  # bar, line pressure above its reference at each snap
    a_thr = np.tile(jac, (n, 1))
    a_line = np.vstack([jac * dl for dl in line])  # (2n, 2)
    a = np.hstack([a_thr, np.zeros((2 * n, 5)), a_line])
    # the snaps follow the line pressure, 0.25 / 0.2 bar of threshold per bar of line
    d0 = a_line @ np.array([-0.25, -0.2])
    d0 = spread_mA * d0 / np.sqrt(np.mean(d0**2)) + rng.normal(0.0, 0.3, 2 * n)
    laws, record, _ = _asks(d0, a)
    assert (record["loo_thresholds_mA"] > BAND_MIN_MA) is adopted
    assert record["loo_line_mA"] < BAND_GAIN * record["loo_thresholds_mA"]
    assert (LINE_LAW in laws) is adopted
