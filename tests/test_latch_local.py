"""The local latch-event law: a latch-event law per dither setting, by kernel weights."""

from __future__ import annotations

import json

import numpy as np
import pytest
from synthetic import (
    check_latch_law_fmu,
    check_latch_law_model,
    tiny_never_latching,
    tiny_stand,
    tiny_supply_coupled,
)

from clutchlab.errors import ModelError, ModelFileError
from clutchlab.residual_ml import (
    LocalEventDecision,
    SVCPartitionedGP,
    load_model,
    local_law,
)
from clutchlab.residual_ml.latch_event import fit_event_decision
from clutchlab.residual_ml.latch_local import (
    LINE_COUPLING_RATIO,
    fit_local_event_decision,
    held_out_residuals,
)

SMALL = {"n_hyper": 300, "max_points": 300}
NAMES = ["current_lag_mA", "dither_amp_mA", "dither_freq_Hz", "didt_mA_s", "direction"]
#: Dither settings (mA, Hz) and each one's latch-on / latch-off law: θ (mA), τ (s). The
#: thresholds are not bilinear in (A, f) and τ differs per setting.
SETTINGS = {
    (40.0, 30.0): ((905.0, 0.10), (790.0, 0.20)),
    (100.0, 30.0): ((930.0, 0.16), (770.0, 0.31)),
    (40.0, 70.0): ((880.0, 0.22), (805.0, 0.12)),
    (100.0, 70.0): ((960.0, 0.12), (745.0, 0.26)),
}
RATES = (27.5, 440.0)


#: The thresholds of :data:`SETTINGS` with one slope per direction.
SHARED_SLOPES = {k: ((on[0], 0.15), (off[0], 0.25)) for k, (on, off) in SETTINGS.items()}


def _events(settings=SETTINGS):
    rows = []
    for (a, f), ((t_on, k_on), (t_off, k_off)) in settings.items():
        for r in RATES:
            rows.append((np.array([t_on + k_on * r, a, f, r, 1.0]), 1))
            rows.append((np.array([t_off - k_off * r, a, f, -r, -1.0]), -1))
    return rows


def test_a_narrow_bandwidth_is_each_settings_own_line_between_the_trained_rates():
    dec = fit_local_event_decision(_events(), NAMES, bandwidth=0.2)
    plane = fit_event_decision(_events(), NAMES)
    worst_local = worst_plane = 0.0
    for (a, f), ((t_on, k_on), (t_off, k_off)) in SETTINGS.items():
        for r in (55.0, 110.0, 220.0):  # rates between the trained ones
            want_on, want_off = t_on + k_on * r, t_off - k_off * r
            x = np.array([[want_on, a, f, r, 1.0], [want_off, a, f, -r, -1.0]])
            got = dec(x)  # 0 at the switch current
            worst_local = max(worst_local, float(np.abs(got).max()))
            worst_plane = max(worst_plane, float(np.abs(plane(x)).max()))
    # Within the slope prior's pull (about 2 % of the slope's difference to the neighbours').
    assert worst_local < 0.5
    assert worst_plane > 5.0  # the one-plane law cannot hold these settings
    on, off = dec.thresholds(100.0, 70.0)
    assert on == pytest.approx(960.0, abs=1.0) and off == pytest.approx(745.0, abs=1.0)
    # Latched above the switch current on a rise, below it on a fall.
    x = np.array([[930 + 0.16 * 110 + 1, 100, 30, 110, 1], [930 + 0.16 * 110 - 1, 100, 30, 110, 1]])
    assert list(dec(x) > 0) == [True, False]


def test_a_setting_trained_at_one_rate_borrows_its_neighbours_slope():
    """Left out at the fast rate (as in leave-one-experiment-out), (100 mA, 70 Hz) keeps its
    own slow event and takes the slope of the others instead of none."""
    events = [
        (row, s)
        for row, s in _events()
        if not (row[1] == 100.0 and row[2] == 70.0 and abs(row[3]) == 440.0)
    ]
    dec = fit_local_event_decision(events, NAMES, bandwidth=0.2)
    theta, tau = local_law(dec.on, dec.scale, 0.2, np.array([100.0]), np.array([70.0]))
    assert 0.12 < tau[0] < 0.22  # the neighbours' on-slopes are 0.10-0.22 s, not 0
    assert theta[0] + tau[0] * 27.5 == pytest.approx(960.0 + 0.12 * 27.5, abs=0.5)


