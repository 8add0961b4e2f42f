"""Pieces every plant's kernel uses: the dither waveform, smooth limits, the bench loop.

Only the *bench* is shared here (how the dithered current command is formed, how the
fine simulation step is sampled to the logging rate, a transport delay of the logged
pressure); each plant's circuit equations live in its own module.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..environment import BenchDrive

__all__ = ["dither_wave", "run_kernel", "softplus"]


@njit(cache=True)
def dither_wave(phase: float, triangle: bool) -> float:
    """Dither waveform in [-1, 1] at ``phase`` (cycles): sine or triangle."""
    s = math.sin(2.0 * math.pi * phase)
    if triangle:
        return 2.0 / math.pi * math.asin(s)
    return s


@njit(cache=True)
def softplus(x: float, w: float) -> float:
    """Smooth ``max(x, 0)`` with corner width ``w`` (unit of ``x``)."""
    z = x / w
    if z > 30.0:
        return x
    return w * math.log1p(math.exp(z))


def run_kernel(kernel, values: np.ndarray, drive: BenchDrive, substeps: int, waveform: str):
    """Run a plant kernel over one experiment.

    The kernel integrates ``substeps`` fixed steps per logging sample, the dither formed
    at every step (bench inputs held over a sample), and returns the true coil current
    (mA) and the pressure at the transducer output (bar) at the sample times. A
    transport delay parameter ``delay_ms`` (last entry of ``values`` when the plant has
    one) is applied by the caller (:func:`delayed`).
    """
    t = drive.time_s
    dt = float(t[1] - t[0]) / substeps
    return kernel(
        values,
        dt,
        int(substeps),
        np.ascontiguousarray(drive.current_nom_mA, dtype=float),
        np.ascontiguousarray(drive.dither_amp_mA, dtype=float),
        float(drive.dither_freq_Hz),
        float(drive.phase0),
        waveform == "triangle",
        np.ascontiguousarray(drive.line_bar, dtype=float),
        np.ascontiguousarray(drive.prime_bar, dtype=float),
        np.ascontiguousarray(drive.oil_temp_C, dtype=float),
    )


def delayed(x: np.ndarray, delay_s: float, dt: float) -> np.ndarray:
    """``x`` delayed by ``delay_s`` (s), linear interpolation, first value held."""
    if delay_s <= 0:
        return x
    n = len(x)
    t = np.arange(n) * dt
    return np.interp(t - delay_s, t, x, left=x[0])
