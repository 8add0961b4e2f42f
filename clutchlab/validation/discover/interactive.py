"""Interactive (Plotly) figures of a discovery, for its ``report.html``.

The same figures as the PNGs of :mod:`~clutchlab.validation.discover.report` (which stay for
``report.md``): residual before / after an iteration, the evidence per candidate effect, and
the residual diagnostics — zoomable, values under the mouse. In the residual figure every
experiment is one legend group (a click hides or shows it in every panel). plotly is
imported on use; the page embeds plotly.js once (:func:`clutchlab._plotly.plotlyjs_script`).
"""

from __future__ import annotations

import html
import textwrap
from typing import TYPE_CHECKING, Any

import numpy as np

from ..._plotly import f32, thin
from .result import IterationRecord

if TYPE_CHECKING:
    import plotly.graph_objects as go

__all__ = ["iplot_diagnostics", "iplot_evidence", "iplot_residuals"]

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


def _layout(fig: Any, title: str, height: int, title_lines: int = 1) -> Any:
    extra = 18 * (title_lines - 1)  # room for a title wrapped over several lines
    fig.update_layout(
        title={"text": title, "x": 0.01, "xanchor": "left", "font": {"size": 14}},
        height=height + extra,
        template="plotly_white",
        hovermode="closest",
        legend={"groupclick": "togglegroup"},
        margin={"l": 70, "r": 20, "t": 70 + extra, "b": 50},
    )
    return fig


def iplot_residuals(it: IterationRecord) -> go.Figure:
    """Residual (model − measured, dither-period mean, bar) vs nominal current (mA),
    before and after the iteration, on the training and the test experiments.

    Parameters
    ----------
    it : IterationRecord
        One iteration of the loop.

    Returns
    -------
    plotly.graph_objects.Figure
        2 × 2 panels (training / test × before / after); one legend group per experiment.
    """
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    after = f"after (+ {it.effect})" if it.effect else "after (no effect added)"
    with_test = bool(it.before.test_residual)  # no test experiments: no empty test row
    titles = []
    for row in ("training", "unseen test ramp")[: 2 if with_test else 1]:
        for state, when in ((it.before, "before"), (it.after, after)):
            rmse = (state.train if row == "training" else state.test)["rmse_bar"]
            titles.append(f"{row}, {when}: RMSE {rmse:.4f} bar")
    fig = make_subplots(
        rows=2 if with_test else 1,
        cols=2,
        shared_xaxes=True,
        shared_yaxes="rows",
        subplot_titles=titles,
        horizontal_spacing=0.05,
        vertical_spacing=0.1,
    )
    colors: dict[str, str] = {}
    shown: set[str] = set()

    def add(name: str, cur: Any, r: Any, row: int, col: int, mode: str) -> None:
        c = colors.setdefault(name, _CYCLE[len(colors) % len(_CYCLE)])
        sl = thin(len(cur))
        style = {"marker": {"size": 3, "color": c, "opacity": 0.6}}
        if mode == "lines":
            style = {"line": {"color": c, "width": 1}}
        fig.add_trace(
            go.Scatter(
                x=f32(cur, sl),
                y=f32(r, sl),
                mode=mode,
                name=name,
                legendgroup=name,
                showlegend=name not in shown,
                hovertemplate="%{x:.4g} mA<br>%{y:.3g} bar<extra>%{fullData.name}</extra>",
                **style,
            ),
            row=row,
            col=col,
        )
        shown.add(name)

    for col, state in enumerate((it.before, it.after), start=1):
        res = state.residual
        for name, (a, b) in zip(res.experiments, res.slices, strict=True):
            keep = np.asarray(res.keep[a:b], dtype=bool)
            cur = np.asarray(res.signals["current_mA"][a:b])[keep]
            add(name, cur, np.asarray(res.r[a:b])[keep], 1, col, "markers")
        for name, (cur, r) in state.test_residual.items():
            add(name, cur, r, 2, col, "lines")
    rows = (1, 2) if with_test else (1,)
    for row in rows:
        for col in (1, 2):
            fig.add_hline(y=0.0, line={"color": "#000000", "width": 0.7}, row=row, col=col)
    fig.update_xaxes(title_text="nominal VFS current (mA)", row=rows[-1])
    fig.update_yaxes(title_text="residual, training (bar)", row=1, col=1)
    if with_test:
        fig.update_yaxes(title_text="residual, unseen test ramp (bar)", row=2, col=1)
    return _layout(
        fig,
        f"Iteration {it.index}: residual (model − measured, dither-period mean) before / after",
        700 if with_test else 400,
    )


