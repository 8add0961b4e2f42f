"""Design-point metrics on synthetic signals with known answers, and on one simulated point."""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.physics.design import DesignEvaluator, DesignPoint, MetricSettings, SweepSpec
from clutchlab.physics.design import metrics as m

LINE = 17.7


def _ramp(n=4001, peak=1100.0):
    """Up then down ramp of nominal current (mA) with rising / falling masks."""
    up = np.linspace(0.0, peak, n)
    i = np.concatenate([up, up[::-1]])
    rising = np.r_[np.ones(n, bool), np.zeros(n, bool)]
    return i, rising, ~rising


def _regulated(i, offset):
    """12 bar/A regulated line (below line − 1 bar up to 1100 mA)."""
    return 2.0 + 0.012 * i + offset


def test_gain_hysteresis_and_latch_currents_recovered():
    i, up, dn = _ramp()
    p = np.where(up, _regulated(i, -0.3), _regulated(i, 0.0))
    p = np.where(up & (i >= 950.0), LINE, p)
    p = np.where(dn & (i >= 800.0), LINE, p)
    s = MetricSettings()
    assert m.regulated_gain(i, p, up, LINE, s) == pytest.approx(12.0, rel=1e-9)
    on, off = m.latch_currents(i, p, up, dn, LINE, 1.0)
    assert on == pytest.approx(950.0, abs=0.5)
    assert off == pytest.approx(800.0, abs=0.5)
    # Bins from 775 mA up touch the latch; they and their neighbour are left out.
    assert m.hysteresis_width(i, p, up, dn, LINE, s) == pytest.approx(-0.3, abs=1e-9)


def test_hysteresis_is_nan_when_every_bin_is_latched():
    i, up, dn = _ramp()
    p = np.where(i > 500.0, LINE, 5.0)
    assert np.isnan(m.hysteresis_width(i, p, up, dn, LINE, MetricSettings()))
    on, off = m.latch_currents(i, np.full_like(i, 5.0), up, dn, LINE)
    assert np.isnan(on) and np.isnan(off)


def test_ripple_of_a_sine():
    i, up, _ = _ramp()
    mean = _regulated(i, 0.0)
    raw = mean + 0.2 * np.sin(np.arange(i.size) * 2 * np.pi / 20.0)
    pp, rms = m.ripple(i, raw, mean, up, LINE, MetricSettings())
    assert pp == pytest.approx(0.4, rel=1e-3)
    assert rms == pytest.approx(0.2 / np.sqrt(2), rel=1e-2)


def test_response_times_of_a_first_order_lag():
    tau, fs, t_step = 0.05, 10000.0, 0.1
    t = np.arange(0.0, 1.0, 1.0 / fs)
    p = 3.0 + np.where(t >= t_step, 8.0 * (1.0 - np.exp(-(t - t_step) / tau)), 0.0)
    rise, settle = m.response_times(t, p, t_step, MetricSettings(), n_final=100)
    assert rise == pytest.approx(tau * np.log(9.0), rel=1e-3)
    assert settle == pytest.approx(tau * np.log(20.0), rel=1e-3)
    down = 11.0 - (p - 3.0)  # a falling step gives the same times
    assert m.response_times(t, down, t_step, MetricSettings(), 100) == pytest.approx(
        (rise, settle), rel=1e-9
    )


def test_simulated_point_has_plausible_engineering_metrics():
    """Datasheet circuit, fast ramp + step: numbers a calibration engineer would expect."""
    spec = SweepSpec.from_dict(
        {
            "scenario": {"ramps": ["fast"]},
            "sampling": {"method": "grid"},
            "variables": [{"name": "vfs_d_orf", "values": [0.45]}],
        }
    )
    row = DesignEvaluator(spec).evaluate(DesignPoint(0, "p", {"vfs_d_orf": 0.45}))
    assert row["status"] == "ok", row["error"]
    assert 10.0 < row["regulated_gain_bar_per_A"] < 30.0  # ≈ 0–10 bar VFS over 0–1 A, ×~2
    assert 700.0 < row["latch_off_mA"] < row["latch_on_mA"] < 1100.0
    assert row["hysteresis_fast_bar"] < 0.0  # rising branch lags the falling one
    assert 0.0 < row["ripple_rms_bar"] < row["ripple_pp_bar"] < 2.0
    assert 0.0 < row["rise_10_90_s"] < row["settle_s"] < 0.5


