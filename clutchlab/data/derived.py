"""Derived signals used by every layer: one-dither-period mean and a filtered dI/dt.

:func:`didt` is centred (it looks half a window ahead, for offline use);
:func:`causal_didt` uses past samples only, so a real-time model (an FMU) computes it
exactly as offline training did.

Both work on uniformly sampled arrays (a trace read by :mod:`clutchlab.data` is uniform when
its log was irregular or multi-rate).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ..errors import DataError

__all__ = [
    "causal_didt",
    "causal_window",
    "didt",
    "dither_period_mean",
    "first_crossing",
    "first_order_lag",
]


def _finite_1d(x: ArrayLike, name: str) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim != 1:
        raise DataError(f"{name} must be 1-D, got shape {arr.shape}")
    if arr.size and not np.isfinite(arr).all():
        i = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise DataError(f"{name} has a non-finite value at row {i + 1}")
    return arr


def dither_period_mean(x: ArrayLike, n: float | ArrayLike) -> np.ndarray:
    """Centered moving average over exactly one dither period.

    The average is the integral of the sample-and-hold signal over a window of exactly ``n``
    samples centred on each sample, so a fractional period (1000 Hz / 70 Hz = 14.29 samples)
    removes the dither and all its harmonics as well as an integer one would. Near the ends
    the window is shifted to stay inside the data.

    Parameters
    ----------
    x : array_like
        Uniformly sampled signal, any unit (e.g. current in mA, pressure in bar); finite.
    n : float or array_like
        Window length in samples (sample rate / dither frequency), > 0; one value or one per
        sample. Values below 1 leave the signal unchanged; a window longer than the signal
        gives the signal mean.

    Returns
    -------
    numpy.ndarray
        float64 moving average, same unit and length as ``x``.

    Raises
    ------
    DataError
        If ``x`` is not 1-D or has non-finite values, or ``n`` is not positive and finite, or
        is neither one value nor one per sample.
    """
    arr = _finite_1d(x, "x")
    size = arr.size
    n_arr = np.asarray(n, dtype=np.float64)
    if n_arr.ndim > 1 or (n_arr.ndim == 1 and n_arr.size not in (1, size)):
        raise DataError(
            f"window length n must be one value or one per sample ({size}), got shape {n_arr.shape}"
        )
    width = np.broadcast_to(n_arr, (size,))
    if size == 0:
        return arr.copy()
    if not np.isfinite(width).all() or (width <= 0).any():
        raise DataError(f"window length n must be positive and finite, got {n!r}")
    width = np.clip(width, 1.0, float(size))
    offset = arr.mean()
    cum = np.concatenate([[0.0], np.cumsum(arr - offset)])  # integral up to k - 1/2 at index k
    center = np.arange(size, dtype=np.float64)
    lo = np.clip(center - width / 2.0, -0.5, size - 0.5 - width)
    hi = lo + width
    knots = np.arange(size + 1, dtype=np.float64)
    integral = np.interp(hi + 0.5, knots, cum) - np.interp(lo + 0.5, knots, cum)
    return integral / width + offset


def _derivative_input(x: ArrayLike, sample_rate_Hz: float, n: float) -> np.ndarray:
    """``x`` as a finite 1-D float array, after checking the rate (Hz) and window (samples)."""
    arr = _finite_1d(x, "x")
    if not np.isfinite(sample_rate_Hz) or sample_rate_Hz <= 0:
        raise DataError(f"sample_rate_Hz must be positive, got {sample_rate_Hz!r}")
    if not np.isfinite(n) or n <= 0:
        raise DataError(f"window length n must be positive, got {n!r}")
    return arr


def didt(x: ArrayLike, sample_rate_Hz: float, n: float, *, polyorder: int = 2) -> np.ndarray:
    """Filtered time derivative (Savitzky–Golay) over about one dither period.

    Fits a polynomial of degree ``polyorder`` over a sliding window of ``n`` samples (rounded
    up to odd) and takes its slope at the centre: the least-squares slope, so white noise of
    standard deviation σ gives a derivative noise of about ``σ · fs · sqrt(12 / n³)``.
    Typical use: ``x`` the nominal current (mA), ``n`` one dither period (fs / f_dither) or a
    few, giving dI/dt in mA/s.

    Parameters
    ----------
    x : array_like
        Uniformly sampled signal (e.g. nominal current, mA); finite.
    sample_rate_Hz : float
        Sample rate, Hz.
    n : float
        Window length, samples (at least ``polyorder + 2``; rounded up to odd).
    polyorder : int, optional
        Degree of the local polynomial (default 2; the slope at the centre equals that of a
        straight-line fit for degree 1 or 2).

    Returns
    -------
    numpy.ndarray
        Derivative in units of ``x`` per second (mA/s for a current in mA).

    Raises
    ------
    DataError
        If ``x`` is not finite and 1-D, or the rate or window is not usable.
    """
    from scipy.signal import savgol_filter

    arr = _derivative_input(x, sample_rate_Hz, n)
    window = max(int(np.ceil(n)), polyorder + 2)
    window += 1 - window % 2
    if arr.size < window:
        if arr.size < 2:
            return np.zeros_like(arr)
        return np.full(arr.size, np.polyfit(np.arange(arr.size), arr, 1)[0] * sample_rate_Hz)
    return savgol_filter(arr, window, polyorder, deriv=1, delta=1.0 / sample_rate_Hz, mode="interp")


def causal_window(n: float) -> int:
    """Samples of the causal dI/dt window for a length of ``n`` samples (see :func:`didt`).

    ``ceil(n)`` (with a 1e-6 allowance, so that ``n`` computed in another order of floating
    point operations, as an FMU does, gives the same count), at least 4, rounded up to odd:
    the same count as the centred :func:`didt` window.

    Parameters
    ----------
    n : float
        Window length, samples (> 0).

    Returns
    -------
    int
        Odd window length, samples (≥ 5).
    """
    window = max(int(np.ceil(n - 1e-6)), 4)
    return window + 1 - window % 2


def causal_didt(x: ArrayLike, sample_rate_Hz: float, n: float) -> np.ndarray:
    """Causal filtered time derivative: least-squares slope over the trailing window.

    At sample k the slope of the straight line fitted to samples ``k − N + 1 … k``,
    ``N = causal_window(n)``; before the first sample the signal is taken as constant at its
    first value (the history a real-time model starts with). For a ramp of rate r it is r
    (as :func:`didt`), lagging by ``(N − 1)/2`` samples; white noise of standard deviation σ
    gives a derivative noise of ``σ · fs · sqrt(12 / (N (N² − 1)))``. The weights are those
    of :class:`clutchlab.physics.fmu.DidtSpec`, which computes it inside an FMU.

    Parameters
    ----------
    x : array_like
        Uniformly sampled signal (e.g. nominal current, mA); finite.
    sample_rate_Hz : float
        Sample rate, Hz.
    n : float
        Window length, samples (rounded by :func:`causal_window`).

    Returns
    -------
    numpy.ndarray
        Derivative in units of ``x`` per second (mA/s for a current in mA).

    Raises
    ------
    DataError
        If ``x`` is not finite and 1-D, or the rate or window is not usable.
    """
    arr = _derivative_input(x, sample_rate_Hz, n)
    if arr.size == 0:
        return arr.copy()
    window = causal_window(n)
    dt = 1.0 / sample_rate_Hz
    j = np.arange(window, dtype=np.float64)  # age of the sample, samples
    w = (-j * dt + (window - 1) * dt / 2) / (dt * dt * window * (window * window - 1) / 12)
    padded = np.concatenate([np.full(window - 1, arr[0]), arr])
    # slope[k] = Σ_j w_j x[k − j]: a correlation of the newest-first window with w
    return np.lib.stride_tricks.sliding_window_view(padded, window)[:, ::-1] @ w


def first_order_lag(x: np.ndarray, tau_s: float, sample_rate_Hz: float) -> np.ndarray:
    """Signal through a first-order lag ``τ dy/dt = x − y``, starting at rest at ``x[0]``.

    Exact discretization for a signal held between samples: ``y[k] = a y[k−1] + (1 − a)
    x[k]``, ``a = exp(−1 / (τ fs))``. Causal (past samples only). On a ramp of rate ``r``
    the output trails the input by ``τ · r`` once the start transient (a few τ) has decayed.

    Parameters
    ----------
    x : numpy.ndarray
        Uniformly sampled signal (e.g. nominal current, mA).
    tau_s : float
        Time constant τ, s (0: the signal itself).
    sample_rate_Hz : float
        Sample rate fs, Hz.

    Returns
    -------
    numpy.ndarray
        The lagged signal, in the units of ``x``.

    Raises
    ------
    DataError
        If ``x`` is not 1-D or not finite, ``tau_s`` is negative or not finite, or
        ``sample_rate_Hz`` is not positive and finite.
    """
    from scipy.signal import lfilter

    x = _finite_1d(x, "x")
    if not (math.isfinite(tau_s) and tau_s >= 0):
        raise DataError(f"time constant tau_s must be finite and >= 0 s, got {tau_s!r}")
    if not (math.isfinite(sample_rate_Hz) and sample_rate_Hz > 0):
        raise DataError(f"sample_rate_Hz must be finite and > 0, got {sample_rate_Hz!r}")
    if tau_s == 0 or x.size == 0:
        return x.copy()
    a = np.exp(-1.0 / (tau_s * sample_rate_Hz))
    y, _ = lfilter([1.0 - a], [1.0, -a], x, zi=[a * x[0]])
    return y


#: Trace metadata key of the dither frequency (Hz) found in the measured current when a log
#: declares none (set when the log is read; see :func:`dither_period_samples`).
FOUND_DITHER_KEY = "dither_freq_found_Hz"


def dither_period_samples(trace) -> float:
    """Samples in one dither period of ``trace`` (fractional; 1.0 without dither).

    The dither frequency (Hz) is the median of the ``dither_freq_Hz`` signal where it is
    positive (a logger that writes 0 Hz while the dither is off, over half the samples, gave
    a 1-sample period), else the manifest's ``dither_freq_Hz``, else the frequency
    demodulated from the measured current when the log was read (metadata
    :data:`FOUND_DITHER_KEY`: DESIGN §3's "demodulated if absent"; before, such a log's
    "dither-period means" were single samples of a dithered pressure); the sample rate (Hz)
    is the trace's.
    """
    if trace.has("dither_freq_Hz"):
        f = np.asarray(trace.get("dither_freq_Hz"), dtype=float)
        f = f[np.isfinite(f) & (f > 0)]
        f = float(np.median(f)) if f.size else 0.0
    else:
        f = float(trace.meta.get("dither_freq_Hz", 0.0) or 0.0)
        if not f > 0:
            f = float(trace.meta.get(FOUND_DITHER_KEY, 0.0) or 0.0)
    return max(1.0, trace.sample_rate_Hz / f) if f > 0 else 1.0


def first_crossing(x: ArrayLike, g: ArrayLike, upward: bool) -> float:
    """Where ``g`` first changes sign in one direction, linearly interpolated in ``x``.

    The shared step of the latch-current analyses (validation report and design studies):
    ``x`` is the nominal current (mA) of one ramp branch, ``g`` the clutch pressure minus a
    threshold (bar).

    Parameters
    ----------
    x : array_like
        Abscissa per sample, e.g. current in mA.
    g : array_like
        Signed distance to the threshold per sample, same length (e.g. bar).
    upward : bool
        True: the first crossing from below (g < 0 to g ≥ 0); False: from above.

    Returns
    -------
    float
        ``x`` at the crossing (unit of ``x``); NaN when ``g`` never crosses that way.

    Raises
    ------
    DataError
        If ``x`` and ``g`` are not 1-D arrays of the same length.
    """
    i = np.asarray(x, dtype=float)
    g = np.asarray(g, dtype=float)
    if i.ndim != 1 or i.shape != g.shape:
        raise DataError(f"x {i.shape} and g {g.shape} must be 1-D and of the same length")
    above = g >= 0
    hit = (above[1:] & ~above[:-1]) if upward else (~above[1:] & above[:-1])
    k = np.flatnonzero(hit)
    if k.size == 0:
        return float("nan")
    k = int(k[0])
    frac = g[k] / (g[k] - g[k + 1]) if g[k] != g[k + 1] else 0.0
    return float(i[k] + frac * (i[k + 1] - i[k]))
