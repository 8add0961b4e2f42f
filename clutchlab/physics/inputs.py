"""Model input matrices from a trace: the dither resolved, defaults filled in."""

from __future__ import annotations

import numpy as np

from ..data import Trace
from ..errors import DataError
from .assembly import MODEL_INPUTS
from .settings import SimulationSettings

__all__ = ["WAVEFORMS", "choose_drive", "input_matrix"]

WAVEFORMS = ("sine", "triangle", "square")
_IDX = {s.name: k for k, s in enumerate(MODEL_INPUTS)}


def choose_drive(trace: Trace, settings: SimulationSettings) -> str:
    """The drive mode for ``trace``: measured current if present (``auto``), else command."""
    if settings.drive == "auto":
        return "measured" if trace.has("current_mA") else "command"
    if settings.drive == "measured" and not trace.has("current_mA"):
        raise DataError(f"{trace.name}: drive='measured' but the trace has no current_mA column")
    if settings.drive == "command" and not trace.has("current_cmd_mA"):
        raise DataError(f"{trace.name}: drive='command' but the trace has no current_cmd_mA column")
    return settings.drive


def _signal_or_meta(trace: Trace, name: str, fallback: float) -> np.ndarray:
    if trace.has(name):
        return np.asarray(trace.get(name), dtype=float)
    value = trace.meta.get(name, fallback)
    return np.full(len(trace), float(value))


def input_matrix(trace: Trace, drive: str, settings: SimulationSettings) -> np.ndarray:
    """Inputs (N × nu, :data:`MODEL_INPUTS` order) on the trace's time grid.

    The dither phase is the trapezoidal integral of the dither frequency; the
    waveform comes from ``trace.meta["dither_waveform"]`` or the settings.
    """
    t = trace.time_s
    n = len(trace)
    u = np.zeros((n, len(MODEL_INPUTS)))
    if trace.has("current_cmd_mA"):
        u[:, _IDX["current_nom_mA"]] = trace.get("current_cmd_mA")
    elif drive == "command":
        raise DataError(f"{trace.name}: no current_cmd_mA to build the command from")
    freq = _signal_or_meta(trace, "dither_freq_Hz", 0.0)
    u[:, _IDX["dither_amp_mA"]] = _signal_or_meta(trace, "dither_amp_mA", 0.0)
    u[:, _IDX["dither_freq_Hz"]] = freq
    u[:, _IDX["dither_phase"]] = np.concatenate(
        [[0.0], np.cumsum(0.5 * (freq[1:] + freq[:-1]) * np.diff(t))]
    )
    wave = str(trace.meta.get("dither_waveform", settings.dither_waveform))
    if wave not in WAVEFORMS:
        raise DataError(f"{trace.name}: dither_waveform {wave!r} is not one of {WAVEFORMS}")
    u[:, _IDX[f"wave_{wave}"]] = 1.0
    if trace.has("current_mA"):
        i_meas = np.asarray(trace.get("current_mA"), dtype=float)
        u[:, _IDX["current_meas_mA"]] = i_meas
        rate = np.diff(i_meas) / np.diff(t)
        u[:, _IDX["current_meas_rate_mA_s"]] = np.concatenate([rate, rate[-1:]])
    u[:, _IDX["line_pressure_bar"]] = trace.get("line_pressure_bar")
    u[:, _IDX["prime_pressure_bar"]] = trace.get("prime_pressure_bar")
    u[:, _IDX["oil_temp_C"]] = _signal_or_meta(trace, "oil_temp_C", settings.oil_temp_C)
    return u


def interval_inputs(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inputs at the start and end of each sample interval.

    Piecewise-constant inputs (the measured-current slope) keep the interval's
    value at both ends so that interpolation does not mix neighbouring intervals.
    """
    u0, u1 = u[:-1].copy(), u[1:].copy()
    k = _IDX["current_meas_rate_mA_s"]
    u1[:, k] = u0[:, k]
    return u0, u1
