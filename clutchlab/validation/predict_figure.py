"""The figure of one experiment's prediction (``clutchlab predict``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

from ..data import dither_period_mean
from .averaging import scored_signal
from .figures import VARIANT_COLORS

if TYPE_CHECKING:
    from .predict import ExperimentPrediction

__all__ = ["prediction_figure"]

#: Most points drawn per line (a 166 s log at 1 kHz is thinned to this).
_MAX_POINTS = 6000


def prediction_figure(p: ExperimentPrediction) -> Figure:
    """Measured and predicted clutch pressure of one experiment: against time (with the
    residual, and ±2σ when the prediction has a std) and against the nominal current.

    Parameters
    ----------
    p : ExperimentPrediction
        From :func:`~clutchlab.validation.predict.predict_traces`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig = Figure(figsize=(11, 6.5), layout="constrained")
    grid = fig.add_gridspec(2, 2, height_ratios=(3, 1.3), width_ratios=(1.6, 1))
    ax_t = fig.add_subplot(grid[0, 0])
    ax_r = fig.add_subplot(grid[1, 0], sharex=ax_t)
    ax_i = fig.add_subplot(grid[:, 1])
    k = slice(None, None, max(1, p.time_s.size // _MAX_POINTS))
    t, measured, predicted = p.time_s[k], p.measured_bar[k], p.predicted_bar[k]
    pred_color = VARIANT_COLORS["paper_svc_gp"]
    ax_t.plot(t, predicted, color=pred_color, lw=1.4, alpha=0.8, label="predicted")
    ax_t.plot(t, measured, color=VARIANT_COLORS["measured"], lw=0.6, label="measured")
    if p.std_bar is not None:
        s = 2.0 * p.std_bar[k]
        ax_t.fill_between(t, predicted - s, predicted + s, color=pred_color, alpha=0.2, lw=0,
                          label="±2σ")  # fmt: skip
    ax_t.set_ylabel("clutch pressure (bar)")
    ax_t.legend(loc="upper left", fontsize=8)
    residual = p.predicted_bar - p.measured_bar
    signal = scored_signal({p.name: p.averaging} if p.averaging else None)
    ax_r.plot(t, residual[k], color="0.75", lw=0.5, label="samples")
    if np.isfinite(residual).all() and p.period_samples > 1:
        mean = dither_period_mean(residual, p.period_samples)[k]
        ax_r.plot(t, mean, color="tab:red", lw=0.8, label=signal)
        ax_r.legend(loc="upper left", fontsize=7)
    ax_r.axhline(0.0, color="grey", lw=0.5)
    ax_r.set_xlabel("time (s)")
    ax_r.set_ylabel("predicted − measured (bar)")
    ax_i.plot(p.current_mA[k], predicted, color=pred_color, lw=1.2, alpha=0.8, label="predicted")
    ax_i.plot(p.current_mA[k], measured, color=VARIANT_COLORS["measured"], lw=0.5,
              label="measured")  # fmt: skip
    ax_i.set_xlabel("nominal current (mA)")
    ax_i.set_ylabel("clutch pressure (bar)")
    ax_i.legend(loc="upper left", fontsize=8)
    m = p.metrics
    title = (
        f"{p.name}" + (f" ({p.ramp})" if p.ramp else "") + f": RMSE {m['rmse_bar']:.4f} bar, "
        f"fit {m['fit_pct']:.1f} %, {signal}"
    )
    if p.trained:
        title += " — a training experiment: in-sample"
    fig.suptitle(title, fontsize=10)
    if not np.isfinite(p.predicted_bar).all():
        ax_t.text(0.5, 0.5, "the prediction is not finite everywhere", transform=ax_t.transAxes,
                  ha="center", color="tab:red")  # fmt: skip
    return fig
