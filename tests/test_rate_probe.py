"""Experiments at a rate between the trained ones, made from training inputs (rate_probe)."""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.data import Trace, dither_period_mean, dither_period_samples
from clutchlab.residual_ml import between_rate_inputs, play_faster, ramp_rate

FS = 1000.0  # Hz
DITHER = 50.0  # Hz


def _ramp(name: str, ramp: str, rise_s: float, amp_mA: float = 40.0) -> Trace:
    """Up 200 -> 1000 mA in ``rise_s``, 0.5 s hold, down again; sine dither of ``amp_mA``."""
    hold = 0.5
    t = np.arange(0.0, 2 * rise_s + 3 * hold, 1 / FS)
    up = np.clip((t - hold) / rise_s, 0, 1)
    down = np.clip((t - 2 * hold - rise_s) / rise_s, 0, 1)
    nominal = 200.0 + 800.0 * (up - down)
    current = nominal + amp_mA * np.sin(2 * np.pi * DITHER * t)
    pressure = 0.01 * nominal  # bar
    meta = {"ramp": ramp, "dither_freq_Hz": DITHER}
    signals = {"time_s": t, "current_mA": current, "clutch_pressure_bar": pressure}
    return Trace(name, signals, meta=meta)


def test_ramp_rate_is_the_rate_along_the_ramps():
    assert ramp_rate(_ramp("a", "fast", 2.0)) == pytest.approx(400.0, rel=0.03)
    assert ramp_rate(_ramp("b", "slow", 32.0)) == pytest.approx(25.0, rel=0.03)


def test_playing_faster_keeps_the_dither_and_speeds_up_the_profile():
    slow = _ramp("slow_A", "slow", 32.0)
    fast = play_faster(slow, 4.0)
    assert fast.ramp == "between" and fast.name == "slow_A_x4"
    assert fast.sample_rate_Hz == pytest.approx(FS)
    assert fast.duration_s == pytest.approx(slow.duration_s / 4, abs=2 / DITHER)
    assert ramp_rate(fast) == pytest.approx(4 * ramp_rate(slow), rel=0.05)
    # the dither keeps its frequency and amplitude: the current less its period mean
    n = dither_period_samples(fast)
    ripple = fast.get("current_mA") - dither_period_mean(fast.get("current_mA"), n)
    core = slice(int(FS), -int(FS))
    assert np.std(ripple[core]) == pytest.approx(40.0 / np.sqrt(2), rel=0.05)
    spectrum = np.abs(np.fft.rfft(ripple[core]))
    freq = np.fft.rfftfreq(ripple[core].size, 1 / FS)
    assert freq[np.argmax(spectrum)] == pytest.approx(DITHER, abs=0.5)
    # the pressure follows its current as before (a static map stays the same map)
    np.testing.assert_allclose(
        dither_period_mean(fast.get("clutch_pressure_bar"), n),
        0.01 * dither_period_mean(fast.get("current_mA"), n),
        atol=0.02,
    )
    with pytest.raises(ValueError, match="factor"):
        play_faster(slow, 0.5)


def test_between_rate_inputs_play_the_slower_ramp_at_the_geometric_mean_rate():
    fast = [_ramp(f"fast_{k}", "fast", 2.0) for k in "AB"]
    slow = [_ramp(f"slow_{k}", "slow", 32.0) for k in "AB"]
    made = between_rate_inputs([*fast, *slow])
    assert [t.name for t in made] == ["slow_A_x4", "slow_B_x4"]
    assert all(ramp_rate(t) == pytest.approx(100.0, rel=0.05) for t in made)
    assert between_rate_inputs(fast) == []  # one rate: nothing between
    # rates within 1.5x of each other are one rate
    assert between_rate_inputs([*fast, _ramp("near", "near", 2.5)]) == []
