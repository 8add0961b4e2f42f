"""Interactive (Plotly) figures of a sweep and the self-contained page ``sweep.html``.

The same figures as the PNGs of :mod:`~clutchlab.physics.design.figures` — the tornado chart
and every metric against every design variable — zoomable, with each point's id, variables
and metric under the mouse; finished and failed points are two legend groups (a click hides
or shows them in every panel). plotly.js is embedded once, inline, so the page works offline.
plotly is imported on use: sweep workers import this package.
"""

from __future__ import annotations

import html
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from ..._plotly import MARKER_SCRIPT, f32, figure_div, plotlyjs_script, thin
from .evaluate import STATUS_FAILED, STATUS_OK
from .figures import _metrics, metric_unit
from .sensitivity import sensitivity_table, tornado_labels
from .spec import SweepSpec

if TYPE_CHECKING:
    import plotly.graph_objects as go

__all__ = ["iplot_metrics_vs_variables", "iplot_tornado", "sweep_html"]

_POS, _NEG, _OK, _FAILED = "#d62728", "#1f77b4", "#1f77b4", "#d62728"


def iplot_tornado(table: pd.DataFrame, spec: SweepSpec) -> go.Figure:
    """Tornado chart: per metric, the change over each variable's range, largest on top.

    Parameters
    ----------
    table : pandas.DataFrame
        Sweep results.
    spec : SweepSpec
        The sweep's spec.

    Returns
    -------
    plotly.graph_objects.Figure
        One panel per metric; bars are the linear effects of :func:`sensitivity_table`
        (metric unit, variable low → high; red increases, blue decreases the metric), R² and
        the standardized coefficient under the mouse.
    """
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    metrics = _metrics(spec)
    sens = sensitivity_table(table, spec, metrics)
    ncols = min(3, len(metrics))
    nrows = -(-len(metrics) // ncols)
    titles = []
    for name in metrics:
        s = sens[sens["metric"] == name]
        r2 = s["r2"].iloc[0] if len(s) else np.nan
        n = int(s["n"].iloc[0]) if len(s) else 0
        titles.append(f"{name} (R² {r2:.2f}, n {n})" if np.isfinite(r2) else f"{name} (n {n})")
    height = max(140, 26 * len(spec.variables) + 90)  # px per row of panels
    total = height * nrows + 90
    fig = make_subplots(
        rows=nrows,
        cols=ncols,
        subplot_titles=titles,
        horizontal_spacing=0.16,
        vertical_spacing=min(0.3, 90 / total) if nrows > 1 else 0.0,
    )
    for k, name in enumerate(metrics):
        s = sens[sens["metric"] == name].copy()
        s["mag"] = s["effect"].abs().fillna(-1.0)
        s = s.sort_values("mag")
        effect = s["effect"].to_numpy(dtype=float)
        labels, message = tornado_labels(s)
        unit = html.escape(metric_unit(name))
        fig.add_trace(
            go.Bar(
                x=np.nan_to_num(effect),
                y=labels,
                orientation="h",
                marker_color=[_POS if e > 0 else _NEG for e in np.nan_to_num(effect)],
                customdata=np.c_[s["std_coef"].to_numpy(dtype=float), effect],
                name=name,
                showlegend=False,
                hovertemplate=f"%{{y}}: %{{customdata[1]:.4g}} {unit} low → high"
                "<br>standardized %{customdata[0]:.3g}<extra>" + html.escape(name) + "</extra>",
            ),
            row=k // ncols + 1,
            col=k % ncols + 1,
        )
        if message:
            fig.add_annotation(
                text=message,
                x=0.5,
                y=0.5,
                xref=f"x{k + 1 if k else ''} domain",
                yref=f"y{k + 1 if k else ''} domain",
                showarrow=False,
            )
        fig.update_xaxes(
            title_text=f"change low → high ({metric_unit(name)})",
            title_font={"size": 10},
            row=k // ncols + 1,
            col=k % ncols + 1,
        )
    fig.update_layout(
        title={"text": f"{spec.name}: sensitivity (linear effect over each variable's range)"},
        height=total,
        template="plotly_white",
        margin={"l": 20, "r": 20, "t": 80, "b": 40},
    )
    fig.update_annotations(font_size=11)
    return fig


def iplot_metrics_vs_variables(table: pd.DataFrame, spec: SweepSpec) -> go.Figure:
    """Every metric against every design variable; failed points marked.

    Parameters
    ----------
    table : pandas.DataFrame
        Sweep results.
    spec : SweepSpec
        The sweep's spec.

    Returns
    -------
    plotly.graph_objects.Figure
        Rows: metrics; columns: variables (log axes for log variables). Finished points are
        one legend group, failed points (red crosses at the bottom of each panel, their error
        under the mouse) another. Panels with more than ``clutchlab._plotly.MAX_POINTS``
        points show every k-th point.
    """
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    metrics = _metrics(spec)
    variables = spec.variables or ()
    ncols = max(len(variables), 1)
    ok = table[table["status"] == STATUS_OK]
    failed = table[table["status"] == STATUS_FAILED]
    fig = make_subplots(
        rows=len(metrics),
        cols=ncols,
        shared_xaxes="columns",
        horizontal_spacing=min(0.06, 0.3 / ncols),
        vertical_spacing=min(0.04, 0.3 / max(len(metrics), 1)),
    )
    sl, slf = thin(len(ok)), thin(len(failed))
    ids = ok["point_id"].astype(str).to_numpy()[sl] if "point_id" in ok else None
    fids = failed["point_id"].astype(str).to_numpy()[slf] if "point_id" in failed else None
    errors = (
        failed["error"].astype(str).str.slice(0, 160).to_numpy()[slf]
        if "error" in failed
        else np.array([""] * len(failed))[slf]
    )
    for r, name in enumerate(metrics, start=1):
        y = ok[name].to_numpy(dtype=float)
        lo = float(np.nanmin(y)) if np.isfinite(y).any() else 0.0
        unit = html.escape(metric_unit(name))
        for c, v in enumerate(variables, start=1):
            vunit = html.escape(v.unit)
            fig.add_trace(
                go.Scatter(
                    x=f32(ok[v.name], sl),
                    y=f32(y, sl),
                    mode="markers",
                    marker={"size": 5 if len(ok) < 500 else 3, "color": _OK, "opacity": 0.6},
                    name=f"finished ({len(ok)})",
                    legendgroup="ok",
                    showlegend=r == 1 and c == 1,
                    text=ids,
                    hovertemplate=f"%{{x:.4g}} {vunit}<br>%{{y:.4g}} {unit}<br>"
                    "point %{text}<extra></extra>",
                ),
                row=r,
                col=c,
            )
            if len(failed):
                fig.add_trace(
                    go.Scatter(
                        x=f32(failed[v.name], slf),
                        y=np.full(len(errors), lo, dtype=np.float32),
                        mode="markers",
                        marker={"symbol": "x", "size": 8, "color": _FAILED},
                        name=f"failed ({len(failed)})",
                        legendgroup="failed",
                        showlegend=r == 1 and c == 1,
                        text=fids,
                        customdata=errors,
                        hovertemplate=f"%{{x:.4g}} {vunit}<br>point %{{text}} failed:"
                        "<br>%{customdata}<extra></extra>",
                    ),
                    row=r,
                    col=c,
                )
            if v.scale == "log":
                fig.update_xaxes(type="log", row=r, col=c)
            if r == len(metrics):
                fig.update_xaxes(
                    title_text=f"{v.name} ({v.unit})", title_font={"size": 10}, row=r, col=c
                )
        fig.update_yaxes(
            title_text=f"{name} ({metric_unit(name)})", title_font={"size": 9}, row=r, col=1
        )
    fig.update_layout(
        title={
            "text": f"{spec.name}: metrics vs design variables ({len(ok)} ok, {len(failed)} failed)"
        },
        height=170 * len(metrics) + 140,
        template="plotly_white",
        hovermode="closest",
        margin={"l": 90, "r": 20, "t": 80, "b": 50},
    )
    return fig


def sweep_html(table: pd.DataFrame, spec: SweepSpec) -> str:
    """The self-contained page of a sweep: the tornado chart and the metric scatter plots.

    Parameters
    ----------
    table : pandas.DataFrame
        Sweep results.
    spec : SweepSpec
        The sweep's spec.

    Returns
    -------
    str
        HTML with plotly.js inline (once) and the figure marker of
        :mod:`clutchlab.validation.render`.
    """
    n_ok = int((table["status"] == STATUS_OK).sum())
    n_failed = int((table["status"] == STATUS_FAILED).sum())
    title = html.escape(f"clutchlab sweep {spec.name}")
    return "\n".join(
        [
            "<!doctype html><html lang='en'><head><meta charset='utf-8'>",
            f"<title>{title}</title>",
            "<style>body{font-family:system-ui,sans-serif;max-width:1400px;margin:1.5em auto;"
            "padding:0 1em;color:#222} .plotly-graph-div{border:1px solid #ddd;margin:1em 0}"
            " .note{font-size:.85em;color:#555}</style>",
            plotlyjs_script(),
            "</head><body>",
            f"<h1>{title}</h1>",
            f"<p>{len(table)} points: {n_ok} finished, {n_failed} failed; variables "
            f"{html.escape(', '.join(v.name for v in spec.variables))}.</p>",
            "<p class='note'>Drag to zoom, double-click to reset, hover for a point's id and "
            "values; click a legend entry to hide or show finished or failed points.</p>",
            figure_div(iplot_tornado(table, spec), "plot-tornado"),
            figure_div(iplot_metrics_vs_variables(table, spec), "plot-metrics_vs_variables"),
            MARKER_SCRIPT,
            "</body></html>",
        ]
    )
