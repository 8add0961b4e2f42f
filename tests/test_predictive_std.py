"""The predictive std of ``SVCPartitionedGP`` beyond the GP's own: the latch-timing mixture
near a predicted switch (``latch_uncertainty``), the rate bridge between trained ramp rates
(``rate_uncertainty``) and the per-frequency noise floor of a period mean (``noise_model``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.special import ndtr
from synthetic import tiny_stand

from clutchlab.errors import ModelFileError
from clutchlab.residual_ml import HybridModel, SVCPartitionedGP, load_model
from clutchlab.residual_ml.hybrid import HYBRID_FEATURES
from clutchlab.residual_ml.latch_timing import (
    LatchTiming,
    bridge_variance,
    mixture_interval_std,
    rate_anchors,
    switch_errors,
    switches,
)

SMALL = {"n_hyper": 300, "max_points": 300}


def test_switches_and_their_errors_are_matched_per_direction():
    state = np.array([0, 0, 1, 1, 1, 0, 0, 0])
    pred = np.array([0, 0, 0, 1, 1, 1, 0, 0])
    current = np.array([0.0, 10, 20, 30, 40, 30, 20, 10])
    assert switches(state) == [(2, 1), (5, -1)]
    errors, missed = switch_errors(state, pred, current)
    assert errors == {1: [10.0], -1: [-10.0]}  # on 10 mA late; off 10 mA early (lower)
    assert missed == {1: 0, -1: 0}
    errors, missed = switch_errors(state, np.zeros(8), current)
    assert errors == {1: [], -1: []} and missed == {1: 1, -1: 1}


def test_rate_anchors_group_rates_and_average_the_switch_currents():
    events = [(27.0, 800.0, -1), (28.0, 804.0, -1), (440.0, 720.0, -1), (440.0, 900.0, 1)]
    a = rate_anchors(events)
    assert np.allclose(a[-1][1], [802.0, 720.0])
    assert np.allclose(np.exp(a[-1][0]), [np.sqrt(27.0 * 28.0), 440.0])
    assert a[1] == ([pytest.approx(np.log(440.0))], [900.0])


def test_bridge_variance_is_zero_at_trained_rates_and_largest_between():
    a, c = [np.log(25.0), np.log(400.0)], [820.0, 720.0]
    assert bridge_variance(a[0], a, c) == 0.0 == bridge_variance(a[1], a, c)
    mid = 0.5 * (a[0] + a[1])
    assert bridge_variance(mid, a, c) == pytest.approx(100.0**2 / 4)
    # outside the trained rates it grows with the distance, in units of the span
    span = a[1] - a[0]
    assert bridge_variance(a[1] + span, a, c) == pytest.approx(100.0**2)
    assert bridge_variance(mid, a[:1], c[:1]) == 0.0  # one trained rate: no rate term
    timing = LatchTiming({1: 1.0, -1: 2.0}, {1: a, -1: a}, {1: c, -1: c})
    assert timing.sigma_mA(-1, 100.0, 0.5) == pytest.approx(np.sqrt(4.0 + 0.25 * 100.0**2 / 4))
    assert timing.sigma_mA(1, 400.0, 0.5) == pytest.approx(1.0)


def test_mixture_std_reaches_the_other_regime_only_when_it_is_likely():
    mean, std = np.zeros(3), np.full(3, 0.05)
    other, ostd = np.full(3, 4.0), np.full(3, 0.05)
    p = np.array([0.0, 0.01, 0.3])
    out = mixture_interval_std(mean, std, other, ostd, p)
    assert out[0] == pytest.approx(0.05, rel=1e-6)  # far from a switch: the GP's std
    assert out[1] < 0.1  # 1 % of the mass can stay outside a 95 % interval
    assert 1.96 * out[2] >= 4.0  # 30 %: the interval reaches the other regime
    # the interval holds 95 % of the mixture's mass
    h = 1.959964 * out[2]
    held = 0.7 * (ndtr(h / 0.05) - ndtr(-h / 0.05)) + 0.3 * (
        ndtr((h - 4.0) / 0.05) - ndtr((-h - 4.0) / 0.05)
    )
    assert held == pytest.approx(0.95, abs=1e-6)


@pytest.fixture(scope="module")
def data():
    return tiny_stand(5)


@pytest.fixture(scope="module")
def fitted(data):
    train = data.select(ramps=["fast", "slow"])
    only = {"rate_uncertainty": "none", "noise_model": "constant"}
    fits = {
        kind: SVCPartitionedGP(latch_uncertainty=kind, **only, **SMALL).fit(train)
        for kind in ("mixture", "none")
    }
    fits["bridge"] = SVCPartitionedGP(
        latch_uncertainty="none", noise_model="constant", **SMALL
    ).fit(train)
    fits["noise"] = SVCPartitionedGP(
        latch_uncertainty="none", rate_uncertainty="none", **SMALL
    ).fit(train)
    return fits


def test_the_std_widens_only_near_a_predicted_switch(data, fitted):
    mix, plain = fitted["mixture"], fitted["none"]
    assert plain.latch_timing_ is None
    timing = mix.latch_timing_
    assert timing.n_errors[1] + timing.n_missed[1] == 4  # one latch-on per training run
    assert len(timing.log_rates[-1]) == 2  # two trained ramp rates
    trace = data["medium_30Hz_A"]
    m1, s1 = mix.predict(trace, return_std=True)
    m0, s0 = plain.predict(trace, return_std=True)
    np.testing.assert_array_equal(m1, m0)  # the mean is the point prediction either way
    assert (s1 >= s0 - 1e-12).all()
    wide = s1 > s0 + 1e-9
    cls = mix.predict_latch(trace)
    sw = np.flatnonzero(np.diff(cls) != 0)
    assert sw.size >= 2 and wide.any()
    # every widened sample lies near a predicted switch, and the std there reaches the snap
    near = np.min(np.abs(np.arange(len(trace))[:, None] - sw[None, :]), axis=1)
    assert near[wide].max() < 0.25 * len(trace)
    assert (s1[sw] > 0.3).all() and (s0[sw] < 0.3).all()


def test_the_band_covers_more_of_the_latch_window(data, fitted):
    from clutchlab.validation import AnalysisSettings, ExperimentReference, interval_coverage

    s = AnalysisSettings()
    got = {}
    for kind in ("mixture", "none"):
        model = fitted[kind]
        inside = total = 0
        for trace in data.select(ramps=["medium"]):
            ref = ExperimentReference.of(trace, s)
            mean, std = model.predict(trace, return_std=True)
            cov = interval_coverage(
                ref.time_s,
                ref.period_mean(ref.line_bar),
                ref.measured_mean_bar,
                ref.period_mean(mean),
                ref.period_mean(std),
                s,
            )
            inside += cov["latch_window"][0]
            total += cov["latch_window"][1]
        got[kind] = inside / total
    assert got["mixture"] > got["none"] + 0.1


def test_save_load_keeps_the_timing_model(tmp_path, data, fitted):
    model = fitted["mixture"]
    model.save(tmp_path / "m.json")
    loaded = load_model(tmp_path / "m.json")
    assert loaded.latch_timing_ == model.latch_timing_
    trace = data["medium_70Hz_B"]
    np.testing.assert_allclose(
        loaded.predict(trace, return_std=True)[1], model.predict(trace, return_std=True)[1]
    )
    doc = json.loads((tmp_path / "m.json").read_text())
    doc["state"]["latch_timing"]["currents_mA"]["off"] = [1.0]
    doc["params"]["latch_rate_scale"] = -1  # κ is a parameter, read at prediction
    (tmp_path / "m.json").write_text(json.dumps(doc))
    with pytest.raises(ModelFileError) as err:
        load_model(tmp_path / "m.json")
    assert "latch_rate_scale" in str(err.value)
    assert "has 1 values for 2 log_rates" in str(err.value)


def test_older_files_without_timing_load_with_the_gp_std(tmp_path, fitted):
    fitted["mixture"].save(tmp_path / "m.json")
    doc = json.loads((tmp_path / "m.json").read_text())
    del doc["state"]["latch_timing"]
    del doc["params"]["latch_uncertainty"], doc["params"]["latch_rate_scale"]
    (tmp_path / "m.json").write_text(json.dumps(doc))
    assert load_model(tmp_path / "m.json").latch_timing_ is None


def test_bad_setting_is_refused(data):
    with pytest.raises(Exception, match="latch_uncertainty must be"):
        SVCPartitionedGP(latch_uncertainty="wide", **SMALL).fit(data.select(ramps=["fast"]))


def test_the_hybrid_residual_carries_the_mixture(data):
    """A hybrid's residual model is partitioned too: its band widens near a switch."""
    train = data.select(ramps=["fast", "slow"])
    trace = data["medium_30Hz_A"]
    std = {}
    for kind in ("mixture", "none"):
        res = SVCPartitionedGP(
            features=HYBRID_FEATURES,
            latch_uncertainty=kind,
            rate_uncertainty="none",
            noise_model="constant",
            **SMALL,
        )
        hyb = HybridModel(residual=res, form="residual").fit(train)
        std[kind] = hyb.predict(trace, return_std=True)[1]
    assert (std["mixture"] >= std["none"] - 1e-12).all()
    assert std["mixture"].max() > 0.3 > std["none"].max()


