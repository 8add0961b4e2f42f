"""Ramp labels are listed by their measured ramp rate, fastest first, wherever clutchlab lists
them (the dataset summary of an evaluation, the hysteresis-band figures), not alphabetically:
a user's labels ``r5s`` / ``r10s`` / ``r20s`` sort as ``r10s, r20s, r5s``."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from synthetic import make_trace

from clutchlab.data import Dataset, Trace, ramp_rate_mA_s, ramps_fastest_first

#: A user's labels and their ramp times (s), in dataset order; alphabetical is r10s, r20s, r5s.
USER_RAMPS = {"r10s": 1.0, "r20s": 2.0, "r5s": 0.5}


def _ramp(label: str, ramp_s: float, measured_only: bool = False) -> Trace:
    h = 0.1
    knots = [0, h, h + ramp_s, 2 * h + ramp_s, 2 * h + 2 * ramp_s, 3 * h + 2 * ramp_s]
    tr = make_trace(knots, [0, 0, 1100, 1100, 0, 0], dither_Hz=50.0, ramp=label)
    t, cmd = tr.time_s, tr.get("current_cmd_mA")
    signals = dict(tr.signals) | {
        "clutch_pressure_bar": cmd / 100.0,
        "current_mA": cmd + 100.0 * np.sin(2 * np.pi * 50.0 * t),
    }
    if measured_only:
        signals.pop("current_cmd_mA")
    return Trace(f"{label}_50Hz_A", signals, meta=tr.meta | {"dither_freq_Hz": 50.0})


@pytest.mark.parametrize("measured_only", [False, True])
def test_ramp_rate_is_the_ramps_slope_from_the_command_or_the_measured_current(measured_only):
    rate = ramp_rate_mA_s(_ramp("x", 0.5, measured_only))
    assert rate == pytest.approx(1100.0 / 0.5, rel=0.03)


def test_a_measured_currents_noise_does_not_make_a_slow_ramp_fast():
    """Stand-like measured current: 2 mA noise, 0.5 mA quantization, 100 mA dither at 50 Hz
    on a 27.5 mA/s ramp (the slow one). Its two-sample slope after the period mean read
    ~180 mA/s, faster than a 110 mA/s ramp (logger-data pass, session 43)."""
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 40.0, 1e-3)
    cmd = np.interp(t, [0.0, 40.0], [0.0, 1100.0])
    measured = cmd + 100.0 * np.sin(2 * np.pi * 50.0 * t) + rng.normal(0.0, 2.0, t.size)
    signals = {
        "time_s": t,
        "current_mA": np.round(measured / 0.5) * 0.5,
        "clutch_pressure_bar": cmd / 100.0,
    }
    slow = Trace("slow", signals, meta={"ramp": "slow", "dither_freq_Hz": 50.0})
    assert ramp_rate_mA_s(slow) == pytest.approx(27.5, rel=0.1)


def test_a_held_current_has_rate_zero_and_its_label_comes_last():
    held = make_trace([0, 1.0], [500, 500], ramp="hold")
    assert ramp_rate_mA_s(held) == 0.0
    ds = Dataset([Trace("hold_1", held.signals, held.meta), _ramp("r20s", 2.0)])
    assert list(ramps_fastest_first(ds)) == ["r20s", "hold"]


def test_user_labels_are_grouped_fastest_first():
    ds = Dataset(
        [_ramp(label, s, measured_only=(label == "r20s")) for label, s in USER_RAMPS.items()]
    )
    groups = ramps_fastest_first(ds)
    assert list(groups) == ["r5s", "r10s", "r20s"]
    assert [t.name for t in groups["r5s"]] == ["r5s_50Hz_A"]


def test_evaluation_summary_and_band_figure_list_the_ramps_fastest_first():
    """The summary's ramps were in dataset order and the band figure's legend alphabetical."""
    from clutchlab.validation.figures import plot_hysteresis_bands
    from clutchlab.validation.hysteresis import branch_direction, hysteresis_curve
    from clutchlab.validation.protocol import _summary

    ds = Dataset([_ramp(label, s) for label, s in USER_RAMPS.items()])
    summary = _summary(ds)
    assert list(summary["ramps"]) == ["r5s", "r10s", "r20s"]

    curves = {}
    for tr in ds:
        cur, p = tr.get("current_cmd_mA"), tr.get("clutch_pressure_bar")
        direction = branch_direction(np.gradient(cur, tr.time_s))
        curves[tr.name] = hysteresis_curve(cur, p + 0.1 * direction, direction)
    protocol = SimpleNamespace(
        train_names=["r10s_50Hz_A", "r20s_50Hz_A"],
        test_names=["r5s_50Hz_A"],
        test_ramps=("r5s",),
        dataset_summary=summary,
    )
    ev = SimpleNamespace(protocol=protocol, curves={"measured": curves})
    fig = plot_hysteresis_bands(ev)
    labels = [
        line.get_label() for line in fig.axes[0].get_lines() if not line.get_label().startswith("_")
    ]
    assert labels == ["r5s (test)", "r10s (train)", "r20s (train)"]
