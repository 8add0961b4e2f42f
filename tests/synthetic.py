"""Synthetic traces with known inputs for the tests."""

from __future__ import annotations

import numpy as np

from clutchlab.data import Trace


def make_trace(
    knots_t,
    knots_mA,
    *,
    dt=1e-3,
    dither_mA=100.0,
    dither_Hz=50.0,
    temp_C=40.0,
    line_bar=17.7,
    name="synthetic",
    ramp="fast",
) -> Trace:
    """A command-only trace: piecewise-linear nominal current, constant dither/line/temp."""
    t = np.arange(knots_t[0], knots_t[-1] + 0.5 * dt, dt)
    n = len(t)
    signals = {
        "time_s": t,
        "current_cmd_mA": np.interp(t, knots_t, knots_mA),
        "dither_amp_mA": np.full(n, float(dither_mA)),
        "dither_freq_Hz": np.full(n, float(dither_Hz)),
        "clutch_pressure_bar": np.zeros(n),
        "line_pressure_bar": np.full(n, float(line_bar)),
        "oil_temp_C": np.full(n, float(temp_C)),
    }
    return Trace(name, signals, meta={"ramp": ramp})