def test_the_rate_bridge_widens_ramps_between_the_trained_rates_only(data, fitted):
    """Between the trained rates (medium) the band grows by the GP's change from the slow to
    the fast rate; at a trained rate (fast) and where the current holds it stays put."""
    bridge, plain = fitted["bridge"], fitted["none"]
    assert len(bridge.train_log_rates_) == 2
    assert np.exp(bridge.train_log_rates_[1]) > 3 * np.exp(bridge.train_log_rates_[0])
    extra = {}
    for name in ("medium_30Hz_A", "fast_30Hz_A"):
        trace = data[name]
        m1, s1 = bridge.predict(trace, return_std=True)
        m0, s0 = plain.predict(trace, return_std=True)
        np.testing.assert_array_equal(m1, m0)
        assert (s1 >= s0 - 1e-12).all()
        extra[name] = np.sqrt(np.maximum(s1**2 - s0**2, 0.0))
        holds = np.abs(bridge._trace_matrix(trace)[:, bridge.feature_names_.index("didt_mA_s")])
        assert extra[name][holds < 1.0].max() < 1e-9
    assert np.median(extra["medium_30Hz_A"][extra["medium_30Hz_A"] > 0]) > 5 * np.median(
        extra["fast_30Hz_A"][extra["fast_30Hz_A"] > 0]
    )
    with pytest.raises(Exception, match="rate_uncertainty must be"):
        SVCPartitionedGP(rate_uncertainty="wide", **SMALL).fit(data.select(ramps=["fast"]))


