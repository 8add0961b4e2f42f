"""Hysteresis analysis: rising / falling branches and the binned hysteresis width.

The hysteresis width at a nominal current ``I`` is the clutch pressure on the rising branch
minus the one on the falling branch, both at ``I`` (bar; the paper's Fig. 5 plots it against
current). Per branch and current bin, the branch pressure at the bin centre comes from a
least-squares line through the branch's samples in the bin, so a bin that a branch covers
unevenly is not biased by the slope of the pressure curve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..data import LINE_PRESSURE_BAR
from .settings import AnalysisSettings

__all__ = [
    "FALLING",
    "RISING",
    "HysteresisCurve",
    "branch_arrays",
    "branch_direction",
    "current_bins",
    "hysteresis_curve",
    "hysteresis_width_error",
]

#: Direction codes of :func:`branch_direction`.
RISING, FALLING, HOLD = 1, -1, 0


def branch_direction(didt_mA_s: ArrayLike, settings: AnalysisSettings | None = None) -> np.ndarray:
    """Branch of each sample from the filtered dI/dt of the nominal current.

    Parameters
    ----------
    didt_mA_s : array_like
        Filtered time derivative of the nominal current, mA/s.
    settings : AnalysisSettings, optional
        Thresholds: a sample is rising when ``dI/dt > rate``, falling when
        ``dI/dt < -rate``, ``rate = max(min_rate_mA_s, rel_rate · P90(|dI/dt|))`` (mA/s).

    Returns
    -------
    numpy.ndarray
        int8 per sample: :data:`RISING` (1), :data:`FALLING` (-1) or 0 (hold).
    """
    s = settings or AnalysisSettings()
    d = np.asarray(didt_mA_s, dtype=float)
    if d.size == 0:
        return np.zeros(0, dtype=np.int8)
    rate = max(s.min_rate_mA_s, s.rel_rate * float(np.percentile(np.abs(d), 90)))
    out = np.zeros(d.size, dtype=np.int8)
    out[d > rate] = RISING
    out[d < -rate] = FALLING
    return out


@dataclass(frozen=True)
class HysteresisCurve:
    """Branch pressures per current bin and the hysteresis width.

    Attributes
    ----------
    center_mA : numpy.ndarray
        Bin centres, mA (bins of ``bin_mA`` starting at multiples of ``bin_mA``).
    rising_bar, falling_bar : numpy.ndarray
        Branch pressure at the bin centre, bar; NaN where the branch does not cover the bin
        (fewer than ``min_samples`` samples or a current span below ``min_coverage · bin_mA``).
    latched : numpy.ndarray
        bool per bin: a sample of either branch in the bin is within ``latch_margin_bar`` of
        line pressure (the latch snap, not the regulator's hysteresis).
    """

    center_mA: np.ndarray
    rising_bar: np.ndarray
    falling_bar: np.ndarray
    latched: np.ndarray

    @property
    def width_bar(self) -> np.ndarray:
        """Rising minus falling pressure per bin, bar (NaN where a branch is missing)."""
        return self.rising_bar - self.falling_bar

    @property
    def valid(self) -> np.ndarray:
        """Bins where both branches are covered."""
        return np.isfinite(self.rising_bar) & np.isfinite(self.falling_bar)


def current_bins(current_mA: ArrayLike, bin_mA: float) -> tuple[int, int]:
    """First and last index of the ``bin_mA`` (mA) current bins that ``current_mA`` (mA) spans."""
    i = np.asarray(current_mA, dtype=float)
    if i.size == 0:
        return 0, -1
    return int(np.floor(i.min() / bin_mA)), int(np.floor(i.max() / bin_mA))


def branch_arrays(
    current_mA: ArrayLike, pressure_bar: ArrayLike, direction: ArrayLike, line_bar: ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Current (mA), pressure (bar), branch code and line pressure (bar, broadcast) as arrays.

    Raises
    ------
    ValueError
        If current, pressure and direction are not 1-D of one length.
    """
    i = np.asarray(current_mA, dtype=float)
    p = np.asarray(pressure_bar, dtype=float)
    d = np.asarray(direction)
    if not (i.shape == p.shape == d.shape) or i.ndim != 1:
        raise ValueError(f"current {i.shape}, pressure {p.shape}, direction {d.shape} differ")
    return i, p, d, np.broadcast_to(np.asarray(line_bar, dtype=float), i.shape)


def _branch_values(
    x: np.ndarray, y: np.ndarray, k: np.ndarray, nbins: int, bin_mA: float, s: AnalysisSettings
) -> np.ndarray:
    """Least-squares line per bin evaluated at the bin centre; NaN where not covered."""
    u = x - (k + 0.5) * bin_mA  # offset from the bin centre, |u| ≤ bin/2: no cancellation
    n = np.bincount(k, minlength=nbins).astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        um = np.bincount(k, u, nbins) / n
        ym = np.bincount(k, y, nbins) / n
        var = np.bincount(k, u * u, nbins) / n - um * um
        cov = np.bincount(k, u * y, nbins) / n - um * ym
        slope = np.where(var > 1e-9 * bin_mA**2, cov / var, 0.0)
    lo = np.full(nbins, np.inf)
    hi = np.full(nbins, -np.inf)
    np.minimum.at(lo, k, u)
    np.maximum.at(hi, k, u)
    ok = (n >= s.min_samples) & (hi - lo >= s.min_coverage * bin_mA)
    return np.where(ok, ym - slope * um, np.nan)


def hysteresis_curve(
    current_mA: ArrayLike,
    pressure_bar: ArrayLike,
    direction: ArrayLike,
    line_bar: ArrayLike | float = LINE_PRESSURE_BAR,
    settings: AnalysisSettings | None = None,
    bins: tuple[int, int] | None = None,
) -> HysteresisCurve:
    """Rising and falling clutch pressure per nominal-current bin.

    Parameters
    ----------
    current_mA : array_like
        Nominal (dither-free) current per sample, mA.
    pressure_bar : array_like
        Clutch pressure per sample, bar (dither-period mean or raw).
    direction : array_like
        Branch per sample (:func:`branch_direction`).
    line_bar : array_like or float
        Line pressure, bar (per sample or constant), for the latched-bin flag.
    settings : AnalysisSettings, optional
        Bin width (mA), coverage rules, latch margin (bar).
    bins : (int, int), optional
        First and last bin index (bin ``k`` spans ``[k, k + 1) · bin_mA``); by default the
        range of ``current_mA``. Pass the same range to compare two curves bin by bin.

    Returns
    -------
    HysteresisCurve
    """
    s = settings or AnalysisSettings()
    i, p, d, line = branch_arrays(current_mA, pressure_bar, direction, line_bar)
    k0, k1 = bins if bins is not None else current_bins(i, s.bin_mA)
    nbins = max(k1 - k0 + 1, 0)
    k_all = np.floor(i / s.bin_mA).astype(np.int64)
    inside = (k_all >= k0) & (k_all <= k1)
    values = {}
    for code in (RISING, FALLING):
        m = (d == code) & inside
        values[code] = _branch_values(i[m], p[m], k_all[m] - k0, nbins, s.bin_mA, s)
    m = (d != HOLD) & inside & (p >= line - s.latch_margin_bar)
    latched = np.bincount(k_all[m] - k0, minlength=nbins) > 0
    return HysteresisCurve(
        center_mA=(np.arange(k0, k1 + 1) + 0.5) * s.bin_mA,
        rising_bar=values[RISING],
        falling_bar=values[FALLING],
        latched=latched,
    )


def hysteresis_width_error(
    measured: HysteresisCurve, predicted: HysteresisCurve
) -> tuple[np.ndarray, np.ndarray]:
    """Predicted minus measured hysteresis width in the regulated bins.

    A bin counts when both branches are covered in both curves and neither curve has a latched
    sample in the bin or its two neighbours: the error measures the regulator's hysteresis;
    the latch snap is scored by the latch currents.

    Parameters
    ----------
    measured, predicted : HysteresisCurve
        On the same bins (same ``center_mA``).

    Returns
    -------
    error_bar : numpy.ndarray
        Width error per counted bin, bar.
    center_mA : numpy.ndarray
        Centre of each counted bin, mA.
    """
    if not np.array_equal(measured.center_mA, predicted.center_mA):
        raise ValueError("the two hysteresis curves are on different current bins")
    latched = measured.latched | predicted.latched
    near = latched.copy()
    near[1:] |= latched[:-1]
    near[:-1] |= latched[1:]
    use = measured.valid & predicted.valid & ~near
    return (predicted.width_bar - measured.width_bar)[use], measured.center_mA[use]
