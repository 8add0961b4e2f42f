"""Time bases of a log: sample rate, jitter and gaps; alignment on one uniform grid."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..errors import DataError

__all__ = ["Timing", "align", "analyse_timing", "uniform_grid"]


@dataclass(frozen=True)
class Timing:
    """Sampling of one time base (a CSV/Parquet time column or an MF4 channel group).

    Parameters
    ----------
    label : str
        Name of the time base in messages (``"time_s"``, ``"group 2"``).
    samples : int
        Number of time stamps.
    start_s, end_s : float
        First and last time stamp, s.
    interval_s : float
        Sample interval of the best uniform grid through the time stamps (least squares over
        the sample slots), s.
    rate_Hz : float
        ``1 / interval_s``, Hz.
    jitter_rms_s, jitter_max_s : float
        RMS and largest deviation of a time stamp from that grid, s.
    gaps : tuple of (int, int)
        ``(index, missing)`` for every interval longer than 1.5 sample intervals: the sample
        index after the gap and the number of samples missing in it.
    """

    label: str
    samples: int
    start_s: float
    end_s: float
    interval_s: float
    rate_Hz: float
    jitter_rms_s: float
    jitter_max_s: float
    gaps: tuple[tuple[int, int], ...] = ()

    @property
    def jitter_fraction(self) -> float:
        """Largest time-stamp deviation as a fraction of the sample interval."""
        return self.jitter_max_s / self.interval_s if self.interval_s > 0 else 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of the fields."""
        out = asdict(self)
        out["gaps"] = [list(g) for g in self.gaps]
        return out


def analyse_timing(t: np.ndarray, label: str) -> Timing:
    """Rate, jitter and gaps of strictly increasing, finite time stamps.

    Parameters
    ----------
    t : numpy.ndarray
        Time stamps, s (finite, strictly increasing, at least 2).
    label : str
        Name of the time base.

    Returns
    -------
    Timing
    """
    with np.errstate(over="ignore", invalid="ignore"):  # absurd time stamps give inf, not noise
        return _analyse(np.asarray(t, dtype=np.float64), label)


def _analyse(t: np.ndarray, label: str) -> Timing:
    dt = np.diff(t)
    dt_med = float(np.median(dt))
    slots = np.concatenate([[0], np.cumsum(np.maximum(np.rint(dt / dt_med), 1.0))])
    missing = slots[1:] - slots[:-1] - 1
    gap_idx = np.flatnonzero((dt > 1.5 * dt_med) & (missing >= 1))
    gaps = tuple((int(i) + 1, int(missing[i])) for i in gap_idx)
    if t.size >= 3:
        k = slots - slots.mean()
        interval = float(np.dot(k, t - t.mean()) / np.dot(k, k))
        resid = t - (t.mean() + interval * k)
        jitter_rms, jitter_max = float(np.sqrt(np.mean(resid**2))), float(np.abs(resid).max())
    else:
        interval, jitter_rms, jitter_max = dt_med, 0.0, 0.0
    return Timing(
        label,
        int(t.size),
        float(t[0]),
        float(t[-1]),
        interval,
        1.0 / interval,
        jitter_rms,
        jitter_max,
        gaps,
    )


def uniform_grid(
    timings: list[Timing], rate_Hz: float | None = None, max_samples: int | None = None
) -> np.ndarray:
    """One uniform grid covering the time span common to every time base.

    Parameters
    ----------
    timings : list of Timing
        The time bases to align.
    rate_Hz : float, optional
        Grid rate, Hz; default the rate of the fastest time base.
    max_samples : int, optional
        Refuse grids longer than this (time stamps so irregular that the fastest interval
        is far below the typical one).

    Returns
    -------
    numpy.ndarray
        Grid times, s, anchored on the fastest time base (its own samples fall on the grid
        when it is regular). Empty if the time bases do not overlap.

    Raises
    ------
    DataError
        If the grid would need more than ``max_samples`` samples.
    """
    ref = min(timings, key=lambda tm: tm.interval_s)
    dt = 1.0 / rate_Hz if rate_Hz is not None else ref.interval_s
    start = max(tm.start_s for tm in timings)
    end = min(tm.end_s for tm in timings)
    if end < start:
        return np.empty(0)
    eps = 1e-6 * dt
    first = ref.start_s + np.ceil((start - ref.start_s) / dt - 1e-6) * dt
    count = np.floor((end - first + eps) / dt) + 1
    if not np.isfinite(count) or count < 1:
        return np.empty(0)
    if max_samples is not None and count > max_samples:
        raise DataError(
            f"resampling onto a uniform grid at {1 / dt:.6g} Hz would need {count:.3g} samples "
            f"(more than {max_samples}); the time stamps are too irregular"
        )
    n = int(count)
    grid = first + dt * np.arange(n)
    grid[0] = max(grid[0], start)
    grid[-1] = min(grid[-1], end)
    return grid


def align(grid: np.ndarray, t: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Values of a channel sampled at ``t``, linearly interpolated onto ``grid``.

    Parameters
    ----------
    grid : numpy.ndarray
        Target times, s, inside ``[t[0], t[-1]]``.
    t : numpy.ndarray
        Channel time stamps, s (strictly increasing).
    values : numpy.ndarray
        Channel values (finite), any unit.

    Returns
    -------
    numpy.ndarray
        float64 values on ``grid``, same unit.
    """
    if t.size == grid.size and np.array_equal(t, grid):
        return np.asarray(values, dtype=np.float64)
    return np.interp(grid, t, values)
