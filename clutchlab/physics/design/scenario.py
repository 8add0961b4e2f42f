"""Input traces of a design point: the stand's ramps and dither shapes, noise-free, and a step.

The ramps are the synthetic stand's (:class:`~clutchlab.physics.stand.RampProfile`, nominal
current 0 → peak → 0 mA with holds) and the dither amplitude is the stand's shape
(:func:`~clutchlab.physics.stand.dither_amplitude`) times ``dither_amp_scale``; unlike the
stand, line / prime pressure and oil temperature are constant and there is no sensor noise:
a design point's numbers depend on its design vector only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...data import Trace
from ...errors import ModelError
from ..stand.scenarios import RampProfile, dither_amplitude
from .spec import ScenarioSpec, StepSpec

__all__ = ["DitherChoice", "ramp_trace", "step_trace"]


@dataclass(frozen=True)
class DitherChoice:
    """Dither of one design point.

    Attributes
    ----------
    freq_Hz : float
        Dither frequency (Hz).
    shape : str
        Amplitude shape (A / B / C).
    amp_scale : float
        Factor on the shape's amplitude (-).
    waveform : str
        sine / triangle / square.
    """

    freq_Hz: float
    shape: str
    amp_scale: float = 1.0
    waveform: str = "sine"


def _trace(
    name: str,
    t: np.ndarray,
    i_nom: np.ndarray,
    dither: DitherChoice,
    scenario: ScenarioSpec,
    kind: str,
) -> Trace:
    n = len(t)
    signals = {
        "time_s": t,
        "current_cmd_mA": i_nom,
        "dither_amp_mA": dither.amp_scale * dither_amplitude(dither.shape, i_nom),
        "dither_freq_Hz": np.full(n, dither.freq_Hz),
        "clutch_pressure_bar": np.zeros(n),
        "line_pressure_bar": np.full(n, scenario.line_pressure_bar),
        "prime_pressure_bar": np.full(n, scenario.prime_pressure_bar),
        "oil_temp_C": np.full(n, scenario.oil_temp_C),
    }
    meta = {"scenario": kind, "dither_waveform": dither.waveform}
    return Trace(name, signals, meta=meta)


def _sample_step(sample_rate_Hz: float) -> float:
    """The sample interval (s) of a positive, finite rate (Hz)."""
    if not (isinstance(sample_rate_Hz, int | float) and math.isfinite(sample_rate_Hz)):
        raise ModelError(f"sample_rate_Hz must be a finite number, got {sample_rate_Hz!r}")
    if sample_rate_Hz <= 0:
        raise ModelError(f"sample_rate_Hz must be > 0, got {sample_rate_Hz!r}")
    return 1.0 / sample_rate_Hz


def ramp_trace(
    ramp: RampProfile, dither: DitherChoice, scenario: ScenarioSpec, sample_rate_Hz: float
) -> Trace:
    """The stand ramp ``ramp`` with dither ``dither`` on a grid of ``sample_rate_Hz`` (Hz).

    Returns
    -------
    Trace
        ``current_cmd_mA`` (mA), ``dither_amp_mA`` (mA), ``dither_freq_Hz`` (Hz), constant
        line / prime pressure (bar) and oil temperature (°C); clutch pressure zero (a
        placeholder: the simulation supplies it).
    """
    dt = _sample_step(sample_rate_Hz)
    t = np.arange(0.0, ramp.duration_s + 0.5 * dt, dt)
    return _trace(f"ramp_{ramp.label}", t, ramp.current(t), dither, scenario, "ramp")


def step_trace(
    step: StepSpec, dither: DitherChoice, scenario: ScenarioSpec, sample_rate_Hz: float
) -> tuple[Trace, float]:
    """A current step ``from_mA → to_mA`` at ``hold_s`` (s), held for ``duration_s`` (s).

    Returns
    -------
    trace : Trace
        As :func:`ramp_trace`.
    t_step_s : float
        Time of the step (s).
    """
    dt = _sample_step(sample_rate_Hz)
    t = np.arange(0.0, step.hold_s + step.duration_s + 0.5 * dt, dt)
    i = np.where(t < step.hold_s, step.from_mA, step.to_mA)
    return _trace("step", t, i, dither, scenario, "step"), float(t[t >= step.hold_s][0])
