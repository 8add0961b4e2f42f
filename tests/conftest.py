"""Shared fixtures: synthetic traces with known inputs, and one stand run per session."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic import make_trace

from clutchlab.physics.stand import DEFAULT_SETTINGS, StandConfig, run_stand


@pytest.fixture(scope="session")
def fast_ramp_trace():
    """6.5 s fast ramp 0 → 1100 → 0 mA, 100 mA / 50 Hz dither, hot oil (70 °C), line wandering."""
    tr = make_trace([0, 0.5, 3.0, 3.5, 6.0, 6.5], [0, 0, 1100, 1100, 0, 0], temp_C=70.0)
    t = tr.time_s
    return tr.with_signals(line_pressure_bar=17.7 + 0.2 * np.sin(t))


@pytest.fixture(scope="session")
def stand_run():
    """The stand with three dither settings (30 Hz/A, 50 Hz/B, 70 Hz/C) × three ramps."""
    return run_stand(StandConfig(settings=DEFAULT_SETTINGS[::4]), progress=False)