def test_a_wide_bandwidth_is_one_line_for_every_setting():
    events = _events()
    dec = fit_local_event_decision(events, NAMES, bandwidth=1e4)
    on = np.array([row for row, s in events if s == 1])
    slope, icpt = np.polyfit(on[:, 3], on[:, 0], 1)
    theta, tau = local_law(dec.on, dec.scale, dec.bandwidth, np.array([70.0]), np.array([50.0]))
    assert tau[0] == pytest.approx(slope, rel=1e-6) and theta[0] == pytest.approx(icpt, rel=1e-6)


def test_one_ramp_rate_gives_no_slope_and_bad_input_is_named():
    one_rate = [(row, s) for row, s in _events() if abs(row[3]) == RATES[0]]
    dec = fit_local_event_decision(one_rate, NAMES, bandwidth=0.5)
    theta, tau = local_law(dec.on, dec.scale, 0.5, np.array([40.0]), np.array([30.0]))
    assert abs(tau[0]) < 1e-9 and theta[0] == pytest.approx(905.0 + 0.10 * 27.5, abs=0.5)
    with pytest.raises(ModelError, match="a dI/dt, a direction"):
        fit_local_event_decision(_events(), ["current_mA", "dither_amp_mA"], bandwidth=0.5)
    with pytest.raises(ModelError, match="two latch-off events"):
        fit_local_event_decision([e for e in _events() if e[1] == 1], NAMES, bandwidth=0.5)
    with pytest.raises(ModelError, match="positive number"):
        fit_local_event_decision(_events(), NAMES, bandwidth=0.0)
    back = LocalEventDecision.from_arrays(dec.arrays())
    x = np.array([[900.0, 40, 30, 100, 1], [760.0, 100, 70, -100, -1]])
    np.testing.assert_array_equal(back(x), dec(x))


@pytest.fixture(scope="module")
def data():
    return tiny_stand(1)


@pytest.fixture(scope="module")
def local_model(data):
    train = data.select(ramps=["fast", "slow"])
    return SVCPartitionedGP(latch_model="local_event", **SMALL).fit(train)


def test_partitioned_gp_with_the_local_law(local_model, data, tmp_path):
    check_latch_law_model(local_model, data, tmp_path, "local_event")


def test_a_saved_local_law_is_checked_on_load(local_model, tmp_path):
    local_model.save(tmp_path / "m.json")
    npz = tmp_path / "m.npz"
    arrays = dict(np.load(npz))
    key = next(k for k in arrays if k.endswith("clf.bandwidth"))
    arrays[key] = np.array([-1.0])
    np.savez(npz, **arrays)
    with pytest.raises(ModelFileError, match="bandwidth"):
        load_model(tmp_path / "m.json")
    doc = json.loads((tmp_path / "m.json").read_text())
    doc["params"]["latch_bandwidth"] = 0
    (tmp_path / "m.json").write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match="latch_bandwidth"):
        load_model(tmp_path / "m.json")


def test_local_law_exports_to_an_exact_fmu(data, tmp_path):
    check_latch_law_fmu(data, tmp_path, "local_event", **SMALL)


def test_the_default_falls_back_to_the_classifier_and_reads_its_own_kappa(local_model, data):
    from clutchlab.residual_ml import LATCH_RATE_SCALES

    assert SVCPartitionedGP().latch_model == "local_event"
    assert local_model._latch_rate_scale() == LATCH_RATE_SCALES["local_event"]
    # One training experiment: one latch event per direction, too few for the law.
    one = SVCPartitionedGP(**SMALL).fit([data["slow_30Hz_A"]])
    assert one.latch_model_ == "classifier"
    assert one._latch_rate_scale() == LATCH_RATE_SCALES["classifier"]
    assert one.set_params(latch_rate_scale=0.25)._latch_rate_scale() == 0.25


