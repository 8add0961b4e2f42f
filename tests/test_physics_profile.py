"""Drive profiles for early design: a current profile of one's own, simulated without data.

Before: a profile built in code had to carry a made-up clutch pressure column to be a
:class:`Trace` at all, and a step written as corners with a repeated time was refused as
"time not increasing" with no hint (session 42's new-user pass).
"""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.data import Trace
from clutchlab.errors import DataError
from clutchlab.physics import CircuitModel, drive_trace, knot_profile, simulate


def test_a_repeated_corner_time_is_a_step_on_the_sample_grid():
    t, i = knot_profile([0.0, 0.5, 0.5, 1.5], [0.0, 0.0, 800.0, 800.0], sample_rate_Hz=1000.0)
    assert len(t) == 1501 and t[0] == 0.0 and t[-1] == pytest.approx(1.5)
    np.testing.assert_allclose(np.diff(t), 1e-3, rtol=1e-9)
    assert i[499] == 0.0 and i[500] == 800.0 and i[-1] == 800.0


@pytest.mark.parametrize(
    ("knots_s", "knots_mA", "rate", "message"),
    [
        ([0.0, 1.0, 0.5], [0, 1, 2], 1000.0, "goes back from 1 s to 0.5 s"),
        ([0.0, 1.0], [0.0], 1000.0, "2 corner times but 1 currents"),
        ([0.0], [0.0], 1000.0, "at least two corners"),
        ([0.0, 1.0], [0.0, np.nan], 1000.0, "finite"),
        ([0.0, 1.0], [0.0, 1.0], 0.0, "sample_rate_Hz must be > 0"),
        ([0.0, 1e-4], [0.0, 1.0], 1000.0, "less than one sample"),
    ],
)
def test_a_bad_profile_is_refused_with_its_problem(knots_s, knots_mA, rate, message):
    with pytest.raises(DataError, match=message):
        knot_profile(knots_s, knots_mA, sample_rate_Hz=rate)


def test_a_drive_trace_holds_the_inputs_and_no_measured_pressure():
    t, i = knot_profile([0.0, 0.2, 1.0], [0.0, 0.0, 600.0])
    tr = drive_trace(t, i, dither_amp_mA=80.0, dither_freq_Hz=np.full(len(t), 60.0))
    assert isinstance(tr, Trace) and tr.name == "profile"
    np.testing.assert_array_equal(tr.get("current_cmd_mA"), i)
    assert np.all(tr.get("dither_amp_mA") == 80.0) and np.all(tr.get("dither_freq_Hz") == 60.0)
    assert np.all(tr.get("line_pressure_bar") == 17.7) and np.all(tr.get("oil_temp_C") == 40.0)
    assert np.all(np.isnan(tr.get("clutch_pressure_bar")))
    assert tr.meta["dither_waveform"] == "sine"


def test_a_drive_trace_lists_every_problem():
    t = np.arange(100) * 1e-3
    with pytest.raises(DataError) as info:
        drive_trace(t, np.zeros(99), oil_temp_C=np.zeros(3), dither_waveform="saw")
    text = str(info.value)
    assert "current_cmd_mA has 99 samples, time_s 100" in text
    assert "oil_temp_C has 3 samples" in text and "'saw'" in text


def test_a_step_simulates_without_data_and_the_unit_is_checked():
    t, i = knot_profile([0.0, 0.3, 0.3, 1.0], [0.0, 0.0, 700.0, 700.0])
    model = CircuitModel()
    params = model.default_params()
    tr = drive_trace(t, i, dither_amp_mA=100.0, dither_freq_Hz=50.0)
    p = simulate(model, params, tr).pressure_bar
    assert np.all(np.isfinite(p))
    before, after = p[t < 0.3].mean(), p[t > 0.8].mean()
    assert before < 1.5 and after > before + 5.0  # the regulated pressure follows the step
    # the measured-pressure column plays no part in a simulation
    zeros = Trace(tr.name, dict(tr.signals) | {"clutch_pressure_bar": np.zeros(len(t))}, tr.meta)
    np.testing.assert_array_equal(simulate(model, params, zeros).pressure_bar, p)
    # a current written in amperes is named, not simulated to the prime pressure
    with pytest.raises(DataError, match="amperes"):
        simulate(model, params, drive_trace(t, i / 1000.0))


def test_a_dither_amplitude_without_a_frequency_is_refused_not_ignored():
    """drive_trace(..., dither_amp_mA=100) kept the 0 Hz default frequency: the model's
    dither sin(2π·0·t) is zero, so the amplitude was silently ignored."""
    t, i = knot_profile([0.0, 0.3, 0.3, 1.0], [0.0, 0.0, 700.0, 700.0])
    with pytest.raises(DataError, match=r"dither_amp_mA is 100 mA at dither_freq_Hz = 0 Hz"):
        drive_trace(t, i, dither_amp_mA=100.0)
    freq = np.where(t < 0.5, 50.0, 0.0)  # the dither stops but its amplitude does not
    with pytest.raises(DataError, match=r"row 500, 501 rows in total"):
        drive_trace(t, i, dither_amp_mA=100.0, dither_freq_Hz=freq)
    drive_trace(t, i)  # no dither at all: no frequency needed
    drive_trace(t, i, dither_amp_mA=np.where(t < 0.5, 100.0, 0.0), dither_freq_Hz=freq)
