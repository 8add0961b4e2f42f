"""Error metrics of the validation protocol (DESIGN §5 names).

Per variant, on the test experiments pooled (every metric is computed twice: on the clutch
pressure averaged over one dither period — primary — and on the raw pressure — secondary):

==============================  ====  =========================================================
key                             unit  definition
==============================  ====  =========================================================
``rmse_bar``                    bar   √mean(e²), e = predicted − measured, all test samples
``mae_bar``                     bar   mean |e|
``max_abs_bar``                 bar   max |e|
``fit_pct``                     %     100·(1 − ‖e‖/‖y − ȳ‖)
``hysteresis_width_err_bar``    bar   RMS over experiments × 25 mA current bins of predicted
                                      minus measured hysteresis width (rising minus falling
                                      pressure at the bin centre), regulated bins only (see
                                      :func:`~clutchlab.validation.hysteresis.hysteresis_width_error`)
``latch_on_err_mA``             mA    mean over experiments of |predicted − measured| latch-on
                                      current (:func:`~clutchlab.validation.latch.latch_currents`;
                                      a missing snap counts at the peak current)
``latch_off_err_mA``            mA    the same for the latch-off current
``latched_plateau_rmse_bar``    bar   (in ``details``) √mean(e²) over the samples where both
                                      the measured and the predicted pressure are within the
                                      latch margin of line pressure, at least
                                      ``plateau_guard_s`` (50 ms) from a snap or release of
                                      either: the plateau's level, apart from the latch
                                      timing the latch errors score
``coverage_2sigma``             —     (in ``details``, for variants with a predictive std)
                                      share of samples whose period-mean error lies within
                                      ±2σ, per region: ``regulated`` and ``latched`` (the
                                      measured state, more than ``latch_window_s`` from a
                                      measured snap or release) and ``latch_window`` (within
                                      it); see :func:`interval_coverage`. Pooled over
                                      the test experiments listed in
                                      ``coverage_experiments`` (``evaluate``: the featured
                                      one, whose band the report draws)
``rmse_<region>_bar``           bar   (in ``details``) √mean(e²) over the samples of one region
                                      of :func:`coverage_regions` (``regulated``, ``latched``,
                                      ``latch_window``: the measured state, the window around a
                                      measured snap or release); with
                                      ``sq_error_share_<region>`` (share of the summed e²) and
                                      ``samples_share_<region>`` (share of the samples): where
                                      the error lies, e.g. most of it in a few per cent of the
                                      samples around the latch switches (latch timing)
``fit_s``                       s     wall time of ``fit`` on the training experiments (for a
                                      model built on another variant, including that one's)
``predict_s``                   s     wall time of ``predict`` on all test experiments
==============================  ====  =========================================================

The pressure metrics themselves live in the data layer (the physics fit reports the same
numbers) and are re-exported here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.metrics import pressure_metrics
from .hysteresis import current_bins, hysteresis_curve, hysteresis_width_error
from .latch import LatchCurrents, latch_currents, latch_error
from .settings import AnalysisSettings

__all__ = [
    "ACCURACY_KEYS",
    "COVERAGE_REGIONS",
    "METRIC_KEYS",
    "SIGNAL_KINDS",
    "TIMING_KEYS",
    "ExperimentComparison",
    "compare_experiment",
    "coverage_regions",
    "error_by_region",
    "interval_coverage",
    "pool_comparisons",
    "pressure_metrics",
]

#: Error metrics, computed on each signal kind.
ACCURACY_KEYS: tuple[str, ...] = (
    "rmse_bar",
    "mae_bar",
    "max_abs_bar",
    "fit_pct",
    "hysteresis_width_err_bar",
    "latch_on_err_mA",
    "latch_off_err_mA",
)
#: Timings of a variant, s.
TIMING_KEYS: tuple[str, ...] = ("fit_s", "predict_s")
#: Every key of a variant's row in ``metrics.json`` (DESIGN §5).
METRIC_KEYS: tuple[str, ...] = (*ACCURACY_KEYS, *TIMING_KEYS)
#: Scored signals: the dither-period mean (primary) and the raw pressure (secondary).
SIGNAL_KINDS: tuple[str, ...] = ("period_mean", "raw")


@dataclass(frozen=True)
class ExperimentComparison:
    """Measured against predicted clutch pressure on one test experiment, one signal kind.

    Attributes
    ----------
    name : str
        Experiment name.
    measured_bar, predicted_bar : numpy.ndarray
        The compared signals, bar.
    width_err_bar : numpy.ndarray
        Predicted minus measured hysteresis width in each counted current bin, bar.
    latch_measured, latch_predicted : LatchCurrents
        Latch currents of the two signals, mA.
    plateau : numpy.ndarray or None
        Samples where both signals are on the latched plateau (within the latch margin of
        line pressure).
    regions : dict of str to numpy.ndarray or None
        Sample masks of the :data:`COVERAGE_REGIONS` by the measured pressure (None
        without sample times).
    """

    name: str
    measured_bar: np.ndarray
    predicted_bar: np.ndarray
    width_err_bar: np.ndarray
    latch_measured: LatchCurrents
    latch_predicted: LatchCurrents
    plateau: np.ndarray | None = None
    regions: dict[str, np.ndarray] | None = None

    def latch_errors(self) -> dict[str, tuple[float, bool]]:
        """``{"on": (error_mA, censored), "off": (...)}``, see :func:`latch_error`."""
        peak = self.latch_measured.peak_mA
        return {
            "on": latch_error(self.latch_measured.on_mA, self.latch_predicted.on_mA, peak),
            "off": latch_error(self.latch_measured.off_mA, self.latch_predicted.off_mA, peak),
        }

    def summary(self) -> dict[str, float]:
        """Per-experiment numbers for the report (bar, mA; NaN where undefined)."""
        errs = self.latch_errors()
        w = self.width_err_bar
        return {
            **pressure_metrics(self.measured_bar, self.predicted_bar),
            "hysteresis_width_err_bar": float(np.sqrt(np.mean(w * w))) if w.size else np.nan,
            "hysteresis_bins": int(w.size),
            "latch_on_measured_mA": self.latch_measured.on_mA,
            "latch_on_predicted_mA": self.latch_predicted.on_mA,
            "latch_on_err_mA": errs["on"][0],
            "latch_off_measured_mA": self.latch_measured.off_mA,
            "latch_off_predicted_mA": self.latch_predicted.off_mA,
            "latch_off_err_mA": errs["off"][0],
        }


def compare_experiment(
    name: str,
    current_mA: np.ndarray,
    direction: np.ndarray,
    line_bar: np.ndarray | float,
    measured_bar: np.ndarray,
    predicted_bar: np.ndarray,
    settings: AnalysisSettings | None = None,
    time_s: np.ndarray | None = None,
) -> ExperimentComparison:
    """Compare one experiment's predicted clutch pressure with the measured one.

    Parameters
    ----------
    name : str
        Experiment name.
    current_mA : numpy.ndarray
        Nominal current per sample, mA.
    direction : numpy.ndarray
        Branch per sample (:func:`~clutchlab.validation.hysteresis.branch_direction`).
    line_bar : numpy.ndarray or float
        Measured line pressure, bar.
    measured_bar, predicted_bar : numpy.ndarray
        Clutch pressure, bar, same signal kind (both period means, or both raw).
    settings : AnalysisSettings, optional
        Bins and latch margin.
    time_s : numpy.ndarray, optional
        Sample time (s), for the latched plateau's guard around snaps (no guard without)
        and the error's regions (none without).

    Returns
    -------
    ExperimentComparison
    """
    s = settings or AnalysisSettings()
    bins = current_bins(current_mA, s.bin_mA)
    curve_m = hysteresis_curve(current_mA, measured_bar, direction, line_bar, s, bins=bins)
    curve_p = hysteresis_curve(current_mA, predicted_bar, direction, line_bar, s, bins=bins)
    werr, _ = hysteresis_width_error(curve_m, curve_p)
    plateau = _plateau(measured_bar, predicted_bar, line_bar, s, time_s)
    return ExperimentComparison(
        name=name,
        measured_bar=np.asarray(measured_bar, dtype=float),
        predicted_bar=np.asarray(predicted_bar, dtype=float),
        width_err_bar=werr,
        latch_measured=latch_currents(current_mA, measured_bar, direction, line_bar, s),
        latch_predicted=latch_currents(current_mA, predicted_bar, direction, line_bar, s),
        plateau=plateau,
        regions=None if time_s is None else coverage_regions(time_s, line_bar, measured_bar, s),
    )


def _latched(pressure, line, s: AnalysisSettings) -> np.ndarray:
    """Samples within the latch margin of line pressure."""
    return np.asarray(pressure, dtype=float) >= np.asarray(line, dtype=float) - s.latch_margin_bar


def _distance_to_switch(time_s: np.ndarray, *states: np.ndarray) -> np.ndarray:
    """Time (s) from each sample to the nearest switch of any of ``states`` (inf: none).

    A switch sits between the last sample before it and the first after it.
    """
    t = np.asarray(time_s, dtype=float)
    changed = np.zeros(max(t.size - 1, 0), dtype=bool)
    for st in states:
        changed |= np.diff(np.asarray(st, dtype=np.int8)) != 0
    j = np.flatnonzero(changed)
    if not j.size:
        return np.full(t.size, np.inf)
    edges = 0.5 * (t[j] + t[j + 1])
    k = np.clip(np.searchsorted(edges, t), 1, edges.size) - 1
    return np.minimum(np.abs(t - edges[k]), np.abs(t - edges[np.minimum(k + 1, edges.size - 1)]))


def _plateau(measured, predicted, line, s: AnalysisSettings, time_s) -> np.ndarray:
    """Samples where both signals are latched, ``plateau_guard_s`` from any snap of either."""
    lm, lp = _latched(measured, line, s), _latched(predicted, line, s)
    both = lm & lp
    if time_s is None or s.plateau_guard_s <= 0 or both.size < 2:
        return both
    return both & (_distance_to_switch(time_s, lm, lp) >= s.plateau_guard_s)


def pool_comparisons(comparisons: list[ExperimentComparison]) -> dict[str, float]:
    """The accuracy metrics (:data:`ACCURACY_KEYS`) over several test experiments.

    Parameters
    ----------
    comparisons : list of ExperimentComparison
        One per test experiment, one signal kind.

    Returns
    -------
    dict
        :data:`ACCURACY_KEYS` → value (bar, %, mA; NaN when undefined, e.g. no experiment
        latches in either signal), plus ``hysteresis_bins`` (bins counted),
        ``latched_plateau_rmse_bar`` / ``latched_plateau_samples`` (where both signals
        are on the latched plateau),
        ``latch_on_bias_mA`` / ``latch_off_bias_mA`` (mean signed error),
        ``latch_censored`` (experiments where one signal never snapped) and, when every
        comparison has its regions, the error per region (:func:`error_by_region`).
    """
    if not comparisons:
        raise ValueError("no experiments to pool")
    out = pressure_metrics(
        np.concatenate([c.measured_bar for c in comparisons]),
        np.concatenate([c.predicted_bar for c in comparisons]),
    )
    w = np.concatenate([c.width_err_bar for c in comparisons])
    out["hysteresis_width_err_bar"] = float(np.sqrt(np.mean(w * w))) if w.size else np.nan
    extra: dict[str, float] = {"hysteresis_bins": int(w.size), "latch_censored": 0}
    plat = [c for c in comparisons if c.plateau is not None]
    e = np.concatenate([(c.predicted_bar - c.measured_bar)[c.plateau] for c in plat] or [[]])
    extra["latched_plateau_rmse_bar"] = float(np.sqrt(np.mean(e * e))) if e.size else np.nan
    extra["latched_plateau_samples"] = int(e.size)
    for which in ("on", "off"):
        errs = [c.latch_errors()[which] for c in comparisons]
        vals = np.array([e for e, _ in errs if np.isfinite(e)])
        out[f"latch_{which}_err_mA"] = float(np.mean(np.abs(vals))) if vals.size else np.nan
        extra[f"latch_{which}_bias_mA"] = float(np.mean(vals)) if vals.size else np.nan
        extra["latch_censored"] += sum(c for _, c in errs)
    if all(c.regions is not None for c in comparisons):
        extra |= error_by_region(comparisons)
    return {k: out[k] for k in ACCURACY_KEYS} | extra


def error_by_region(comparisons: list[ExperimentComparison]) -> dict[str, float]:
    """Where the squared error lies, pooled over experiments, per :data:`COVERAGE_REGIONS`.

    Parameters
    ----------
    comparisons : list of ExperimentComparison
        With their ``regions`` (compared with sample times).

    Returns
    -------
    dict
        Per region ``r``: ``rmse_{r}_bar`` (bar; NaN without samples),
        ``sq_error_share_{r}`` (its share of the summed squared error, 0–1; NaN when the
        error is zero everywhere) and ``samples_share_{r}`` (its share of the samples, 0–1).
    """
    e2 = np.concatenate([(c.predicted_bar - c.measured_bar) ** 2 for c in comparisons])
    total = float(np.sum(e2))
    out: dict[str, float] = {}
    for r in COVERAGE_REGIONS:
        mask = np.concatenate([c.regions[r] for c in comparisons])
        n = int(np.sum(mask))
        part = float(np.sum(e2[mask]))
        out[f"rmse_{r}_bar"] = float(np.sqrt(part / n)) if n else np.nan
        out[f"sq_error_share_{r}"] = part / total if total > 0 else np.nan
        out[f"samples_share_{r}"] = n / e2.size if e2.size else np.nan
    return out


#: Regions of :func:`interval_coverage`.
COVERAGE_REGIONS: tuple[str, ...] = ("regulated", "latched", "latch_window")


def interval_coverage(
    time_s: np.ndarray,
    line_bar: np.ndarray | float,
    measured_bar: np.ndarray,
    predicted_bar: np.ndarray,
    std_bar: np.ndarray,
    settings: AnalysisSettings | None = None,
    k: float = 2.0,
) -> dict[str, tuple[int, int]]:
    """Samples whose error lies within ``±k·std``, per region: ``{region: (inside, total)}``.

    Regions (:data:`COVERAGE_REGIONS`) by the *measured* pressure: ``latch_window`` within
    ``settings.latch_window_s`` of a measured snap or release (where a wrong latch time
    makes the largest errors), ``latched`` (within the latch margin of line pressure) and
    ``regulated`` elsewhere.

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample time, s.
    line_bar : numpy.ndarray or float
        Line pressure, bar.
    measured_bar, predicted_bar, std_bar : numpy.ndarray
        Measured and predicted clutch pressure and the predictive std, bar (one signal
        kind, e.g. dither-period means).
    settings : AnalysisSettings, optional
        Latch margin and window.
    k : float
        Interval half-width in standard deviations.
    """
    meas = np.asarray(measured_bar, dtype=float)
    inside = np.abs(np.asarray(predicted_bar) - meas) <= k * np.asarray(std_bar, dtype=float)
    masks = coverage_regions(time_s, line_bar, meas, settings)
    return {r: (int(np.sum(inside & m)), int(np.sum(m))) for r, m in masks.items()}


def coverage_regions(
    time_s: np.ndarray,
    line_bar: np.ndarray | float,
    measured_bar: np.ndarray,
    settings: AnalysisSettings | None = None,
) -> dict[str, np.ndarray]:
    """Sample masks of the :data:`COVERAGE_REGIONS` (see :func:`interval_coverage`).

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample time, s.
    line_bar : numpy.ndarray or float
        Line pressure, bar.
    measured_bar : numpy.ndarray
        Measured clutch pressure, bar.
    settings : AnalysisSettings, optional
        Latch margin and window.

    Returns
    -------
    dict of str to numpy.ndarray
        Boolean mask per region.
    """
    s = settings or AnalysisSettings()
    latched = _latched(np.asarray(measured_bar, dtype=float), line_bar, s)
    window = _distance_to_switch(time_s, latched) <= s.latch_window_s
    return {
        "regulated": ~latched & ~window,
        "latched": latched & ~window,
        "latch_window": window,
    }