def _coupled_events(beta: float, seed: int = 0):
    """The events of :data:`SHARED_SLOPES`, each moved by ``beta`` (mA/bar) times a line
    pressure that wanders by ±0.3 bar, and that line pressure (bar). (Where the slopes
    differ between settings as much as in :data:`SETTINGS`, a held-out event's borrowed
    slope misses by tens of mA and a coupling of a few mA is not worth keeping.)"""
    rng = np.random.default_rng(seed)
    events = _events(SHARED_SLOPES)
    line = 17.7 + 0.15 * rng.standard_normal(len(events))
    moved = [
        (row + np.array([beta * (p - 17.7), 0, 0, 0, 0]), s)
        for (row, s), p in zip(events, line, strict=True)
    ]
    return moved, line


def test_held_out_residuals_are_those_of_one_linear_predictor():
    dec = fit_local_event_decision(_events(), NAMES, bandwidth=0.2)
    rng = np.random.default_rng(1)
    u, v = rng.standard_normal(len(dec.on)), rng.standard_normal(len(dec.on))
    r = lambda w: held_out_residuals(dec.on, dec.scale, 0.2, w)  # noqa: E731
    np.testing.assert_allclose(r(2.0 * u - 3.0 * v), 2.0 * r(u) - 3.0 * r(v), atol=1e-9)
    # Several value columns at once are each held out on their own: the first column is
    # the currents themselves (the law's own held-out misses, one event left out at a time).
    cols = np.column_stack([dec.on[:, 0], u, v])
    both = r(cols)
    for j in range(3):
        np.testing.assert_allclose(both[:, j], r(cols[:, j]), atol=1e-9)
    k = 3
    rest = np.delete(dec.on, k, axis=0)
    theta, tau = local_law(rest, dec.scale, 0.2, dec.on[k : k + 1, 2], dec.on[k : k + 1, 3])
    assert both[k, 0] == pytest.approx(dec.on[k, 0] - theta[0] - tau[0] * dec.on[k, 1], abs=1e-9)


def test_a_latch_that_follows_line_pressure_is_found_and_its_law_corrected():
    events, line = _coupled_events(45.0)
    dec = fit_local_event_decision(events, NAMES, bandwidth=0.2, line=line)
    assert dec.uses_line and dec.line_coef == pytest.approx(45.0, rel=0.05)
    assert dec.line_ratio < 0.1 and dec.line_p_value <= 0.01
    # At the switch current of each setting and rate between the trained ones, with the
    # line pressure of that moment, the decision is at its threshold.
    for (a, f), ((t_on, k_on), _) in SHARED_SLOPES.items():
        for r, p in ((110.0, 17.5), (220.0, 18.0)):
            x = np.array([[t_on + k_on * r + 45.0 * (p - 17.7), a, f, r, 1.0]])
            assert abs(dec(x, line=np.array([p]))[0]) < 1.0
    with pytest.raises(ModelError, match="line pressure"):
        dec(x)
    back = LocalEventDecision.from_arrays(dec.arrays())
    np.testing.assert_array_equal(back(x, line=np.array([17.9])), dec(x, line=np.array([17.9])))
    # Without the coupling in the events the test does not keep one.
    noisy, _ = _coupled_events(0.0, seed=1)  # no coupling; switch currents ±1 mA
    noisy = [
        (row + np.array([1.0 * z, 0, 0, 0, 0]), s)
        for (row, s), z in zip(
            noisy, np.random.default_rng(2).standard_normal(len(noisy)), strict=True
        )
    ]
    plain = fit_local_event_decision(noisy, NAMES, bandwidth=0.2, line=line)
    assert not plain.uses_line and plain.line_ratio > LINE_COUPLING_RATIO
    # A file written before the coupling holds none.
    old = {k: v for k, v in dec.arrays().items() if k != "line"}
    assert not LocalEventDecision.from_arrays(old).uses_line
    with pytest.raises(ModelError, match="finite"):
        fit_local_event_decision(events, NAMES, bandwidth=0.2, line=line[:-1])


@pytest.fixture(scope="module")
def coupled():
    return tiny_supply_coupled(0)


@pytest.fixture(scope="module")
def coupled_model(coupled):
    return SVCPartitionedGP(**SMALL).fit(coupled.select(ramps=["fast", "slow"]))


