"""Figures of the comparison report (matplotlib ``Figure`` objects, no pyplot).

Each function takes an :class:`~clutchlab.validation.evaluate.Evaluation` and returns a
:class:`matplotlib.figure.Figure`, or None when the evaluation lacks what it draws (e.g. no
variant with a predictive standard deviation). The paper's figure numbers refer to Bagla &
Schneider (CTI 2020).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.figure import Figure

from .averaging import scored_signal
from .hysteresis import HysteresisCurve

if TYPE_CHECKING:
    from .evaluate import Evaluation

__all__ = [
    "VARIANT_COLORS",
    "FigureSpec",
    "featured_experiment",
    "plot_classifier_comparison",
    "plot_hysteresis_bands",
    "plot_prediction_vs_time",
    "plot_pressure_vs_current",
    "plot_residuals",
    "plot_uncertainty",
    "ramps_in_summary_order",
    "report_figures",
    "signal_of",
]

#: Line colour of each variant (and of the measurement) in every figure.
VARIANT_COLORS: dict[str, str] = {
    "measured": "black",
    "physics_default": "#b8860b",
    "physics_fitted": "#d62728",
    "gp_base": "#1f77b4",
    "gp_didt": "#17becf",
    "paper_svc_gp": "#2ca02c",
    "hybrid": "#9467bd",
    "augmented_hybrid": "#8c564b",
    "paper_faithful": "#e377c2",
    "physics_fmu": "#7f7f7f",
}
_RAMP_COLORS = {"fast": "tab:blue", "medium": "black", "slow": "tab:green"}
_MAX_POINTS = 6000


def _color(name: str, k: int = 0) -> str:
    return VARIANT_COLORS.get(name, f"C{k % 10}")


def _thin(n: int) -> slice:
    return slice(None, None, max(1, n // _MAX_POINTS))


def featured_experiment(ev: Evaluation) -> str:
    """The test experiment drawn in the single-experiment figures (the middle one by name)."""
    return ev.protocol.featured


def signal_of(ev: Evaluation) -> str:
    """What the figures' pressure is, for labels and captions: ``"dither-period mean"``, or
    what it really is when a test log has no dither to average over
    (:func:`~clutchlab.validation.averaging.scored_signal`)."""
    return scored_signal({n: ref.averaging for n, ref in ev.references.items()})


def _present(ev: Evaluation, wanted: Sequence[str]) -> list[str]:
    return [n for n in wanted if n in ev.scores]


def plot_prediction_vs_time(ev: Evaluation, experiment: str | None = None) -> Figure | None:
    """Evolution of the prediction on a test experiment (paper Fig. 3).

    Measured clutch pressure and the predictions of ``gp_base`` and ``paper_svc_gp`` (every
    scored variant when neither exists) vs time, dither-period means (bar); the nominal
    current (mA) below.
    """
    if not ev.scores:
        return None
    name = experiment or featured_experiment(ev)
    ref = ev.references[name]
    shown = _present(ev, ("gp_base", "paper_svc_gp")) or list(ev.scores)
    fig = Figure(figsize=(8.5, 5.2), layout="constrained")
    ax, axi = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    sl = _thin(ref.time_s.size)
    ax.plot(ref.time_s[sl], ref.measured_mean_bar[sl], color="black", lw=1.6, label="measured")
    for k, v in enumerate(shown):
        p = ref.period_mean(ev.scores[v].predictions[name].mean_bar)
        ax.plot(ref.time_s[sl], p[sl], color=_color(v, k), lw=1.0, label=v)
    ax.set(ylabel="clutch pressure (bar)", title=f"Evolution of the prediction — {name} (test)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    axi.plot(ref.time_s[sl], ref.current_mA[sl], color="0.4", lw=1.0)
    axi.set(xlabel="time (s)", ylabel="current (mA)")
    axi.grid(alpha=0.3)
    return fig


def plot_pressure_vs_current(ev: Evaluation, experiment: str | None = None) -> Figure | None:
    """Clutch pressure vs nominal current on a test experiment (paper Fig. 4).

    Measured, ``physics_default``, ``physics_fitted``, ``paper_svc_gp`` and ``hybrid`` (those
    scored; every scored variant when none is), dither-period means (bar).
    """
    if not ev.scores:
        return None
    name = experiment or featured_experiment(ev)
    ref = ev.references[name]
    wanted = ("physics_default", "physics_fitted", "paper_svc_gp", "hybrid", "augmented_hybrid")
    shown = _present(ev, wanted) or list(ev.scores)
    fig = Figure(figsize=(8.5, 5.5), layout="constrained")
    ax = fig.subplots()
    sl = _thin(ref.time_s.size)
    ax.plot(ref.current_mA[sl], ref.measured_mean_bar[sl], color="black", lw=1.8, label="measured")
    for k, v in enumerate(shown):
        p = ref.period_mean(ev.scores[v].predictions[name].mean_bar)
        ax.plot(ref.current_mA[sl], p[sl], color=_color(v, k), lw=1.0, label=v)
    ax.set(
        xlabel="nominal VFS current (mA)",
        ylabel=f"clutch pressure, {signal_of(ev)} (bar)",
        title=f"Pressure vs current on the unseen test ramp — {name}",
    )
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    return fig


def _regulated_width(curve: HysteresisCurve) -> np.ndarray:
    """Width with latched bins and their neighbours blanked (NaN), bar."""
    lat = curve.latched
    near = lat.copy()
    near[1:] |= lat[:-1]
    near[:-1] |= lat[1:]
    return np.where(near, np.nan, curve.width_bar)


def _band(curves: list[HysteresisCurve]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Common current grid and the mean / min / max width over experiments (bar)."""
    lo = min(c.center_mA[0] for c in curves)
    hi = max(c.center_mA[-1] for c in curves)
    step = curves[0].center_mA[1] - curves[0].center_mA[0] if curves[0].center_mA.size > 1 else 1
    grid = np.arange(lo, hi + 0.5 * step, step)
    rows = np.full((len(curves), grid.size), np.nan)
    for r, c in enumerate(curves):
        idx = np.rint((c.center_mA - lo) / step).astype(int)
        rows[r, idx] = _regulated_width(c)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns stay NaN
        return grid, np.nanmean(rows, 0), np.nanmin(rows, 0), np.nanmax(rows, 0)


