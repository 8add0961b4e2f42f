"""Lagged products of a series, the raw material of its autocorrelation (FFT, no wrap-around)."""

from __future__ import annotations

import numpy as np

__all__ = ["lagged_sums"]


def lagged_sums(x: np.ndarray) -> np.ndarray:
    """``Σ_t x_t · x_{t+l}`` for every lag ``l = 0 … n − 1`` (not centred, not normalized).

    Computed by FFT with the series zero-padded to twice its length, so no lag wraps
    around. Centre ``x`` first for an autocovariance; divide by the lag-0 value for an
    autocorrelation; add the sums of several series for a pooled one.

    Parameters
    ----------
    x : numpy.ndarray
        Equally spaced series (any unit u).

    Returns
    -------
    numpy.ndarray
        Length ``len(x)``, unit u².
    """
    x = np.asarray(x, dtype=float)
    n = len(x)
    f = np.fft.rfft(x, 2 * n)
    return np.fft.irfft(f * np.conj(f))[:n]