def test_rate_groups_and_bridge_weights_are_vectorized():
    from clutchlab.residual_ml.rate_bridge import bridge_weight, group_log_rates

    logs = np.log([440.0, 27.0, 450.0, 28.0, 110.0])
    assert group_log_rates(logs) == [[1, 3], [4], [0, 2]]
    a = [np.log(27.5), np.log(110.0), np.log(440.0)]
    k, v = bridge_weight(np.log([27.5, 55.0, 220.0, 880.0]), a)
    np.testing.assert_array_equal(k, [0, 0, 1, 1])
    np.testing.assert_allclose(v, [0.0, 0.25, 0.25, 0.5])


def test_model_choice_folds_skip_the_std_only_fits():
    """Folds that score means (LOEO, the hybrid's form choice) fit without the extra
    decision fits; estimators without those parameters are left as they are."""
    from clutchlab.residual_ml import GPBaseline
    from clutchlab.residual_ml.estimators import mean_only

    est = mean_only(SVCPartitionedGP())
    assert est.latch_uncertainty == "none" and est.rate_uncertainty == "none"
    assert est.noise_model == "constant"
    gp = mean_only(GPBaseline(max_points=7))  # the single GP: its own std options, off
    assert gp.rate_uncertainty == "none" and gp.residual_variance == "none"
    assert gp.max_points == 7
    from sklearn.linear_model import LinearRegression

    assert mean_only(LinearRegression()).get_params() == LinearRegression().get_params()


def test_the_noise_floor_follows_the_dither_frequency(data, fitted):
    """A period mean of white noise is noisier at a higher dither frequency (fewer samples
    per period): the floor grows with f, and the std is never below the GP's."""
    noise, plain = fitted["noise"], fitted["none"]
    assert plain.noise_by_freq_ == {}
    assert set(noise.noise_by_freq_) == {0, 1}
    for c, slope in noise.noise_by_freq_.values():
        assert c >= 0 and slope >= 0
    assert noise.noise_by_freq_[1][1] > 0  # the stand's sensor noise is white
    std = {}
    for name in ("medium_30Hz_A", "medium_70Hz_B"):
        trace = data[name]
        m1, s1 = noise.predict(trace, return_std=True)
        m0, s0 = plain.predict(trace, return_std=True)
        np.testing.assert_array_equal(m1, m0)
        assert (s1 >= s0 - 1e-12).all()
        latched = noise.predict_latch(trace) == 1
        std[name] = np.median(s1[latched])
    assert std["medium_70Hz_B"] > std["medium_30Hz_A"]


def test_the_noise_floor_is_saved_and_checked(tmp_path, data, fitted):
    model = fitted["noise"]
    model.save(tmp_path / "m.json")
    loaded = load_model(tmp_path / "m.json")
    assert loaded.noise_by_freq_ == model.noise_by_freq_
    trace = data["medium_70Hz_B"]
    np.testing.assert_allclose(
        loaded.predict(trace, return_std=True)[1], model.predict(trace, return_std=True)[1]
    )
    doc = json.loads((tmp_path / "m.json").read_text())
    doc["state"]["noise_by_freq"]["1"] = [-1.0, 0.0]
    (tmp_path / "m.json").write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match="noise_by_freq"):
        load_model(tmp_path / "m.json")


def test_the_scored_coverage_names_the_experiments_it_pools(data, fitted):
    """``evaluate`` draws the band of one featured experiment and scores its coverage there:
    the details and the report's variant line say on which experiments."""
    from clutchlab.validation import Protocol
    from clutchlab.validation.report import _describe

    protocol = Protocol(data, train=("fast", "slow"), test=("medium",))
    one = protocol.featured
    score = protocol.score("paper_svc_gp", fitted["mixture"], std_for=(one,))
    assert score.details["coverage_experiments"] == [one]
    line = _describe("paper_svc_gp", {"description": "d", **score.details}, html_=False)
    assert f"±2σ coverage ({one})" in line
    every = protocol.score("paper_svc_gp", fitted["mixture"])
    assert every.details["coverage_experiments"] == sorted(protocol.test_names)
