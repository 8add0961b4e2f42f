"""Engineering metrics of one design point, from its simulated ramps and current step.

Every analysis works on the dither-period mean of the simulated sensor pressure
(:func:`clutchlab.data.dither_period_mean`) against the *nominal* current; the branches
(rising / falling) are known exactly from the ramp profile, so no dI/dt threshold is needed.
Definitions follow the validation metrics (DESIGN §5): 25 mA bins, rising minus falling
pressure, latch = within 1 bar of line pressure.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ...data import dither_period_mean, first_crossing

__all__ = [
    "METRIC_UNITS",
    "MetricSettings",
    "hysteresis_width",
    "latch_currents",
    "metric_names",
    "regulated_gain",
    "response_times",
    "ripple",
]


@dataclass(frozen=True)
class MetricSettings:
    """Windows and thresholds of the design-point metrics.

    Attributes
    ----------
    bin_mA : float
        Current bin width of the hysteresis analysis (mA).
    hysteresis_mA : (float, float)
        Current window of the hysteresis width (mA); bins with a latched sample (and their
        neighbours) are left out.
    gain_mA : (float, float)
        Current window of the regulated-gain fit on the rising branch (mA).
    ripple_mA : (float, float)
        Current window of the dither-ripple measurement on the rising branch (mA).
    latch_margin_bar : float
        Pressure counts as latched within this margin of line pressure (bar).
    settle_band : float
        Settling band of the step response, fraction of the step size (0.05 = 5 %).
    """

    bin_mA: float = 25.0
    hysteresis_mA: tuple[float, float] = (600.0, 1000.0)
    gain_mA: tuple[float, float] = (250.0, 700.0)
    ripple_mA: tuple[float, float] = (400.0, 800.0)
    latch_margin_bar: float = 1.0
    settle_band: float = 0.05

    def __post_init__(self) -> None:
        problems = []
        if not self.bin_mA > 0:
            problems.append(f"bin_mA must be > 0, got {self.bin_mA}")
        if not self.latch_margin_bar > 0:
            problems.append(f"latch_margin_bar must be > 0, got {self.latch_margin_bar}")
        if not 0 < self.settle_band < 1:
            problems.append(f"settle_band must be in (0, 1), got {self.settle_band}")
        if problems:
            raise ValueError("; ".join(problems))


#: Unit of each metric that does not depend on the ramp labels.
METRIC_UNITS: dict[str, str] = {
    "regulated_gain_bar_per_A": "bar/A",
    "latch_on_mA": "mA",
    "latch_off_mA": "mA",
    "ripple_pp_bar": "bar",
    "ripple_rms_bar": "bar",
    "rise_10_90_s": "s",
    "settle_s": "s",
}


def metric_names(ramp_labels: tuple[str, ...], step: bool = True) -> tuple[str, ...]:
    """Metric columns of a sweep: fixed ones, one hysteresis width per ramp, step metrics."""
    names = ["regulated_gain_bar_per_A", "latch_on_mA", "latch_off_mA"]
    names += [f"hysteresis_{r}_bar" for r in ramp_labels]
    names += ["ripple_pp_bar", "ripple_rms_bar"]
    if step:
        names += ["rise_10_90_s", "settle_s"]
    return tuple(names)


def latch_currents(
    current_mA: np.ndarray,
    pressure_bar: np.ndarray,
    rising: np.ndarray,
    falling: np.ndarray,
    line_bar: float,
    margin_bar: float = 1.0,
) -> tuple[float, float]:
    """Latch-on and latch-off current of one ramp.

    Parameters
    ----------
    current_mA : ndarray
        Nominal current per sample (mA).
    pressure_bar : ndarray
        Dither-period mean clutch pressure per sample (bar).
    rising, falling : ndarray of bool
        Samples of the up and down ramp.
    line_bar : float
        Line pressure (bar).
    margin_bar : float
        Latched means within this margin of line pressure (bar).

    Returns
    -------
    on_mA, off_mA : float
        Current at the first upward crossing of ``line − margin`` on the rising branch and at
        the first downward crossing on the falling branch (mA); NaN if it never crosses.
    """
    g = pressure_bar - (line_bar - margin_bar)
    on = first_crossing(current_mA[rising], g[rising], upward=True)
    off = first_crossing(current_mA[falling], g[falling], upward=False)
    return on, off


def hysteresis_width(
    current_mA: np.ndarray,
    pressure_bar: np.ndarray,
    rising: np.ndarray,
    falling: np.ndarray,
    line_bar: float,
    settings: MetricSettings,
) -> float:
    """Mean rising-minus-falling pressure over the hysteresis window (bar).

    Per ``bin_mA`` bin the branch pressure is the mean of its samples; bins where either
    branch is within ``latch_margin_bar`` of line pressure, and their neighbours, are left
    out (that is the latch, not the regulator's hysteresis). Negative: the rising branch
    lies below the falling one.

    Returns
    -------
    float
        Width (bar); NaN when no bin qualifies.
    """
    lo, hi = settings.hysteresis_mA
    edges = np.arange(lo, hi + 1e-9, settings.bin_mA)
    latched = pressure_bar >= line_bar - settings.latch_margin_bar
    widths, bad = [], []
    for a, b in itertools.pairwise(edges):
        inside = (current_mA >= a) & (current_mA < b)
        up, dn = inside & rising, inside & falling
        if not up.any() or not dn.any():
            widths.append(np.nan)
            bad.append(True)
            continue
        widths.append(pressure_bar[up].mean() - pressure_bar[dn].mean())
        bad.append(bool(latched[up | dn].any()))
    bad_arr = np.array(bad, dtype=bool)
    near = bad_arr.copy()
    near[1:] |= bad_arr[:-1]
    near[:-1] |= bad_arr[1:]
    w = np.array(widths)[~near]
    return float(w.mean()) if w.size else float("nan")


def regulated_gain(
    current_mA: np.ndarray,
    pressure_bar: np.ndarray,
    rising: np.ndarray,
    line_bar: float,
    settings: MetricSettings,
) -> float:
    """Slope of the unlatched rising branch over the gain window (bar/A).

    Returns
    -------
    float
        Least-squares slope of period-mean pressure vs nominal current, bar/A; NaN with
        fewer than 10 samples.
    """
    lo, hi = settings.gain_mA
    sel = rising & (current_mA >= lo) & (current_mA <= hi)
    sel &= pressure_bar < line_bar - settings.latch_margin_bar
    if sel.sum() < 10:
        return float("nan")
    return float(np.polyfit(current_mA[sel], pressure_bar[sel], 1)[0] * 1000.0)


def ripple(
    current_mA: np.ndarray,
    raw_bar: np.ndarray,
    mean_bar: np.ndarray,
    rising: np.ndarray,
    line_bar: float,
    settings: MetricSettings,
    min_samples: int = 1,
) -> tuple[float, float]:
    """Dither ripple: raw minus period-mean pressure on the rising branch in the ripple window.

    Parameters
    ----------
    current_mA : ndarray
        Nominal current per sample (mA).
    raw_bar, mean_bar : ndarray
        Pressure and its dither-period mean per sample (bar).
    rising : ndarray of bool
        Samples of the up ramp.
    line_bar : float
        Line pressure (bar).
    settings : MetricSettings
        ``ripple_mA`` window and ``latch_margin_bar``.
    min_samples : int
        Fewest unlatched samples in the window: one dither period's worth, or the ripple of a
        fraction of a period (a ramp crossing the window faster than one period) would be
        reported as if it were the ripple.

    Returns
    -------
    pp_bar, rms_bar : float
        Peak-to-peak and RMS of the ripple (bar); NaN with fewer than ``min_samples``
        unlatched samples in the window.
    """
    lo, hi = settings.ripple_mA
    sel = rising & (current_mA >= lo) & (current_mA <= hi)
    sel &= mean_bar < line_bar - settings.latch_margin_bar
    if not sel.any() or sel.sum() < min_samples:
        return float("nan"), float("nan")
    r = raw_bar[sel] - mean_bar[sel]
    return float(r.max() - r.min()), float(np.sqrt(np.mean(r * r)))


def response_times(
    time_s: np.ndarray,
    pressure_bar: np.ndarray,
    t_step_s: float,
    settings: MetricSettings,
    n_final: int,
) -> tuple[float, float]:
    """Rise time (10–90 %) and settling time of the period-mean pressure after a current step.

    Parameters
    ----------
    time_s : ndarray
        Sample times (s).
    pressure_bar : ndarray
        Dither-period mean pressure (bar).
    t_step_s : float
        Time of the step (s).
    settings : MetricSettings
        ``settle_band``: fraction of the step size.
    n_final : int
        Samples at the end averaged for the final value (one dither period or more).

    Returns
    -------
    rise_s, settle_s : float
        Time from 10 % to 90 % of the pressure change, and from the step until the pressure
        stays within ``settle_band`` of the final value (s); NaN if the change is below
        0.1 bar or the pressure never gets there.
    """
    before = time_s < t_step_s
    after = ~before
    p0 = float(pressure_bar[before][-n_final:].mean())
    p1 = float(pressure_bar[-n_final:].mean())
    dp = p1 - p0
    if abs(dp) < 0.1:
        return float("nan"), float("nan")
    t, p = time_s[after], (pressure_bar[after] - p0) / dp
    t10 = _first_time(t, p, 0.1)
    t90 = _first_time(t, p, 0.9)
    outside = np.flatnonzero(np.abs(p - 1.0) > settings.settle_band)
    if outside.size == 0:
        settle = 0.0
    elif outside[-1] >= len(t) - 1:
        settle = float("nan")
    else:
        settle = float(t[outside[-1] + 1] - t_step_s)
    return t90 - t10, settle


def _first_time(t: np.ndarray, p: np.ndarray, level: float) -> float:
    k = np.flatnonzero(p >= level)
    if k.size == 0:
        return float("nan")
    k = int(k[0])
    if k == 0:
        return float(t[0])
    frac = (level - p[k - 1]) / (p[k] - p[k - 1])
    return float(t[k - 1] + frac * (t[k] - t[k - 1]))


def period_mean(pressure_bar: np.ndarray, sample_rate_Hz: float, freq_Hz: float) -> np.ndarray:
    """Dither-period mean of a pressure signal (bar) sampled at ``sample_rate_Hz`` (Hz)."""
    return dither_period_mean(pressure_bar, sample_rate_Hz / freq_Hz)
