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


def tiny_stand(seed: int):
    """Six short stand experiments: fast / medium / slow (1 / 2 / 4 s ramps) × (30 Hz A,
    70 Hz B), two substeps; the dataset of the ML tests (seed of noise and wander)."""
    from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

    config = StandConfig(
        settings=(DitherSetting(30.0, "A"), DitherSetting(70.0, "B")),
        ramps=(
            RampProfile("fast", 1.0, 0.3),
            RampProfile("medium", 2.0, 0.3),
            RampProfile("slow", 4.0, 0.3),
        ),
        substeps=2,
        seed=seed,
    )
    return run_stand(config, progress=False).dataset
