"""The latch-event law: latch currents linear in the ramp rate, thresholds in the dither."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic import check_latch_law_fmu, check_latch_law_model, tiny_stand

from clutchlab.errors import ModelError
from clutchlab.residual_ml import SVCPartitionedGP
from clutchlab.residual_ml.latch_event import EventDecision, fit_event_decision, latch_events

SMALL = {"n_hyper": 300, "max_points": 300}
NAMES = ["current_lag_mA", "dither_amp_mA", "dither_freq_Hz", "didt_mA_s", "direction"]


def _events(rng, n=40):
    """Synthetic events of a known law: on 900 + 0.2 A − 0.5 f + 0.15 İ, off 780 + … − 0.25 |İ|."""
    rows = []
    for _ in range(n):
        a, f = rng.choice([40.0, 80.0, 120.0]), rng.choice([30.0, 50.0, 70.0])
        r = rng.choice([27.5, 440.0])
        on = 900 + 0.2 * a - 0.5 * f + 0.15 * r + rng.normal(0, 0.5)
        off = 780 + 0.1 * a - 0.3 * f - 0.25 * r + rng.normal(0, 0.5)
        rows.append((np.array([on, a, f, r, 1.0]), 1))
        rows.append((np.array([off, a, f, -r, -1.0]), -1))
    return rows


def test_fit_recovers_a_known_law_and_ignores_an_outlier():
    rng = np.random.default_rng(0)
    events = _events(rng)
    events.append((np.array([600.0, 80.0, 50.0, 440.0, 1.0]), 1))  # a mis-detected snap
    dec = fit_event_decision(events, NAMES)
    np.testing.assert_allclose(dec.on[[1, 2, 4]], [0.2, -0.5, 0.15], atol=0.03)
    np.testing.assert_allclose(dec.off[[1, 2, 4]], [0.1, -0.3, 0.25], atol=0.03)
    on0, off0 = dec.thresholds(80.0, 50.0)
    assert on0 == pytest.approx(900 + 16 - 25, abs=2) and off0 == pytest.approx(780 + 8 - 15, abs=2)
    # Between the two trained rates the law interpolates: at 220 mA/s rising, latched
    # from 900 + 16 − 25 + 33 mA on.
    x = np.array([[924.0 - 2, 80, 50, 220, 1], [924.0 + 2, 80, 50, 220, 1]])
    assert list(dec(x) > 0) == [False, True]
    # Falling (direction −1): latched above 780 + 8 − 15 − 55 mA at that rate.
    x = np.array([[718.0 + 2, 80, 50, -220, -1], [718.0 - 2, 80, 50, -220, -1]])
    assert list(dec(x) > 0) == [True, False]
    back = EventDecision.from_arrays(dec.arrays())
    np.testing.assert_array_equal(back(x), dec(x))


def test_fit_needs_its_features_and_events():
    rng = np.random.default_rng(1)
    with pytest.raises(ModelError, match="a dI/dt, a direction"):
        fit_event_decision(_events(rng), ["current_mA", "dither_amp_mA", "dither_freq_Hz"])
    with pytest.raises(ModelError, match="two latch-off events"):
        fit_event_decision([e for e in _events(rng) if e[1] == 1], NAMES)
    state = np.array([0, 0, 1, 1, 1, 0, 0])
    ev = latch_events(np.arange(7.0)[:, None], state)
    assert [(float(r[0]), s) for r, s in ev] == [(2.0, 1), (5.0, -1)]


@pytest.fixture(scope="module")
def data():
    return tiny_stand(1)


@pytest.fixture(scope="module")
def event_model(data):
    train = data.select(ramps=["fast", "slow"])
    return SVCPartitionedGP(latch_model="event", **SMALL).fit(train)


def test_partitioned_gp_with_the_event_law(event_model, data, tmp_path):
    check_latch_law_model(event_model, data, tmp_path, "event")


def test_event_law_falls_back_to_the_classifier_on_arrays(event_model, data):
    X = event_model._trace_matrix(data["fast_30Hz_A"])
    y = data["fast_30Hz_A"].get("clutch_pressure_bar")
    m = SVCPartitionedGP(latch_model="event", **SMALL).fit(X[::20], y[::20])
    assert m.latch_model_ == "classifier"
    # the report and `train` say why the classifier decides (they said only "classifier")
    from clutchlab.residual_ml import latch_decision_text

    said = latch_decision_text(m)
    assert "in place of the latch-event law" in said and "a feature array" in said, said
    one = SVCPartitionedGP(**SMALL).fit([data["fast_30Hz_A"]])  # one up and one down event
    said = latch_decision_text(one)
    assert "in place of the local latch-event law" in said and "fewer than two" in said, said
    assert "in place of" not in latch_decision_text(event_model)
    with pytest.raises(ModelError, match="latch_model"):
        SVCPartitionedGP(latch_model="tree", **SMALL).fit(data.select(ramps=["fast", "slow"]))


def test_event_law_exports_to_an_exact_fmu(data, tmp_path):
    check_latch_law_fmu(data, tmp_path, "event", **SMALL)
