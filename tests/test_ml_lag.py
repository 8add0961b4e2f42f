"""The lagged-current feature and the choice of its time constant by leave-one-ramp-rate-out."""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.data import Trace
from clutchlab.errors import DataError, ModelError
from clutchlab.residual_ml import (
    LAG_GRID_S,
    FeatureBuilder,
    GPBaseline,
    GPWithDerivative,
    load_model,
    select_lag,
)
from clutchlab.residual_ml.features import LAG_DIDT_FEATURES, first_order_lag

FS = 1000.0


def test_first_order_lag_trails_a_ramp_by_tau_times_rate():
    t = np.arange(0, 4.0, 1 / FS)
    x = 100.0 + 250.0 * t  # 250 mA/s
    for tau in (0.05, 0.2):
        y = first_order_lag(x, tau, FS)
        a = np.exp(-1 / (tau * FS))
        # exact steady lag of the discretized filter: r · a / ((1 − a) fs) ≈ r · τ
        assert y[0] == x[0]
        assert abs((x[-1] - y[-1]) - 250.0 * a / ((1 - a) * FS)) < 1e-6
        assert abs((x[-1] - y[-1]) - 250.0 * tau) < 250.0 / FS
    assert np.array_equal(first_order_lag(x, 0.0, FS), x)


def test_first_order_lag_is_causal():
    rng = np.random.default_rng(0)
    x = rng.normal(size=2000)
    z = x.copy()
    z[1500:] += 50.0
    assert np.array_equal(first_order_lag(x, 0.1, FS)[:1500], first_order_lag(z, 0.1, FS)[:1500])


def test_feature_builder_rejects_a_negative_lag():
    with pytest.raises(DataError, match="lag_s"):
        FeatureBuilder(LAG_DIDT_FEATURES, lag_s=-0.1)


def _ramp_trace(name: str, ramp: str, ramp_s: float, tau: float, setting: int) -> Trace:
    """Up-down ramp 0 → 1000 mA whose pressure is a static curve of the lagged current."""
    hold = 0.5
    n = int((2 * hold + 2 * ramp_s + hold) * FS)
    t = np.arange(n) / FS
    knots = [0, hold, hold + ramp_s, 2 * hold + ramp_s, 2 * hold + 2 * ramp_s, t[-1]]
    i = np.interp(t, knots, [0, 0, 1000, 1000, 0, 0])
    lagged = first_order_lag(i, tau, FS)
    amp = np.full(n, 50.0 + 25.0 * setting)
    freq = np.full(n, 50.0)
    p = 2.0 + 0.01 * lagged + 0.002 * amp + 4.0 * np.tanh((lagged - 700.0) / 40.0)
    return Trace(
        name,
        {
            "time_s": t,
            "current_mA": i,
            "current_cmd_mA": i,
            "dither_amp_mA": amp,
            "dither_freq_Hz": freq,
            "clutch_pressure_bar": p,
            "line_pressure_bar": np.full(n, 17.7),
        },
        meta={"ramp": ramp},
    )


def _traces(tau: float) -> list[Trace]:
    return [
        _ramp_trace(f"{ramp}_{k}", ramp, ramp_s, tau, k)
        for ramp, ramp_s in (("fast", 1.0), ("slow", 6.0))
        for k in range(3)
    ]


@pytest.mark.parametrize("tau", [0.05, 0.2])
def test_select_lag_recovers_the_lag_of_the_data(tau):
    traces = _traces(tau)
    sel = select_lag(traces, FeatureBuilder(LAG_DIDT_FEATURES))
    assert sel.groups == ("fast", "slow")
    # the chosen value is the truth to within the √2 refinement of the grid
    assert tau / np.sqrt(2) * 0.99 <= sel.lag_s <= tau * np.sqrt(2) * 1.01, sel.scores
    assert sel.scores[sel.lag_s] < 0.5 * sel.scores[0.0]
    assert set(LAG_GRID_S) <= set(sel.scores)


def test_select_lag_needs_two_ramp_rates():
    traces = [t for t in _traces(0.1) if t.ramp == "fast"]
    sel = select_lag(traces, FeatureBuilder(LAG_DIDT_FEATURES))
    assert sel.lag_s == 0.0 and "fewer than two ramp rates" in sel.reason


def test_estimator_chooses_the_lag_and_saves_it(tmp_path):
    traces = _traces(0.1)
    small = {"n_hyper": 300, "max_points": 300}
    m = GPWithDerivative(**small).fit(traces)
    assert m.feature_names_[0] == "current_lag_mA"
    assert 0.1 / np.sqrt(2) * 0.99 <= m.lag_s_ <= 0.1 * np.sqrt(2) * 1.01
    assert m.lag_selection_.scores
    fixed = GPWithDerivative(lag_s=m.lag_s_, **small).fit(traces)
    assert fixed.lag_s_ == m.lag_s_ and fixed.lag_selection_ is None
    m.save(tmp_path / "m.json")
    loaded = load_model(tmp_path / "m.json")
    assert loaded.lag_s_ == m.lag_s_
    assert np.array_equal(loaded.predict(traces[0]), m.predict(traces[0]))
    # a model without the lagged current ignores lag_s
    assert GPBaseline(**small).fit(traces).lag_s_ == 0.0


@pytest.mark.parametrize("bad", [-1.0, "fast", float("nan")])
def test_bad_lag_parameter_is_a_model_error(bad):
    with pytest.raises(ModelError, match="lag_s"):
        GPWithDerivative(lag_s=bad).fit(_traces(0.1))
