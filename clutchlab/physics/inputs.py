"""Model input matrices from a trace: the dither resolved, defaults filled in."""

from __future__ import annotations

import math

import numpy as np

from ..data import Trace
from ..data.validate import check_values
from ..errors import DataError
from .assembly import MODEL_INPUTS
from .settings import SimulationSettings

__all__ = ["WAVEFORMS", "choose_drive", "input_matrix", "interval_inputs", "split_intervals"]

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


def _signal_or_meta(trace: Trace, name: str, fallback: float, problems: list[str]) -> np.ndarray:
    """The signal ``name``, else the trace's metadata value of that key, else ``fallback``."""
    if trace.has(name):
        return np.asarray(trace.get(name), dtype=float)
    value = trace.meta.get(name, fallback)
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not math.isfinite(number):
        problems.append(
            f"metadata {name} = {value!r} is not a finite number (it stands for the "
            f"absent {name} signal)"
        )
    return np.full(len(trace), number)


def _check_finite(trace: Trace, name: str, values: np.ndarray, problems: list[str]) -> None:
    """Add a problem naming the first sample (and time) where input ``name`` is not finite."""
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        k = int(bad[0])
        more = f" and {bad.size - 1} more sample(s)" if bad.size > 1 else ""
        problems.append(
            f"signal {name!r} is {values[k]} at t = {trace.time_s[k]:.6g} s "
            f"(sample {k}, row {k + 1}){more}"
        )


def input_matrix(trace: Trace, drive: str, settings: SimulationSettings) -> np.ndarray:
    """Inputs (N × nu, :data:`MODEL_INPUTS` order) on the trace's time grid.

    The dither phase is the trapezoidal integral of the dither frequency; the
    waveform comes from ``trace.meta["dither_waveform"]`` or the settings.

    Raises
    ------
    DataError
        If the trace has fewer than 2 samples (the sample interval sets the integration
        step), or listing every input signal that is not finite (with its first sample and
        time), every input signal in an implausible unit (a current in A, a pressure in
        Pa or psi, a temperature in °F or K) or outside its physical range, and every
        metadata value standing for an absent signal that is not a finite number — found
        before anything is integrated.
    """
    t = trace.time_s
    n = len(trace)
    if n < 2:
        raise DataError(
            f"{trace.name}: a simulation needs at least 2 samples (the sample interval sets "
            f"the integration step); the trace has {n}"
        )
    problems: list[str] = []
    u = np.zeros((n, len(MODEL_INPUTS)))
    if trace.has("current_cmd_mA"):
        u[:, _IDX["current_nom_mA"]] = trace.get("current_cmd_mA")
        _check_finite(trace, "current_cmd_mA", u[:, _IDX["current_nom_mA"]], problems)
    elif drive == "command":
        raise DataError(f"{trace.name}: no current_cmd_mA to build the command from")
    freq = _signal_or_meta(trace, "dither_freq_Hz", 0.0, problems)
    amp = _signal_or_meta(trace, "dither_amp_mA", 0.0, problems)
    for name, values in (("dither_freq_Hz", freq), ("dither_amp_mA", amp)):
        if trace.has(name):
            _check_finite(trace, name, values, problems)
    u[:, _IDX["dither_amp_mA"]] = amp
    u[:, _IDX["dither_freq_Hz"]] = freq
    u[:, _IDX["dither_phase"]] = np.concatenate(
        [[0.0], np.cumsum(0.5 * (freq[1:] + freq[:-1]) * np.diff(t))]
    )
    wave = str(trace.meta.get("dither_waveform", settings.dither_waveform))
    if wave not in WAVEFORMS:
        problems.append(f"metadata dither_waveform {wave!r} is not one of {WAVEFORMS}")
    else:
        u[:, _IDX[f"wave_{wave}"]] = 1.0
    if trace.has("current_mA"):
        i_meas = np.asarray(trace.get("current_mA"), dtype=float)
        _check_finite(trace, "current_mA", i_meas, problems)
        u[:, _IDX["current_meas_mA"]] = i_meas
        rate = np.diff(i_meas) / np.diff(t)
        u[:, _IDX["current_meas_rate_mA_s"]] = np.concatenate([rate, rate[-1:]])
    for name in ("line_pressure_bar", "prime_pressure_bar"):
        u[:, _IDX[name]] = trace.get(name)
        _check_finite(trace, name, u[:, _IDX[name]], problems)
    oil = _signal_or_meta(trace, "oil_temp_C", settings.oil_temp_C, problems)
    if trace.has("oil_temp_C"):
        _check_finite(trace, "oil_temp_C", oil, problems)
    u[:, _IDX["oil_temp_C"]] = oil
    for name in _CHECKED_SIGNALS:  # a current in A, a pressure in Pa / psi, °F / K, …
        if trace.has(name):
            problems += check_values(name, np.asarray(trace.get(name)), f"signal {name!r}")
    if problems:
        raise DataError(f"{trace.name}: cannot simulate, bad inputs", problems)
    return u


#: Input signals checked for an implausible unit or a value outside the signal's physical
#: range (:func:`clutchlab.data.validate.check_values`, as every file read is): a trace
#: built in code is not read through the data layer's validation.
_CHECKED_SIGNALS = (
    "current_cmd_mA",
    "current_mA",
    "dither_amp_mA",
    "dither_freq_Hz",
    "line_pressure_bar",
    "prime_pressure_bar",
    "oil_temp_C",
)


def interval_inputs(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inputs at the start and end of each sample interval.

    Piecewise-constant inputs (the measured-current slope) keep the interval's
    value at both ends so that interpolation does not mix neighbouring intervals.
    """
    u0, u1 = u[:-1].copy(), u[1:].copy()
    k = _IDX["current_meas_rate_mA_s"]
    u1[:, k] = u0[:, k]
    return u0, u1


def split_intervals(
    t: np.ndarray, u: np.ndarray, parts: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A finer grid: sample interval ``k`` of ``(t, u)`` split into ``parts[k]`` equal ones.

    The inputs at the new points are interpolated linearly, as the integrator does within
    an interval; the piecewise-constant measured-current slope keeps its interval's value.
    The original samples are kept exactly.

    Parameters
    ----------
    t : numpy.ndarray
        Sample times (s), N.
    u : numpy.ndarray
        Inputs (N × nu, :data:`MODEL_INPUTS` order).
    parts : numpy.ndarray
        Parts of each of the N − 1 intervals (int ≥ 1).

    Returns
    -------
    t_fine : numpy.ndarray
        Times (s), M = 1 + Σ parts.
    u_fine : numpy.ndarray
        Inputs (M × nu).
    keep : numpy.ndarray
        Index in the fine grid of each original sample (N).
    """
    parts = np.asarray(parts, dtype=np.int64)
    keep = np.concatenate([[0], np.cumsum(parts)])
    k = np.repeat(np.arange(len(parts)), parts)  # original interval of each fine interval
    frac = (np.arange(keep[-1]) - keep[k]) / parts[k]
    t_fine = np.empty(keep[-1] + 1)
    u_fine = np.empty((keep[-1] + 1, u.shape[1]))
    t_fine[:-1] = t[k] + frac * (t[k + 1] - t[k])
    u_fine[:-1] = u[k] + frac[:, None] * (u[k + 1] - u[k])
    t_fine[keep] = t  # exactly, not t[k] + 1.0 * (t[k + 1] - t[k])
    u_fine[keep] = u
    r = _IDX["current_meas_rate_mA_s"]
    u_fine[:-1, r] = u[k, r]
    u_fine[-1, r] = u[-1, r]
    return t_fine, u_fine, keep
