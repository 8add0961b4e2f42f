"""Drive profiles for simulation before any hardware exists.

A design engineer simulates the circuit on current profiles of their own — a step, a slow
ramp with a long hold, a profile without dither — not on test-stand logs. A
:class:`~clutchlab.data.Trace` needs a measured clutch pressure, which such a profile does not
have; :func:`drive_trace` builds the trace from the inputs alone (the pressure NaN: nothing
measured), and :func:`knot_profile` samples a piecewise-linear current given by its corners,
where a repeated corner time is a step.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ..data import LINE_PRESSURE_BAR, Trace
from ..errors import DataError
from .inputs import WAVEFORMS

__all__ = ["drive_trace", "knot_profile"]


def knot_profile(
    knots_s: Sequence[float], knots_mA: Sequence[float], sample_rate_Hz: float = 1000.0
) -> tuple[np.ndarray, np.ndarray]:
    """A piecewise-linear current through its corners, sampled on a uniform grid.

    Parameters
    ----------
    knots_s : sequence of float
        Corner times (s), non-decreasing; a time given twice is a step there (the current
        jumps between the two samples around it).
    knots_mA : sequence of float
        Current at each corner (mA).
    sample_rate_Hz : float
        Sample rate of the grid (Hz); 1 kHz, the stand's, by default.

    Returns
    -------
    time_s : numpy.ndarray
        ``knots_s[0]`` to ``knots_s[-1]`` (s), every ``1 / sample_rate_Hz``.
    current_mA : numpy.ndarray
        The current on that grid (mA).

    Raises
    ------
    DataError
        Listing every problem: lengths that differ, fewer than two corners, a time that
        goes back, a profile shorter than two samples, values that are not finite.
    """
    t = np.asarray(knots_s, dtype=float).ravel()
    i = np.asarray(knots_mA, dtype=float).ravel()
    problems = []
    if t.size != i.size:
        problems.append(f"{t.size} corner times but {i.size} currents")
    if t.size < 2:
        problems.append("a profile needs at least two corners")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(i))):
        problems.append("corner times and currents must be finite numbers")
    elif t.size >= 2 and t.size == i.size:
        back = np.flatnonzero(np.diff(t) < 0)
        if back.size:
            k = int(back[0])
            problems.append(
                f"corner time goes back from {t[k]:g} s to {t[k + 1]:g} s (corner {k + 2}); "
                "give the corners in time order (a time given twice is a step)"
            )
    if not (isinstance(sample_rate_Hz, int | float) and math.isfinite(sample_rate_Hz)):
        problems.append(f"sample_rate_Hz must be a finite number, got {sample_rate_Hz!r}")
    elif sample_rate_Hz <= 0:
        problems.append(f"sample_rate_Hz must be > 0, got {sample_rate_Hz!r}")
    if not problems and (t[-1] - t[0]) * sample_rate_Hz < 1.0:
        problems.append(
            f"the profile lasts {t[-1] - t[0]:g} s, less than one sample at {sample_rate_Hz:g} Hz"
        )
    if problems:
        raise DataError("invalid current profile", problems)
    n = math.floor((t[-1] - t[0]) * sample_rate_Hz * (1.0 + 1e-12)) + 1
    grid = t[0] + np.arange(n) / sample_rate_Hz
    # at a repeated corner np.interp takes the right-hand value: the step is at that time
    return grid, np.interp(grid, t, i)


def _column(name: str, value: ArrayLike, n: int, problems: list[str]) -> np.ndarray:
    """``value`` as an n-sample float column: a scalar is held constant."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        return np.full(n, float(arr))
    arr = arr.ravel()
    if arr.size != n:
        problems.append(f"{name} has {arr.size} samples, time_s {n}")
    return arr


