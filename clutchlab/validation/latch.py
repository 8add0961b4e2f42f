"""Latch analysis: the nominal currents at which the clutch pressure snaps to line pressure.

On the rising branch the latch valve latches and the clutch pressure jumps to line pressure
(latch-on current); on the falling branch it releases and the pressure drops back to the
regulated value (latch-off current, lower: the latch has hysteresis, ``p_on > p_off``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..data import LINE_PRESSURE_BAR, first_crossing
from .hysteresis import FALLING, RISING, branch_arrays
from .settings import AnalysisSettings

__all__ = ["LatchCurrents", "latch_currents", "latch_error"]


@dataclass(frozen=True)
class LatchCurrents:
    """Latch-on and latch-off currents of one experiment.

    Attributes
    ----------
    on_mA : float
        Nominal current where the pressure snaps up to line pressure on a rising branch
        (see :func:`latch_currents`), mA (median over rising segments); NaN if it never does.
    off_mA : float
        Nominal current where it drops back on a falling branch, mA; NaN if it never does.
    peak_mA : float
        Highest nominal current on a rising branch, mA (the censoring value when a latch
        current is missing).
    """

    on_mA: float
    off_mA: float
    peak_mA: float


def _segments(mask: np.ndarray) -> list[tuple[int, int]]:
    """Start and stop (exclusive) of each run of True."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def _snap_current(
    i: np.ndarray, p: np.ndarray, line: np.ndarray, upward: bool, s: AnalysisSettings
) -> float:
    """Latch current of one branch segment: coarse threshold crossing, then the midpoint.

    The coarse crossing is that of ``line − latch_margin_bar``. The refined one is the
    crossing of the midpoint between line pressure and the regulated pressure extrapolated
    from the branch's samples 1–3 current bins below the coarse crossing, where the snap
    is centred for any symmetric smoothing of the step (the dither-period mean spreads a
    snap over one period).
    """
    coarse = first_crossing(i, p - (line - s.latch_margin_bar), upward)
    if not np.isfinite(coarse):
        return coarse
    near = (i >= coarse - 3 * s.bin_mA) & (i <= coarse - s.bin_mA)
    if near.sum() < s.min_samples or np.ptp(i[near]) < s.min_coverage * s.bin_mA:
        return coarse
    slope, offset = np.polyfit(i[near] - coarse, p[near], 1)
    regulated = offset + slope * (i - coarse)
    fine = first_crossing(i, p - 0.5 * (regulated + line), upward)
    return fine if np.isfinite(fine) and abs(fine - coarse) <= s.bin_mA else coarse


def latch_currents(
    current_mA: ArrayLike,
    pressure_bar: ArrayLike,
    direction: ArrayLike,
    line_bar: ArrayLike | float = LINE_PRESSURE_BAR,
    settings: AnalysisSettings | None = None,
) -> LatchCurrents:
    """Latch-on and latch-off currents of a clutch pressure trace.

    Per branch segment, the first crossing of ``line_bar − latch_margin_bar`` locates the
    snap; the latch current is then the crossing of the midpoint between line pressure and
    the regulated pressure just below the snap (extrapolated linearly from the samples one to
    three ``bin_mA`` below it), interpolated linearly between the two samples around it.

    Parameters
    ----------
    current_mA : array_like
        Nominal current per sample, mA.
    pressure_bar : array_like
        Clutch pressure per sample, bar.
    direction : array_like
        Branch per sample (:func:`~clutchlab.validation.hysteresis.branch_direction`).
    line_bar : array_like or float
        Line pressure, bar (per sample or constant).
    settings : AnalysisSettings, optional
        ``latch_margin_bar`` (bar).

    Returns
    -------
    LatchCurrents
    """
    s = settings or AnalysisSettings()
    i, p, d, line = branch_arrays(current_mA, pressure_bar, direction, line_bar)
    found = {}
    for code in (RISING, FALLING):
        hits = [
            _snap_current(i[a:b], p[a:b], line[a:b], code == RISING, s)
            for a, b in _segments(d == code)
        ]
        hits = [h for h in hits if np.isfinite(h)]
        found[code] = float(np.median(hits)) if hits else np.nan
    rising = d == RISING
    peak = float(i[rising].max()) if rising.any() else float(i.max(initial=np.nan))
    return LatchCurrents(on_mA=found[RISING], off_mA=found[FALLING], peak_mA=peak)


def latch_error(measured: float, predicted: float, peak_mA: float) -> tuple[float, bool]:
    """Predicted minus measured latch current, with a missing latch censored at the peak.

    Parameters
    ----------
    measured, predicted : float
        Latch current (on or off), mA; NaN when that signal never snaps.
    peak_mA : float
        Highest nominal current of the rising branch, mA: a pressure that never snaps is
        scored as if it snapped there (the smallest error consistent with it).

    Returns
    -------
    error_mA : float
        Predicted minus measured, mA; NaN when neither signal snaps.
    censored : bool
        Whether one of the two was missing and replaced by ``peak_mA``.
    """
    m_ok, p_ok = np.isfinite(measured), np.isfinite(predicted)
    if not (m_ok or p_ok):
        return float("nan"), False
    m = measured if m_ok else peak_mA
    p = predicted if p_ok else peak_mA
    return float(p - m), not (m_ok and p_ok)
