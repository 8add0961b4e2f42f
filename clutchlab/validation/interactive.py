"""Interactive (Plotly) figures of the HTML reports: zoomable, hoverable, variants toggled.

Each ``iplot_*`` function takes an :class:`~clutchlab.validation.evaluate.Evaluation` and
returns a :class:`plotly.graph_objects.Figure`, or None when the evaluation lacks what it
draws — the same figures as the static PNGs of :mod:`~clutchlab.validation.figures` (which
stay for ``report.md``). Every variant is one legend group: a click on its legend entry hides
or shows it in every panel of the figure; a double click shows it alone.

The page carries plotly.js once (:func:`plotlyjs_script`, inline, so ``report.html`` stays one
self-contained file that works offline) and each figure as a ``<div>`` with its data and a
call to ``Plotly.newPlot`` (:func:`figure_div`). Every line is thinned to at most
:data:`MAX_POINTS` points and its values are stored as float32, which keeps a report of a
few megabytes (plotly.js itself is about 4.8 MB).
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .._plotly import (
    MAX_POINTS,
    PLOTLY_CONFIG,
    figure_div,
    minmax_indices,
    plotlyjs_script,
    thin,
)
from .._plotly import f32 as _f32
from .figures import (
    VARIANT_COLORS,
    _band,
    featured_experiment,
    ramps_in_summary_order,
    signal_of,
)

if TYPE_CHECKING:
    import plotly.graph_objects as go

    from .evaluate import Evaluation

__all__ = [
    "MAX_POINTS",
    "PLOTLY_CONFIG",
    "RESIDUAL_MIN_POINTS",
    "RESIDUAL_PANEL_POINTS",
    "figure_div",
    "interactive_figures",
    "iplot_hysteresis_bands",
    "iplot_prediction_vs_time",
    "iplot_pressure_vs_current",
    "iplot_residuals",
    "iplot_uncertainty",
    "plotlyjs_script",
    "thin",
]

#: Most points of one residual panel (a variant, vs time or vs current), over all lines.
RESIDUAL_PANEL_POINTS = 6000

#: Fewest points per line of the residual figure, however many test experiments.
RESIDUAL_MIN_POINTS = 400

# Default plotly colours, for variants without a fixed one.
_CYCLE = (
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
)
_DASHES = ("solid", "dash", "dot", "dashdot", "longdash", "longdashdot")


def _go() -> Any:
    import plotly.graph_objects as go

    return go


def _subplots(**kw: Any) -> go.Figure:
    from plotly.subplots import make_subplots

    return make_subplots(**kw)


def _color(name: str, k: int = 0) -> str:
    c = VARIANT_COLORS.get(name, _CYCLE[k % len(_CYCLE)])
    return "#000000" if c == "black" else c


def _rgba(hex_color: str, alpha: float) -> str:
    h = hex_color.lstrip("#")
    r, g, b = (int(h[i : i + 2], 16) for i in (0, 2, 4))
    return f"rgba({r},{g},{b},{alpha})"


def _layout(fig: go.Figure, title: str, height: int) -> go.Figure:
    fig.update_layout(
        title={"text": title, "x": 0.01, "xanchor": "left", "font": {"size": 15}},
        height=height,
        template="plotly_white",
        hovermode="closest",
        legend={"groupclick": "togglegroup", "tracegroupgap": 2},
        margin={"l": 70, "r": 20, "t": 60, "b": 50},
    )
    return fig


def iplot_prediction_vs_time(ev: Evaluation, experiment: str | None = None) -> go.Figure | None:
    """Measured and predicted clutch pressure vs time on a test experiment (paper Fig. 3).

    Every scored variant is drawn (``gp_base`` and ``paper_svc_gp`` shown at first, the others
    one legend click away; all shown when neither is scored), dither-period means (bar); the
    nominal current (mA) below.

    Parameters
    ----------
    ev : Evaluation
        The scored variants.
    experiment : str, optional
        Test experiment; :attr:`Protocol.featured` by default.

    Returns
    -------
    plotly.graph_objects.Figure or None
        None when no variant is scored.
    """
    if not ev.scores:
        return None
    go = _go()
    name = experiment or featured_experiment(ev)
    ref = ev.references[name]
    first = [v for v in ("gp_base", "paper_svc_gp") if v in ev.scores] or list(ev.scores)
    fig = _subplots(
        rows=2, cols=1, shared_xaxes=True, row_heights=[0.72, 0.28], vertical_spacing=0.05
    )
    sl = thin(ref.time_s.size)
    t = _f32(ref.time_s, sl)
    hover = "t %{x:.4g} s<br>%{y:.4g} bar<extra>%{fullData.name}</extra>"
    fig.add_trace(
        go.Scatter(
            x=t,
            y=_f32(ref.measured_mean_bar, sl),
            name="measured",
            legendgroup="measured",
            line={"color": "#000000", "width": 2},
            hovertemplate=hover,
        ),
        row=1,
        col=1,
    )
    for k, v in enumerate(ev.scores):
        p = ref.period_mean(ev.scores[v].predictions[name].mean_bar)
        fig.add_trace(
            go.Scatter(
                x=t,
                y=_f32(p, sl),
                name=v,
                legendgroup=v,
                line={"color": _color(v, k), "width": 1.2},
                visible=True if v in first else "legendonly",
                hovertemplate=hover,
            ),
            row=1,
            col=1,
        )
    fig.add_trace(
        go.Scatter(
            x=t,
            y=_f32(ref.current_mA, sl),
            name="nominal current",
            line={"color": "#666666", "width": 1},
            hovertemplate="t %{x:.4g} s<br>%{y:.4g} mA<extra></extra>",
        ),
        row=2,
        col=1,
    )
    fig.update_yaxes(title_text="clutch pressure (bar)", row=1, col=1)
    fig.update_yaxes(title_text="current (mA)", row=2, col=1)
    fig.update_xaxes(title_text="time (s)", row=2, col=1)
    return _layout(fig, f"Evolution of the prediction — {name} (test)", 560)


def iplot_pressure_vs_current(ev: Evaluation, experiment: str | None = None) -> go.Figure | None:
    """Clutch pressure vs nominal current on a test experiment (paper Fig. 4).

    Measured and every scored variant, dither-period means (bar); ``physics_default``,
    ``physics_fitted``, ``paper_svc_gp``, ``hybrid`` and ``augmented_hybrid`` are shown at
    first (every variant when none of them is scored), the others one legend click away.

    Parameters
    ----------
    ev : Evaluation
        The scored variants.
    experiment : str, optional
        Test experiment; :attr:`Protocol.featured` by default.

    Returns
    -------
    plotly.graph_objects.Figure or None
        None when no variant is scored.
    """
    if not ev.scores:
        return None
    go = _go()
    name = experiment or featured_experiment(ev)
    ref = ev.references[name]
    wanted = ("physics_default", "physics_fitted", "paper_svc_gp", "hybrid", "augmented_hybrid")
    first = [v for v in wanted if v in ev.scores] or list(ev.scores)
    sl = thin(ref.time_s.size)
    i = _f32(ref.current_mA, sl)
    t = _f32(ref.time_s, sl)
    hover = "%{x:.4g} mA<br>%{y:.4g} bar<br>t %{customdata:.4g} s<extra>%{fullData.name}</extra>"
    fig = go.Figure()
    fig.add_trace(
        go.Scatter(
            x=i,
            y=_f32(ref.measured_mean_bar, sl),
            customdata=t,
            name="measured",
            legendgroup="measured",
            line={"color": "#000000", "width": 2},
            hovertemplate=hover,
        )
    )
    for k, v in enumerate(ev.scores):
        p = ref.period_mean(ev.scores[v].predictions[name].mean_bar)
        fig.add_trace(
            go.Scatter(
                x=i,
                y=_f32(p, sl),
                customdata=t,
                name=v,
                legendgroup=v,
                line={"color": _color(v, k), "width": 1.2},
                visible=True if v in first else "legendonly",
                hovertemplate=hover,
            )
        )
    fig.update_xaxes(title_text="nominal VFS current (mA)")
    fig.update_yaxes(title_text=f"clutch pressure, {signal_of(ev)} (bar)")
    return _layout(fig, f"Pressure vs current on the unseen test ramp — {name}", 520)


def _ramps(ev: Evaluation) -> dict[str, list[str]]:
    p = ev.protocol
    summary = {row["name"]: row["ramp"] for row in p.dataset_summary["table"]}
    ramps: dict[str, list[str]] = {}
    for n in [*p.train_names, *p.test_names]:
        ramps.setdefault(summary.get(n, "?"), []).append(n)
    return ramps_in_summary_order(ramps, p.dataset_summary)


def iplot_hysteresis_bands(ev: Evaluation) -> go.Figure | None:
    """Hysteresis width vs current, one panel per ramp rate, one band per source (paper Fig. 5).

    In each panel (ramp label, test or train), measured and every model of
    :attr:`Evaluation.curves`: the mean over that ramp's experiments (line) and their range
    (shaded). Width = rising minus falling dither-period-mean pressure in 25 mA bins (bar);
    bins at the latch snap are left out. A source is one legend group across the panels.

    Parameters
    ----------
    ev : Evaluation
        The scored variants with their hysteresis curves.

    Returns
    -------
    plotly.graph_objects.Figure or None
        None when the evaluation holds no curves.
    """
    if not ev.curves:
        return None
    go = _go()
    ramps = _ramps(ev)
    test = set(ev.protocol.test_ramps)
    titles = [f"{r} ({'test' if r in test else 'train — in sample'})" for r in ramps]
    ncol = min(3, len(ramps))
    nrow = -(-len(ramps) // ncol)
    fig = _subplots(
        rows=nrow,
        cols=ncol,
        shared_xaxes=True,
        shared_yaxes=True,
        subplot_titles=titles,
        horizontal_spacing=0.04,
        vertical_spacing=0.12,
    )
    hover = "%{x:.4g} mA<br>%{y:.3g} bar<extra>%{fullData.name}</extra>"
    legend_done: set[str] = set()
    for j, exps in enumerate(ramps.values()):
        row, col = j // ncol + 1, j % ncol + 1
        for k, src in enumerate(ev.curves):
            curves = [ev.curves[src][n] for n in exps if n in ev.curves[src]]
            if not curves:
                continue
            grid, mean, lo, hi = _band(curves)
            c = _color(src, k)
            ok = np.isfinite(mean)
            g32 = _f32(grid[ok])
            kw = {"legendgroup": src, "hoverinfo": "skip", "showlegend": False}
            fig.add_trace(
                go.Scatter(x=g32, y=_f32(lo[ok]), mode="lines", line={"width": 0}, **kw),
                row=row,
                col=col,
            )
            fig.add_trace(
                go.Scatter(
                    x=g32,
                    y=_f32(hi[ok]),
                    mode="lines",
                    line={"width": 0},
                    fill="tonexty",
                    fillcolor=_rgba(c, 0.18),
                    **kw,
                ),
                row=row,
                col=col,
            )
            fig.add_trace(
                go.Scatter(
                    x=g32,
                    y=_f32(mean[ok]),
                    mode="lines",
                    name=src,
                    legendgroup=src,
                    showlegend=src not in legend_done,
                    line={"color": c, "width": 2 if src == "measured" else 1.4},
                    hovertemplate=hover,
                ),
                row=row,
                col=col,
            )
            legend_done.add(src)
        fig.add_hline(y=0.0, line={"color": "#888888", "width": 0.8}, row=row, col=col)
    fig.update_xaxes(title_text="nominal VFS current (mA)", row=nrow)
    fig.update_yaxes(title_text="rising − falling (bar)", col=1)
    return _layout(
        fig, "Hysteresis bands for the ramp rates (latch snap excluded)", 330 * nrow + 130
    )


def iplot_residuals(ev: Evaluation) -> go.Figure | None:
    """Residual (predicted − measured, dither-period mean, bar) vs time and vs current.

    One row per scored variant, every test experiment overlaid (dash style per experiment);
    a variant is one legend group over both columns. Each line keeps the minimum and maximum
    of every stretch of samples (:func:`clutchlab._plotly.minmax_indices`), at most
    :data:`RESIDUAL_PANEL_POINTS` points per panel over the experiments (at least
    :data:`RESIDUAL_MIN_POINTS` per line).

    Parameters
    ----------
    ev : Evaluation
        The scored variants.

    Returns
    -------
    plotly.graph_objects.Figure or None
        None when no variant is scored.
    """
    if not ev.scores:
        return None
    go = _go()
    variants = list(ev.scores)
    fig = _subplots(
        rows=len(variants),
        cols=2,
        shared_xaxes="columns",
        horizontal_spacing=0.07,
        vertical_spacing=min(0.08, 0.3 / max(1, len(variants))),
    )
    refs = ev.references
    # Many test experiments × variants × 2 panels: a budget per panel keeps the page small;
    # min / max thinning keeps the latch-snap spikes.
    per_line = max(RESIDUAL_MIN_POINTS, min(MAX_POINTS, RESIDUAL_PANEL_POINTS // len(refs)))
    for r, v in enumerate(variants, start=1):
        c = _color(v, r - 1)
        all_res = []
        for e, (name, ref) in enumerate(refs.items()):
            res = ref.period_mean(ev.scores[v].predictions[name].mean_bar) - ref.measured_mean_bar
            all_res.append(res)
            sl = minmax_indices(res, per_line)
            line = {"color": c, "width": 1, "dash": _DASHES[e % len(_DASHES)]}
            for col, x, unit in ((1, ref.time_s, "s"), (2, ref.current_mA, "mA")):
                fig.add_trace(
                    go.Scatter(
                        x=_f32(x, sl),
                        y=_f32(res, sl),
                        mode="lines",
                        name=v,
                        legendgroup=v,
                        showlegend=e == 0 and col == 1,
                        line=line,
                        hovertemplate=f"{html.escape(name)}<br>%{{x:.4g}} {unit}<br>"
                        "%{y:.3g} bar<extra>%{fullData.name}</extra>",
                    ),
                    row=r,
                    col=col,
                )
        lim = float(np.nanpercentile(np.abs(np.concatenate(all_res)), 99.5)) * 1.2 or 0.1
        for col in (1, 2):
            fig.update_yaxes(range=[-lim, lim], row=r, col=col)
            fig.add_hline(y=0.0, line={"color": "#555555", "width": 0.8}, row=r, col=col)
        fig.update_yaxes(title_text=f"{v} (bar)", title_font={"size": 11}, row=r, col=1)
    fig.update_xaxes(title_text="time (s)", row=len(variants), col=1)
    fig.update_xaxes(title_text="nominal VFS current (mA)", row=len(variants), col=2)
    return _layout(
        fig,
        f"Residuals on the test experiments (predicted − measured, {signal_of(ev)})",
        190 * len(variants) + 140,
    )


def iplot_uncertainty(ev: Evaluation, experiment: str | None = None) -> go.Figure | None:
    """Predictive mean ± 2σ (bar) vs time on a test experiment, per variant that gives σ.

    Parameters
    ----------
    ev : Evaluation
        The scored variants.
    experiment : str, optional
        Test experiment; :attr:`Protocol.featured` by default (the only one with σ).

    Returns
    -------
    plotly.graph_objects.Figure or None
        None when no scored variant gives a standard deviation.
    """
    name = experiment or (featured_experiment(ev) if ev.scores else None)
    shown = [v for v, s in ev.scores.items() if s.predictions[name].std_bar is not None]
    if not shown:
        return None
    go = _go()
    ref = ev.references[name]
    sl = thin(ref.time_s.size)
    t = _f32(ref.time_s, sl)
    fig = go.Figure()
    fig.add_trace(
        go.Scatter(
            x=t,
            y=_f32(ref.measured_mean_bar, sl),
            name="measured",
            legendgroup="measured",
            line={"color": "#000000", "width": 1.5},
            hovertemplate="t %{x:.4g} s<br>%{y:.4g} bar<extra>measured</extra>",
        )
    )
    for k, v in enumerate(shown):
        pred = ev.scores[v].predictions[name]
        mean = ref.period_mean(pred.mean_bar)
        std = ref.period_mean(pred.std_bar)
        c = _color(v, k)
        kw = {"legendgroup": v, "hoverinfo": "skip", "showlegend": False, "mode": "lines"}
        fig.add_trace(go.Scatter(x=t, y=_f32(mean - 2 * std, sl), line={"width": 0}, **kw))
        fig.add_trace(
            go.Scatter(
                x=t,
                y=_f32(mean + 2 * std, sl),
                line={"width": 0},
                fill="tonexty",
                fillcolor=_rgba(c, 0.25),
                **kw,
            )
        )
        inside = float(np.mean(np.abs(ref.measured_mean_bar - mean) <= 2 * std))
        fig.add_trace(
            go.Scatter(
                x=t,
                y=_f32(mean, sl),
                customdata=_f32(2 * std, sl),
                name=f"{v} ± 2σ ({100 * inside:.1f} % inside)",
                legendgroup=v,
                line={"color": c, "width": 1.2},
                hovertemplate="t %{x:.4g} s<br>%{y:.4g} ± %{customdata:.3g} bar"
                f"<extra>{html.escape(v)}</extra>",
            )
        )
    fig.update_xaxes(title_text="time (s)")
    fig.update_yaxes(title_text="clutch pressure (bar)")
    return _layout(fig, f"Predictive uncertainty on {name} (test)", 480)


_BUILDERS = {
    "prediction_vs_time": iplot_prediction_vs_time,
    "pressure_vs_current": iplot_pressure_vs_current,
    "hysteresis_bands": iplot_hysteresis_bands,
    "residuals": iplot_residuals,
    "uncertainty": iplot_uncertainty,
}


def interactive_figures(ev: Evaluation, keys: Sequence[str] | None = None) -> dict[str, Any]:
    """The interactive figures the evaluation can draw, by the key of the static figure.

    Parameters
    ----------
    ev : Evaluation
        The scored variants.
    keys : sequence of str, optional
        Figure keys wanted (default: every one with an interactive form: prediction_vs_time,
        pressure_vs_current, hysteresis_bands, residuals, uncertainty).

    Returns
    -------
    dict
        Figure key → :class:`plotly.graph_objects.Figure`; keys it cannot draw are absent
        (the report shows the static PNG for those, e.g. the classifier comparison).
    """
    out = {}
    for key, build in _BUILDERS.items():
        if keys is not None and key not in keys:
            continue
        fig = build(ev)
        if fig is not None:
            out[key] = fig
    return out