def test_the_partitioned_gp_keeps_a_line_coupling_where_the_latch_has_one(
    coupled, coupled_model, data, tmp_path
):
    train = coupled.select(ramps=["fast", "slow"])
    model = coupled_model
    dec = model.decision_
    assert dec.uses_line and 20.0 < dec.line_coef < 80.0 and dec.line_ratio <= LINE_COUPLING_RATIO
    check_latch_law_model(model, coupled, tmp_path, "local_event")
    off = SVCPartitionedGP(latch_line="off", **SMALL).fit(train)
    assert not off.decision_.uses_line
    # On the stand (no coupling) the test runs and keeps none.
    stand = SVCPartitionedGP(**SMALL).fit(data.select(ramps=["fast", "slow"]))
    assert not stand.decision_.uses_line and np.isfinite(stand.decision_.line_ratio)
    for latch_model in ("local_event", "classifier"):
        with pytest.raises(ModelError, match="latch_line"):
            SVCPartitionedGP(latch_line="on", latch_model=latch_model, **SMALL).fit(train)


def test_a_line_coupled_latch_law_exports_to_an_exact_fmu(coupled, tmp_path):
    model = check_latch_law_fmu(coupled, tmp_path, "local_event", **SMALL)
    assert model.decision_.uses_line


def test_train_names_the_coupling_it_kept(coupled_model, local_model):
    from clutchlab.cli_ml import _latch_decision

    text = _latch_decision(coupled_model)
    assert "follow line pressure by +" in text and "permutation p" in text
    assert "no line-pressure coupling" in _latch_decision(local_model)


def test_a_setting_that_never_latched_is_not_predicted_to_latch(tmp_path):
    from clutchlab.physics.fmu import FmuPhysics, build_fmu, ml_program_from
    from clutchlab.residual_ml.features import causal_features

    data = tiny_never_latching()
    train = data.select(ramps=["fast", "slow"])
    model = SVCPartitionedGP(**SMALL).fit(train)
    dec = model.decision_
    # 30 Hz B reaches its 1100 mA peak without latching on both training ramps
    assert len(dec.censored) == 2 and np.all(dec.censored[:, 0] > 1090.0)
    np.testing.assert_array_equal(dec.censored[:, 2], [30.0, 30.0])
    assert not model.predict_latch(data["medium_30Hz_B"]).any()
    assert model.predict_latch(data["medium_30Hz_A"]).any()
    check_latch_law_model(model, data, tmp_path, "local_event")
    without = LocalEventDecision.from_arrays(
        {k: v for k, v in dec.arrays().items() if k != "censored"}
    )
    F = model._trace_matrix(data["medium_30Hz_B"])[:, model.classifier_columns_]
    line = data["medium_30Hz_B"].get("line_pressure_bar")
    assert (without(F, line=line) > 0).any()  # the neighbours' law alone would latch
    # The FMU holds the same rows and the same decision.
    features = causal_features(SVCPartitionedGP()._builder().names)
    causal = SVCPartitionedGP(features=features, **SMALL).fit(train)
    assert len(causal.decision_.censored) == 2
    fmu = build_fmu(ml_program_from(causal, with_std=False), tmp_path / "never.fmu")
    causal.set_params(knot_tol=0.0)
    for name in ("medium_30Hz_B", "medium_30Hz_A"):
        sim = FmuPhysics(fmu).simulate(data[name])
        np.testing.assert_array_equal(sim.outputs["latch_state"], causal.predict_latch(data[name]))


def test_only_never_latched_experiments_that_contradict_the_law_are_kept():
    """A partial ramp that stopped short of its setting's latch-on current is consistent
    with the law and dropped; a ramp past it without latching is kept."""
    short = np.array([850.0, 40.0, 30.0, 27.5, 1.0])  # law: 905 + 0.15 * 27.5 mA
    past = np.array([1100.0, 70.0, 50.0, 27.5, 1.0])  # a new setting; neighbours latch < 1000
    dec = fit_local_event_decision(
        _events(SHARED_SLOPES), NAMES, bandwidth=0.2, censored=[short, past]
    )
    np.testing.assert_array_equal(dec.censored, [[1100.0, 70.0, 50.0]])
    fall = np.array([[880.0, 40.0, 30.0, -27.5, -1.0]])  # above 790 - 0.25 * 27.5: latched
    assert dec(fall)[0] > 0
    rise = np.array([[1050.0, 70.0, 50.0, 27.5, 1.0]])
    assert dec(rise)[0] < 0 and LocalEventDecision.from_arrays(dec.arrays())(rise)[0] < 0