def ramps_in_summary_order(ramps: dict[str, list[str]], summary: dict) -> dict[str, list[str]]:
    """``ramps`` (label → experiment names) in the order of the dataset summary's ramps
    (fastest first, :func:`~clutchlab.data.ramps_fastest_first`); labels it does not list
    follow, alphabetically."""
    rank = {label: k for k, label in enumerate(summary.get("ramps", {}))}
    order = sorted(ramps, key=lambda label: (rank.get(label, len(rank)), label))
    return {label: ramps[label] for label in order}


def plot_hysteresis_bands(ev: Evaluation) -> Figure | None:
    """Hysteresis width vs current per ramp rate, measured and modelled (paper Fig. 5).

    One panel per source (measured, then ``physics_default``, ``physics_fitted`` and
    ``paper_svc_gp`` where scored); in each, one band per ramp label: the mean
    over that ramp's experiments (line) and their range (shaded). Width = rising minus
    falling dither-period-mean pressure in the current bins of the analysis settings (bar;
    25 mA by default); bins at the latch snap are left out (the latch currents score it).
    Training ramps of a model are in sample.
    """
    if not ev.curves:
        return None
    ramps: dict[str, list[str]] = {}
    p = ev.protocol
    names = [*p.train_names, *p.test_names]
    summary = {row["name"]: row["ramp"] for row in p.dataset_summary["table"]}
    for n in names:
        ramps.setdefault(summary.get(n, "?"), []).append(n)
    ramps = ramps_in_summary_order(ramps, p.dataset_summary)
    sources = list(ev.curves)
    ncol = 2 if len(sources) > 1 else 1
    nrow = int(np.ceil(len(sources) / ncol))
    fig = Figure(figsize=(9.0, 3.3 * nrow + 0.4), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrow, ncol, sharex=True, sharey=True, squeeze=False))
    for ax, src in zip(axes.flat, sources, strict=False):
        for k, (ramp, exps) in enumerate(ramps.items()):
            curves = [ev.curves[src][n] for n in exps if n in ev.curves[src]]
            if not curves:
                continue
            grid, mean, lo, hi = _band(curves)
            color = _RAMP_COLORS.get(ramp, f"C{k}")
            test = ramp in p.test_ramps
            label = f"{ramp} ({'test' if test else 'train'})"
            ax.plot(grid, mean, color=color, lw=1.4, ls="-" if test else "--", label=label)
            ax.fill_between(grid, lo, hi, color=color, alpha=0.18, lw=0)
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.set_title(src, fontsize=10)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(sources) :]:
        ax.set_visible(False)
    for col in range(ncol):  # the lowest drawn panel of each column carries the current axis
        drawn = [ax for ax in axes[:, col] if ax.get_visible()]
        if drawn:
            drawn[-1].xaxis.set_tick_params(labelbottom=True)
            drawn[-1].set_xlabel("nominal VFS current (mA)")
    for ax in axes[:, 0]:
        ax.set_ylabel("rising − falling (bar)")
    axes.flat[0].legend(loc="lower left", fontsize=8)
    fig.suptitle("Hysteresis bands for the ramp rates (latch snap excluded)")
    return fig


