"""Hysteresis and latch analysis on synthetic loops with known answers (issue 6, must-show 3).

The loop: nominal current 0 → 1100 → 0 mA with holds, regulated pressure linear in current,
a hysteresis width that varies linearly with current, a latch snap to line pressure at a
known current on each branch, and sensor noise. Tolerances: hysteresis width within
0.02 bar, latch currents within 2 mA.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from clutchlab.data import didt, dither_period_mean
from clutchlab.validation import (
    FALLING,
    RISING,
    AnalysisSettings,
    branch_direction,
    compare_experiment,
    current_bins,
    error_by_region,
    hysteresis_curve,
    hysteresis_width_error,
    latch_currents,
    latch_error,
    pool_comparisons,
)

FS = 1000.0
I_ON, I_OFF = 930.0, 790.0


def width_true(i):
    """Rising minus falling pressure of the synthetic loop, bar (negative: falling is higher)."""
    return -(0.1 + 4e-4 * i)


def loop(rate_up=100.0, rate_down=100.0, noise=0.02, seed=0, line=17.7, dither=None):
    """Nominal current (mA), measured pressure (bar), line pressure (bar), time (s)."""
    t_up, t_dn, hold = 1100.0 / rate_up, 1100.0 / rate_down, 1.0
    knots = np.cumsum([0, hold, t_up, hold, t_dn, hold])
    t = np.arange(0.0, knots[-1], 1.0 / FS)
    i = np.interp(t, knots, [0, 0, 1100, 1100, 0, 0])
    rising = (t > knots[1]) & (t < knots[2])
    top = t >= knots[2]
    reg = 0.5 + 0.014 * i
    p = np.where(rising | (t <= knots[1]), reg + width_true(i) / 2, reg - width_true(i) / 2)
    latched_up = (rising & (i >= I_ON)) | ((t >= knots[2]) & (t <= knots[3]))
    latched_dn = top & (t > knots[3]) & (i >= I_OFF)
    rng = np.random.default_rng(seed)
    line_s = line + 0.2 * np.sin(2 * np.pi * t / 7.0)
    p = np.where(latched_up | latched_dn, line_s, p)
    if dither is not None:
        p = p + 0.8 * np.sin(2 * np.pi * dither * t)
    p = p + noise * rng.standard_normal(t.size)
    return t, i, p, line_s


def direction_of(i):
    return branch_direction(didt(i, FS, FS / 50.0 * 5))


def test_branch_direction_splits_ramps_and_holds():
    t, i, _, _ = loop()
    d = direction_of(i)
    assert set(np.unique(d)) == {FALLING, 0, RISING}
    assert np.all(d[(t > 2.0) & (t < 11.0)] == RISING)
    assert np.all(d[(t > 13.0) & (t < 22.0)] == FALLING)
    assert np.all(d[(t > 0.1) & (t < 0.9)] == 0) and np.all(d[(t > 12.2) & (t < 12.8)] == 0)


@pytest.mark.parametrize("rate_down", [100.0, 330.0])
def test_hysteresis_width_known_answer(rate_down):
    _, i, p, line = loop(rate_down=rate_down)
    curve = hysteresis_curve(i, p, direction_of(i), line)
    regulated = curve.valid & ~curve.latched & (curve.center_mA < I_OFF - 25)
    assert regulated.sum() >= 25
    w = curve.width_bar[regulated]
    np.testing.assert_allclose(w, width_true(curve.center_mA[regulated]), atol=0.02)
    # The latch region is flagged, not mistaken for regulator hysteresis.
    assert curve.latched[(curve.center_mA > I_OFF + 15) & (curve.center_mA < I_ON - 15)].all()


def test_hysteresis_width_on_dithered_period_mean():
    _, i, p, line = loop(dither=50.0)
    pm = dither_period_mean(p, FS / 50.0)
    curve = hysteresis_curve(i, pm, direction_of(i), line)
    regulated = curve.valid & ~curve.latched & (curve.center_mA < I_OFF - 25)
    np.testing.assert_allclose(
        curve.width_bar[regulated], width_true(curve.center_mA[regulated]), atol=0.02
    )


def test_hysteresis_width_error_of_a_shifted_prediction():
    _, i, p, line = loop(noise=0.0)
    d = direction_of(i)
    pred = p.copy()
    pred[d == RISING] += np.where(p[d == RISING] < 16.0, 0.1, 0.0)  # width 0.1 bar too large
    s = AnalysisSettings()
    m = hysteresis_curve(i, p, d, line, s)
    q = hysteresis_curve(i, pred, d, line, s, bins=current_bins(i, s.bin_mA))
    err, centers = hysteresis_width_error(m, q)
    assert err.size >= 25 and centers.max() < I_OFF
    np.testing.assert_allclose(err, 0.1, atol=1e-9)


@pytest.mark.parametrize(("rate", "noise", "dither"), [(100.0, 0.02, None), (440.0, 0.05, 30.0)])
def test_latch_currents_known_answer(rate, noise, dither):
    _, i, p, line = loop(rate_up=rate, rate_down=rate, noise=noise, dither=dither)
    if dither is not None:
        p = dither_period_mean(p, FS / dither)
    lc = latch_currents(i, p, direction_of(i), line)
    assert abs(lc.on_mA - I_ON) < 2.0, lc
    assert abs(lc.off_mA - I_OFF) < 2.0, lc
    assert lc.peak_mA == pytest.approx(1100.0)


def test_latch_missing_is_censored_at_the_peak():
    _, i, p, line = loop()
    d = direction_of(i)
    flat = np.minimum(p, 14.0)  # never snaps
    lc = latch_currents(i, flat, d, line)
    assert math.isnan(lc.on_mA) and math.isnan(lc.off_mA)
    err, censored = latch_error(I_ON, lc.on_mA, lc.peak_mA)
    assert censored and err == pytest.approx(1100.0 - I_ON, abs=0.5)
    assert latch_error(I_ON, I_ON + 3.0, 1100.0) == (pytest.approx(3.0), False)
    assert math.isnan(latch_error(math.nan, math.nan, 1100.0)[0])


def test_pooled_metrics_of_a_known_offset():
    _, i, p, line = loop(noise=0.0)
    d = direction_of(i)
    pred = np.where(p < 16.0, p + 0.05, p)  # regulated pressure 0.05 bar high
    c = compare_experiment("x", i, d, line, p, pred)
    pooled = pool_comparisons([c, c])
    assert pooled["mae_bar"] == pytest.approx(0.05 * np.mean(p < 16.0), rel=1e-9)
    assert pooled["max_abs_bar"] == pytest.approx(0.05)
    assert pooled["hysteresis_width_err_bar"] == pytest.approx(0.0, abs=1e-9)
    assert pooled["latch_on_err_mA"] < 0.5 and pooled["latch_off_err_mA"] < 0.5
    assert pooled["hysteresis_bins"] == 2 * c.width_err_bar.size


def test_error_by_region_puts_a_latch_timing_error_in_the_latch_window():
    """A prediction that is exact but for a 50 ms late snap and release: all of its squared
    error lies in the latch window; a regulated offset's lies in the regulated region."""
    t, i, p, line = loop(noise=0.0)
    d = direction_of(i)
    late = np.interp(t - 0.05, t, p)  # the whole signal 50 ms late: the snaps too
    latched = p >= line - 1.0
    pred_timing = np.where(latched != (late >= line - 1.0), late, p)
    pred_offset = np.where(p < 16.0, p + 0.05, p)
    pooled = {}
    for name, pred in (("timing", pred_timing), ("offset", pred_offset)):
        c = compare_experiment(name, i, d, line, p, pred, time_s=t)
        pooled[name] = pool_comparisons([c])
        for key in ("sq_error_share", "samples_share"):
            total = sum(
                pooled[name][f"{key}_{r}"] for r in ("regulated", "latched", "latch_window")
            )
            assert total == pytest.approx(1.0)
        e = pred - p
        window = c.regions["latch_window"]
        assert pooled[name]["rmse_latch_window_bar"] == pytest.approx(
            np.sqrt(np.mean(e[window] ** 2))
        )
        assert 0.0 < pooled[name]["samples_share_latch_window"] < 0.2
    assert pooled["timing"]["sq_error_share_latch_window"] == pytest.approx(1.0)
    assert pooled["timing"]["rmse_regulated_bar"] == 0.0
    assert pooled["offset"]["rmse_regulated_bar"] == pytest.approx(0.05)
    assert pooled["offset"]["rmse_latched_bar"] == 0.0
    assert pooled["offset"]["sq_error_share_regulated"] > 0.8
    # without sample times there are no regions, and no region keys
    c = compare_experiment("x", i, d, line, p, pred_offset)
    assert c.regions is None and "rmse_regulated_bar" not in pool_comparisons([c])
    assert set(error_by_region([compare_experiment("x", i, d, line, p, p, time_s=t)])) == {
        f"{k}_{r}{u}"
        for r in ("regulated", "latched", "latch_window")
        for k, u in (("rmse", "_bar"), ("sq_error_share", ""), ("samples_share", ""))
    }