def iplot_evidence(it: IterationRecord, min_share: float | None = None) -> go.Figure:
    """Score statistic of every candidate (log scale) against the significance threshold.

    Parameters
    ----------
    it : IterationRecord
        One iteration of the loop.
    min_share : float, optional
        Share of the residual (0–1) a significant candidate must explain
        (``DiscoverySettings.min_share``), stated on the axis.

    Returns
    -------
    plotly.graph_objects.Figure
        One bar per candidate (green: added, orange: significant, grey: not), its share,
        p-value and novelty under the mouse; dashed lines: thresholds per degrees of freedom.
    """
    import plotly.graph_objects as go
    from scipy.stats import chi2

    cands = it.candidates[::-1]
    colors = [
        "#2ca02c" if c.effect == it.effect else ("#ff7f0e" if c.significant else "#7f7f7f")
        for c in cands
    ]
    fig = go.Figure(
        go.Bar(
            x=[max(c.statistic, 1e-2) for c in cands],
            y=[c.effect for c in cands],
            orientation="h",
            marker_color=colors,
            customdata=[[c.share, c.p_value, c.novelty, c.status] for c in cands],
            text=[f"{c.statistic:.3g}, share {c.share:.2f}" for c in cands],
            textposition="auto",
            hovertemplate="%{y}: statistic %{x:.4g}<br>share %{customdata[0]:.3f}, "
            "p %{customdata[1]:.2g}, novelty %{customdata[2]:.2f}<br>%{customdata[3]}"
            "<extra></extra>",
            showlegend=False,
        )
    )
    for k in sorted({c.k for c in cands}):
        fig.add_vline(
            x=float(chi2.isf(it.threshold_p, k)),
            line={"dash": "dash", "width": 1, "color": "#000000"},
        )
    from .report import evidence_axis_label  # report imports this module

    label = evidence_axis_label(it.threshold_p, min_share).replace("\n", "<br>")
    fig.update_xaxes(type="log", title_text=html.escape(label).replace("&lt;br&gt;", "<br>"))
    return _layout(
        fig,
        f"Iteration {it.index}: evidence per candidate effect "
        "(green: added, orange: significant, grey: not significant)",
        int(24 * max(len(cands), 4) + 160),
    )


def iplot_diagnostics(it: IterationRecord) -> go.Figure:
    """Residual diagnostics of the iteration's starting model.

    Parameters
    ----------
    it : IterationRecord
        One iteration of the loop.

    Returns
    -------
    plotly.graph_objects.Figure
        η² per signal (residual variance explained by the signal's binned mean, -; on the
        residual and beyond the current and its direction; dashed: signature threshold), lagged
        cross-correlations with the residual (lag in ms; one legend entry per signal) and the
        residual power spectral density (bar²/Hz, log scale).
    """
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots

    d = it.diagnostics
    fig = make_subplots(rows=1, cols=3, horizontal_spacing=0.12)
    from .diagnostics import SIGNATURE_ETA2
    from .report import LAG_LABEL  # report imports this module

    assoc = d.associations[::-1]
    bars = [("eta2", "#1f77b4", "η², residual", "on the residual")]
    if any(a.get("eta2_beyond_current") is not None for a in assoc):
        bars.append(
            (
                "eta2_beyond_current",
                "#ff7f0e",
                "η², beyond the current and its direction",
                "beyond the current",
            )
        )
    for key, color, name, where in bars:
        fig.add_trace(
            go.Bar(
                x=[a.get(key) or 0.0 for a in assoc],
                y=[a["signal"] for a in assoc],
                orientation="h",
                marker_color=color,
                name=name,
                hovertemplate=f"%{{y}}: η² %{{x:.3g}} {where}<extra></extra>",
            ),
            row=1,
            col=1,
        )
    fig.add_vline(
        x=SIGNATURE_ETA2, line={"dash": "dash", "width": 1, "color": "#000000"}, row=1, col=1
    )
    for k, (name, xc) in enumerate(d.cross_correlation.items()):
        lags = np.asarray(xc["lags_s"], dtype=float) * 1e3
        sl = thin(lags.size)
        fig.add_trace(
            go.Scatter(
                x=f32(lags, sl),
                y=f32(xc["values"], sl),
                mode="lines",
                name=name,
                line={"color": _CYCLE[k % len(_CYCLE)], "width": 1.2},
                hovertemplate="lag %{x:.4g} ms<br>%{y:.3f}<extra>%{fullData.name}</extra>",
            ),
            row=1,
            col=2,
        )
    if d.spectrum.get("freq_Hz"):
        f = np.asarray(d.spectrum["freq_Hz"], dtype=float)[1:]
        p = np.asarray(d.spectrum["psd_bar2_Hz"], dtype=float)[1:]
        sl = thin(f.size)
        fig.add_trace(
            go.Scatter(
                x=f32(f, sl),
                y=f32(p, sl),
                mode="lines",
                name="residual PSD",
                line={"color": "#444444", "width": 1},
                showlegend=False,
                hovertemplate="%{x:.4g} Hz<br>%{y:.3g} bar²/Hz<extra></extra>",
            ),
            row=1,
            col=3,
        )
        fig.update_yaxes(type="log", row=1, col=3)
    fig.update_xaxes(title_text="η² (-); dashed: signature threshold", row=1, col=1)
    fig.update_xaxes(title_text=LAG_LABEL.replace("\n", "<br>"), row=1, col=2)
    fig.update_yaxes(title_text="cross-correlation (-)", row=1, col=2)
    fig.update_xaxes(title_text="frequency (Hz)", row=1, col=3)
    fig.update_yaxes(title_text="residual PSD (bar²/Hz)", row=1, col=3)
    lines = textwrap.wrap(f"Iteration {it.index}: residual diagnostics — {d.summary()}", 130)
    return _layout(fig, "<br>".join(html.escape(x) for x in lines), 430, len(lines))