def plot_residuals(ev: Evaluation) -> Figure | None:
    """Residual (predicted − measured, dither-period mean, bar) vs time and vs current.

    One row per scored variant, every test experiment overlaid; the vertical range is the
    99.5th percentile of |residual| (latch-snap spikes beyond it are clipped).
    """
    if not ev.scores:
        return None
    variants = list(ev.scores)
    fig = Figure(figsize=(9.0, 1.9 * len(variants) + 0.6), layout="constrained")
    axes = fig.subplots(len(variants), 2, sharex="col", squeeze=False)
    refs = ev.references
    for r, v in enumerate(variants):
        all_res = []
        for name, ref in refs.items():
            res = ref.period_mean(ev.scores[v].predictions[name].mean_bar) - ref.measured_mean_bar
            all_res.append(res)
            sl = _thin(res.size)
            axes[r, 0].plot(ref.time_s[sl], res[sl], lw=0.6, color=_color(v, r), alpha=0.5)
            axes[r, 1].plot(ref.current_mA[sl], res[sl], lw=0.6, color=_color(v, r), alpha=0.5)
        lim = float(np.percentile(np.abs(np.concatenate(all_res)), 99.5)) * 1.2 or 0.1
        for ax in axes[r]:
            ax.set_ylim(-lim, lim)
            ax.axhline(0.0, color="0.3", lw=0.6)
            ax.grid(alpha=0.3)
        axes[r, 0].set_ylabel(f"{v}\nresidual (bar)", fontsize=8)
    axes[-1, 0].set_xlabel("time (s)")
    axes[-1, 1].set_xlabel("nominal VFS current (mA)")
    fig.suptitle(f"Residuals on the test experiments (predicted − measured, {signal_of(ev)})")
    return fig


def plot_uncertainty(ev: Evaluation, experiment: str | None = None) -> Figure | None:
    """Predictive mean ± 2σ (bar) vs time on a test experiment, per variant that gives σ.

    The standard deviation is predicted on the featured test experiment only
    (:attr:`Protocol.featured`).
    """
    name = experiment or (featured_experiment(ev) if ev.scores else None)
    shown = [v for v, s in ev.scores.items() if s.predictions[name].std_bar is not None]
    if not shown:
        return None
    ref = ev.references[name]
    fig = Figure(figsize=(8.5, 2.6 * len(shown) + 0.5), layout="constrained")
    axes = fig.subplots(len(shown), 1, sharex=True, squeeze=False)[:, 0]
    sl = _thin(ref.time_s.size)
    for k, (ax, v) in enumerate(zip(axes, shown, strict=True)):
        pred = ev.scores[v].predictions[name]
        mean = ref.period_mean(pred.mean_bar)
        std = ref.period_mean(pred.std_bar)
        c = _color(v, k)
        ax.fill_between(
            ref.time_s[sl],
            (mean - 2 * std)[sl],
            (mean + 2 * std)[sl],
            color=c,
            alpha=0.25,
            lw=0,
            label="±2σ",
        )
        ax.plot(ref.time_s[sl], mean[sl], color=c, lw=1.0, label=f"{v} mean")
        ax.plot(ref.time_s[sl], ref.measured_mean_bar[sl], color="black", lw=0.9, label="measured")
        inside = np.mean(np.abs(ref.measured_mean_bar - mean) <= 2 * std)
        ax.set(ylabel="pressure (bar)", title=f"{v}: {100 * inside:.1f} % of samples within ±2σ")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", fontsize=8)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(f"Predictive uncertainty on {name} (test)")
    return fig


def plot_classifier_comparison(ev: Evaluation) -> Figure | None:
    """Latch-classifier comparison (paper Fig. 2), drawn by :mod:`clutchlab.residual_ml`.

    The comparison object's ``figure()``: each classifier's decision regions in the plane of
    nominal current (mA) and dI/dt (mA/s) with its leave-one-experiment-out accuracy on the
    training experiments. None when the evaluation holds no comparison.
    """
    comp = ev.classifier_comparison
    draw = getattr(comp, "figure", None) if comp is not None else None
    return draw() if callable(draw) else None


@dataclass(frozen=True)
class FigureSpec:
    """A report figure.

    Attributes
    ----------
    key : str
        File stem (``figures/<key>.png``).
    title : str
        Heading in the report.
    caption : str
        What it shows, with units.
    figure : matplotlib.figure.Figure
        The figure.
    """

    key: str
    title: str
    caption: str
    figure: Any