def test_first_crossing_is_interpolated_per_direction_and_nan_when_absent():
    from clutchlab.data import first_crossing

    x = np.array([0.0, 10.0, 20.0, 30.0, 40.0])
    g = np.array([-2.0, -1.0, 1.0, 3.0, -1.0])
    assert first_crossing(x, g, upward=True) == pytest.approx(15.0)
    assert first_crossing(x, g, upward=False) == pytest.approx(37.5)
    assert np.isnan(first_crossing(x, np.abs(g) + 0.1, upward=True))


def test_metric_vs_variable_panels_share_the_x_axis_of_their_column():
    """The tick labels are drawn on the bottom row only, but a panel whose metric is NaN for
    some points had its own x range: points at vfs_d_orf = 0.6 were drawn at 0.475."""
    import pandas as pd

    from clutchlab.physics.design import SweepSpec, metric_names, plot_metrics_vs_variables

    spec = SweepSpec.from_dict(
        {
            "sampling": {"method": "grid"},
            "variables": [
                {"name": "vfs_d_orf", "values": [0.35, 0.6]},
                {"name": "vacc_V", "values": [1.0, 4.0], "scale": "log"},
            ],
        }
    )
    table = pd.DataFrame(
        {"status": "ok", "vfs_d_orf": [0.35, 0.35, 0.6, 0.6], "vacc_V": [1.0, 4.0, 1.0, 4.0]}
    )
    for k, name in enumerate(metric_names(("fast",))):
        table[name] = [np.nan, np.nan, 1.0 + k, 2.0 + k] if name == "latch_on_mA" else k + 0.0
    fig = plot_metrics_vs_variables(table, spec)
    grid = np.array(fig.axes).reshape(-1, 2)
    for col in range(2):
        limits = {tuple(np.round(ax.get_xlim(), 9)) for ax in grid[:, col]}
        assert len(limits) == 1, limits


def test_ripple_of_a_ramp_through_the_window_in_less_than_a_dither_period_is_nan():
    """A 10 ms ramp crossed the 400-800 mA window in 4 samples of a 20 ms dither period and
    reported ripple_rms_bar 0.011 > ripple_pp_bar 0.0098: no ripple can be measured there."""
    spec = SweepSpec.from_dict(
        {
            "scenario": {
                "ramps": [{"label": "x", "ramp_s": 0.01, "hold_s": 0.01}],
                "step": {"hold_s": 0.005, "duration_s": 0.005},
            },
            "simulation": {"settle_s": 0.0},
            "sampling": {"method": "grid"},
            "variables": [{"name": "reg_k", "values": [10.0]}],
        }
    )
    row = DesignEvaluator(spec).evaluate(DesignPoint(0, "p", {"reg_k": 10.0}))
    assert row["status"] == "ok", row["error"]
    assert np.isnan(row["ripple_pp_bar"]) and np.isnan(row["ripple_rms_bar"])
    i, up, _ = _ramp()  # the default keeps every window of at least one sample
    mean = _regulated(i, 0.0)
    raw = mean + 0.2 * np.sin(np.arange(i.size) * 2 * np.pi / 20.0)
    assert np.isnan(m.ripple(i, raw, mean, up, LINE, MetricSettings(), min_samples=10**6)[0])


def test_tornado_says_what_its_colours_mean():
    """Red and blue bars were not explained anywhere in tornado.png."""
    import pandas as pd

    from clutchlab.physics.design import metric_names, plot_tornado

    spec = SweepSpec.from_dict(
        {"sampling": {"method": "grid"}, "variables": [{"name": "reg_k", "values": [10, 20, 30]}]}
    )
    table = pd.DataFrame({"status": "ok", "reg_k": [10.0, 20.0, 30.0]})
    for name in metric_names(("fast",)):
        table[name] = [1.0, 2.0, 2.5]
    title = plot_tornado(table, spec).get_suptitle()
    assert "red: the metric rises, blue: it falls" in title