def drive_trace(
    time_s: ArrayLike,
    current_mA: ArrayLike,
    *,
    dither_amp_mA: ArrayLike = 0.0,
    dither_freq_Hz: ArrayLike = 0.0,
    dither_waveform: str = "sine",
    line_pressure_bar: ArrayLike = LINE_PRESSURE_BAR,
    prime_pressure_bar: ArrayLike = 0.5,
    oil_temp_C: ArrayLike = 40.0,
    name: str = "profile",
) -> Trace:
    """A trace of the circuit's inputs alone, to simulate a design on (nothing measured).

    Parameters
    ----------
    time_s : array_like
        Sample times (s), strictly increasing; 1 kHz or faster resolves a dither, coarser
        grids are integrated in steps of at most 0.5 ms (see
        :class:`~clutchlab.physics.SimulationSettings`).
    current_mA : array_like
        Nominal (dither-free) coil current command per sample (mA).
    dither_amp_mA : float or array_like
        Dither amplitude (mA); 0, no dither, by default.
    dither_freq_Hz : float or array_like
        Dither frequency (Hz); 0 by default, which only a zero dither amplitude may have
        (a dither amplitude at 0 Hz would be ignored: it is refused).
    dither_waveform : {"sine", "triangle", "square"}
        Dither waveform (what the trace's ``dither_waveform`` metadata says).
    line_pressure_bar, prime_pressure_bar : float or array_like
        Supply (line) and prime pressure (bar); the DESIGN defaults 17.7 and 0.5 bar.
    oil_temp_C : float or array_like
        Oil temperature (°C); it matters only to a model with the ``oil_temperature`` effect.
    name : str
        The trace's name (results and messages carry it).

    Returns
    -------
    Trace
        ``time_s``, ``current_cmd_mA``, ``dither_amp_mA``, ``dither_freq_Hz``, line and prime
        pressure, oil temperature; ``clutch_pressure_bar`` NaN (nothing measured), so it is
        never mistaken for data. Hand it to :func:`~clutchlab.physics.simulate`.

    Raises
    ------
    DataError
        Listing every problem: columns whose length is not ``time_s``'s, a waveform that is
        not one of the three, a dither amplitude without a dither frequency, and whatever
        the trace's own checks find (times not increasing, values that are not finite or
        outside a signal's physical range).

    Examples
    --------
    >>> from clutchlab.physics import CircuitModel, drive_trace, knot_profile, simulate
    >>> t, i = knot_profile([0.0, 0.5, 0.5, 1.5], [0.0, 0.0, 800.0, 800.0])  # step at 0.5 s
    >>> trace = drive_trace(t, i, dither_amp_mA=100.0, dither_freq_Hz=50.0)
    >>> model = CircuitModel()
    >>> result = simulate(model, model.default_params(), trace)  # doctest: +SKIP
    """
    t = np.asarray(time_s, dtype=float).ravel()
    n = t.size
    problems: list[str] = []
    columns = {
        "current_cmd_mA": current_mA,
        "dither_amp_mA": dither_amp_mA,
        "dither_freq_Hz": dither_freq_Hz,
        "line_pressure_bar": line_pressure_bar,
        "prime_pressure_bar": prime_pressure_bar,
        "oil_temp_C": oil_temp_C,
    }
    signals = {"time_s": t} | {k: _column(k, v, n, problems) for k, v in columns.items()}
    if dither_waveform not in WAVEFORMS:
        problems.append(f"dither_waveform {dither_waveform!r} is not one of {WAVEFORMS}")
    if not problems:
        amp, freq = signals["dither_amp_mA"], signals["dither_freq_Hz"]
        idle = np.flatnonzero((amp != 0.0) & (freq == 0.0))
        if idle.size:
            problems.append(
                f"dither_amp_mA is {amp[idle[0]]:g} mA at dither_freq_Hz = 0 Hz (row "
                f"{idle[0]}, {idle.size} rows in total): a 0 Hz dither is no dither, the "
                "amplitude would be ignored; give dither_freq_Hz (e.g. 50.0), or "
                "dither_amp_mA=0 for no dither"
            )
    if problems:
        raise DataError(f"{name}: invalid drive profile", problems)
    signals["clutch_pressure_bar"] = np.full(n, np.nan)
    return Trace(name, signals, meta={"dither_waveform": dither_waveform})