def _discovery_iteration(ev: Evaluation):
    """The iteration of ``augmented_hybrid``'s discovery to show: the last one that added an
    effect, else the first (what was looked at before nothing was added)."""
    result = ev.discovery_result()
    if result is None or not result.iterations:
        return None
    added = [it for it in result.iterations if it.effect]
    return added[-1] if added else result.iterations[0]


def plot_discovery_evidence(ev: Evaluation) -> Figure | None:
    """Closing the loop: score statistic per candidate effect (``augmented_hybrid``)."""
    from .discover.report import plot_evidence

    it = _discovery_iteration(ev)
    return None if it is None or not it.candidates else plot_evidence(it)


def plot_discovery_residuals(ev: Evaluation) -> Figure | None:
    """Closing the loop: training residual vs current before / after (``augmented_hybrid``)."""
    from .discover.report import plot_residuals

    it = _discovery_iteration(ev)
    return None if it is None else plot_residuals(it)


def _classifier_comparison_missing(ev: Evaluation) -> str:
    """Why the evaluation holds no latch-classifier comparison."""
    if "classifier_comparison" in ev.failed:
        return f"the comparison failed ({ev.failed['classifier_comparison']})"
    skipped = ev.extra.get("classifier_comparison_skipped")
    if skipped:
        return f"the comparison was not run: {skipped}"
    return "clutchlab.residual_ml provides no classifier comparison in this installation"


def report_figures(ev: Evaluation) -> tuple[list[FigureSpec], dict[str, str]]:
    """Every report figure that the evaluation can draw, and why the others are missing.

    Returns
    -------
    figures : list of FigureSpec
    missing : dict
        Figure key → reason it is not drawn.
    """
    sig = signal_of(ev) if ev.scores else "dither-period mean"
    bin_mA = f"{ev.protocol.settings.bin_mA:g}"  # the bins the curves were computed in
    entries = [
        (
            "classifier_comparison",
            "Latch-classifier comparison (paper Fig. 2)",
            "Accuracy of the six latch classifiers, leave-one-experiment-out on the training "
            "experiments, and their decision regions.",
            plot_classifier_comparison,
            _classifier_comparison_missing(ev),
        ),
        (
            "prediction_vs_time",
            "Evolution of the prediction (paper Fig. 3)",
            f"Measured vs predicted clutch pressure ({sig}, bar) over time on one "
            "test experiment; nominal current (mA) below.",
            plot_prediction_vs_time,
            "no variant scored",
        ),
        (
            "pressure_vs_current",
            "Pressure vs current on the test ramp (paper Fig. 4)",
            f"Clutch pressure ({sig}, bar) vs nominal current (mA), measured and "
            "predicted, on one test experiment.",
            plot_pressure_vs_current,
            "no variant scored",
        ),
        (
            "hysteresis_bands",
            "Hysteresis bands for the ramp rates (paper Fig. 5)",
            f"Rising minus falling pressure ({sig}, bar) in {bin_mA} mA bins vs nominal "
            "current (mA); line: mean over a ramp's experiments, band: their range. Training "
            "ramps are in sample for the models; bins at the latch snap are left out.",
            plot_hysteresis_bands,
            "no variant scored",
        ),
        (
            "residuals",
            "Residuals vs time and vs current",
            f"Predicted minus measured clutch pressure ({sig}, bar) on every test "
            "experiment, per variant.",
            plot_residuals,
            "no variant scored",
        ),
        (
            "uncertainty",
            "Predictive uncertainty",
            f"Predictive mean ± 2σ ({sig}, bar) against the measurement on one "
            "test experiment, for the variants that give a standard deviation.",
            plot_uncertainty,
            "no scored variant gives a predictive standard deviation",
        ),
        (
            "discovery_evidence",
            "Closing the loop: evidence per candidate effect",
            "augmented_hybrid's discovery on the training experiments: score statistic of "
            "each library effect against the fitted physics (log scale; dashed: significance "
            "threshold; green: added, orange: significant). The test ramp is not used.",
            plot_discovery_evidence,
            "the discovery scored no candidate",
        ),
        (
            "discovery_residuals",
            "Closing the loop: residual before / after",
            "Physics residual (model − measured, dither-period mean, bar) vs nominal current "
            "on the training experiments, before and after the discovery's iteration (the "
            "test-ramp errors of physics_fitted, hybrid and augmented_hybrid are in the "
            "table above).",
            plot_discovery_residuals,
            "the discovery ran no iteration",
        ),
    ]
    if ev.discovery_result() is None:  # no augmented_hybrid: nothing to miss
        entries = [e for e in entries if not e[0].startswith("discovery_")]
    figures, missing = [], {}
    for key, title, caption, fn, why in entries:
        fig = fn(ev)
        if fig is None:
            missing[key] = why
        else:
            figures.append(FigureSpec(key, title, caption, fig))
    return figures, missing
