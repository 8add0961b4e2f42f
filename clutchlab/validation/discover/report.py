"""Figures and the HTML / Markdown summary of a discovery."""

from __future__ import annotations

import base64
import html
import io
import math
import textwrap
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from ..._plotly import MARKER_SCRIPT, figure_div, plotlyjs_script
from ...data.output import write_folder_atomic
from ...physics.fit import correlation_note
from ...physics.units import unit_shown
from ..report import REPORT_FOLDER
from .alternatives import alternative_note
from .diagnostics import SIGNATURE_ETA2
from .interactive import iplot_diagnostics, iplot_evidence, iplot_residuals
from .result import DiscoveryResult, IterationRecord, ModelState
from .scoring import MIN_NOVELTY

__all__ = [
    "candidate_columns_note",
    "evidence_axis_label",
    "fit_state_text",
    "plot_diagnostics",
    "plot_evidence",
    "plot_residuals",
    "sparse_text",
    "write_report",
]


def _train_curves(state: ModelState):
    res = state.residual
    for name, (a, b) in zip(res.experiments, res.slices, strict=True):
        yield name, res.signals["current_mA"][a:b], res.r[a:b], res.keep[a:b]


def plot_residuals(it: IterationRecord) -> Figure:
    """Residual (model − measured, dither-period mean, bar) vs nominal current (mA),
    before and after the iteration, on the training and (when there are any) the test
    experiments."""
    with_test = bool(it.before.test_residual)
    rows = 2 if with_test else 1
    fig = Figure(figsize=(10, 3.25 * rows + 0.5), layout="constrained")  # no pyplot
    axes = np.asarray(fig.subplots(rows, 2, sharex=True, sharey="row")).reshape(rows, 2)
    after = f"after (+ {it.effect})" if it.effect else "after (no effect added)"
    for col, (state, title) in enumerate(((it.before, "before"), (it.after, after))):
        ax = axes[0, col]
        for name, cur, r, keep in _train_curves(state):
            ax.plot(cur[keep], r[keep], ".", ms=1.5, alpha=0.6, label=name)
        ax.set_title(f"{title}: training RMSE {state.train['rmse_bar']:.4f} bar", fontsize=10)
        if with_test:
            ax = axes[1, col]
            for name, (cur, r) in state.test_residual.items():
                ax.plot(cur, r, lw=0.7, label=name)
            ax.set_title(f"{title}: test RMSE {state.test['rmse_bar']:.4f} bar", fontsize=10)
        axes[-1, col].set_xlabel("nominal VFS current (mA)")
    for ax in axes.ravel():
        ax.axhline(0.0, color="black", lw=0.6)
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("residual, training (bar)")
    if axes[0, 1].get_legend_handles_labels()[0]:
        axes[0, 1].legend(loc="best", fontsize=6, markerscale=5, ncol=2)
    if with_test:
        axes[1, 0].set_ylabel("residual, unseen test ramp (bar)")
        if it.after.test_residual:
            axes[1, 1].legend(loc="best", fontsize=7)
    fig.suptitle(
        f"Iteration {it.index}: residual (model − measured, dither-period mean) before / after"
    )
    return fig


def evidence_axis_label(threshold_p: float, min_share: float | None) -> str:
    """What the evidence figure's x axis and dashed lines are: the statistic, the line
    each candidate's p-value threshold sits at (one test, per number k of its strength
    parameters), and the other conditions of "significant" (more tests, the share)."""
    share = "" if min_share is None else f" and share ≥ {min_share:.2f}"
    return (
        "score statistic n_eff·ln(RSS₀/RSS₁); dashed: p = "
        f"{threshold_p:.2g} for k strength parameters, one test\n(significant also needs "
        f"p < {threshold_p:.2g} / tests{share})"
    )


def plot_evidence(it: IterationRecord, min_share: float | None = None) -> Figure:
    """Score statistic of every candidate (log scale) against the significance threshold.

    Parameters
    ----------
    it : IterationRecord
        One iteration of the loop.
    min_share : float, optional
        Share of the residual (0–1) a candidate must explain to be significant
        (``DiscoverySettings.min_share``); a bar past its line that falls short of it says so.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from scipy.stats import chi2

    fig = Figure(figsize=(8, 0.35 * max(len(it.candidates), 4) + 1.5), layout="constrained")
    ax = fig.subplots()
    cands = it.candidates[::-1]
    stats = [max(c.statistic, 1e-2) for c in cands]
    colors = [
        "tab:green" if c.effect == it.effect else ("tab:orange" if c.significant else "tab:gray")
        for c in cands
    ]
    ax.barh([c.effect for c in cands], stats, color=colors)
    for y, c in enumerate(cands):  # the value in words: a bar at 0 is drawn at 0.01
        short = _significant_cell(c, it.threshold_p, min_share).startswith("no (share")
        ax.text(
            max(c.statistic, 1e-2),
            y,
            f" {c.statistic:.3g}, share {c.share:.2f}" + (f" < {min_share:.2f}" if short else ""),
            va="center",
            fontsize=7,
        )
    for j, k in enumerate(sorted({c.k for c in cands})):
        x = chi2.isf(it.threshold_p, k)
        ax.axvline(x, ls="--", lw=0.8, color="black")
        ax.text(x, 1.0, f" k={k} " , transform=ax.get_xaxis_transform(),
                ha="right" if j == 0 else "left", va="bottom", fontsize=7)  # fmt: skip
    ax.set_xscale("log")
    ax.set_xlabel(evidence_axis_label(it.threshold_p, min_share), fontsize=9)
    ax.set_title(f"Iteration {it.index}: evidence per candidate effect")
    shown = {
        "tab:green": f"added ({it.effect})",
        "tab:orange": "significant, not added",
        "tab:gray": "not significant",
    }
    handles = [Patch(color=k, label=v) for k, v in shown.items() if k in colors]
    if handles:
        ax.legend(handles=handles, loc="best", fontsize=7)
    ax.grid(alpha=0.3, axis="x")
    return fig


#: What a lag of the cross-correlation panel means (``corr(r(t), x(t − lag))``).
LAG_LABEL = "lag (ms)\n> 0: the residual follows the signal later"


def plot_diagnostics(it: IterationRecord) -> Figure:
    """Residual diagnostics of the iteration's starting model: η² per signal (on the
    residual, and beyond a map of the current and its direction where measured; dashed: the
    signature threshold), lagged cross-correlations, spectrum."""
    d = it.diagnostics
    fig = Figure(figsize=(12, 3.8), layout="constrained")
    ax1, ax2, ax3 = fig.subplots(1, 3)
    assoc = d.associations[::-1]
    y = np.arange(len(assoc))
    beyond = [a.get("eta2_beyond_current") for a in assoc]
    ax1.barh(y + 0.2, [a["eta2"] for a in assoc], height=0.4, color="tab:blue", label="residual")
    if any(b is not None for b in beyond):  # the second η² the signature also reads
        ax1.barh(
            y - 0.2,
            [b or 0.0 for b in beyond],
            height=0.4,
            color="tab:orange",
            label="beyond the current and its direction",
        )
    ax1.set_yticks(y, [a["signal"] for a in assoc])
    ax1.axvline(SIGNATURE_ETA2, ls="--", lw=0.8, color="black", label="signature threshold")
    ax1.legend(fontsize=6, loc="lower right")
    ax1.set_xlabel("η² (-)\nresidual variance explained by the signal's binned mean")
    for name, xc in d.cross_correlation.items():
        ax2.plot(np.array(xc["lags_s"]) * 1e3, xc["values"], label=name)
    ax2.set(xlabel=LAG_LABEL, ylabel="cross-correlation with the residual (-)")
    ax2.legend(fontsize=7)
    if d.spectrum.get("freq_Hz"):
        ax3.semilogy(d.spectrum["freq_Hz"][1:], d.spectrum["psd_bar2_Hz"][1:])
    ax3.set(xlabel="frequency (Hz)", ylabel="residual PSD (bar²/Hz)")
    for ax in (ax1, ax2, ax3):
        ax.grid(alpha=0.3)
    text = textwrap.fill(f"Iteration {it.index}: residual diagnostics — {d.summary()}", 150)
    fig.suptitle(text, fontsize=9)  # wrapped, never cut: the summary names what it follows
    return fig


def _png(fig: Figure, files: dict[str, bytes], name: str) -> str:
    """Render ``fig`` as PNG into ``files[name]``; return the same image base64-encoded."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    files[name] = buf.getvalue()
    return base64.b64encode(files[name]).decode()


#: Interactive form of each figure of an iteration (same keys as the PNGs).
_IPLOTS = {
    "residuals": iplot_residuals,
    "evidence": iplot_evidence,
    "diagnostics": iplot_diagnostics,
}


def _fmt(x, spec=".4f") -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def _significant_cell(c, threshold_p: float, min_share: float | None) -> str:
    """The "significant" cell: yes, or no with the test it failed when its p-value alone
    would pass (a share below ``min_share``), so that a p below the stated level beside
    "no" is explained."""
    if c.significant:
        return "yes"
    p_ok = c.status == "scored" and c.p_value < threshold_p / max(c.n_tests, 1)
    if p_ok and min_share is not None and c.share < min_share:
        return f"no (share < {min_share:.2f})"
    return "no"


def _significance_text(threshold_p: float, min_share: float | None) -> str:
    """The rule a candidate's "significant" column applies, in words."""
    share = "" if min_share is None else f" and its share is at least {min_share:.2f}"
    return (
        f"A candidate is significant when p < {threshold_p:.2g} (the level α/m per "
        "candidate) divided by its number of tests (in brackets under 'linearized at')"
        f"{share}."
    )


def _candidate_rows(it: IterationRecord, min_share: float | None = None) -> list[list[str]]:
    rows = []
    for c in it.candidates:
        refit = c.refit
        rows.append(
            [
                c.effect + (" ✔" if c.effect == it.effect else ""),
                _fmt(c.statistic, ".1f"),
                _fmt(c.p_value, ".2g"),
                _fmt(c.share, ".3f"),
                _fmt(c.novelty, ".2f"),
                f"{c.probe} ({c.n_tests})",
                _significant_cell(c, it.threshold_p, min_share),
                _fmt(refit.get("delta_bic"), ".1f") if refit else "",
                alternative_note(refit),
                c.status,
            ]
        )
    return rows


#: "linearized at": zero strength, a small probe strength, or the profile's best point;
#: in brackets the number of points scored (the significance level is divided by it).
_CAND_HEAD = [
    "effect",
    "statistic",
    "p",
    "share",
    "novelty",
    "linearized at (tests)",
    "significant",
    "ΔBIC",
    "flexible alternatives",
    "status",
]


def fit_state_text(status: str, converged: bool, baseline: bool = False) -> str:
    """The "fit after" line of an iteration in words: the solver status, whether the fit
    converged, what a limit in it means and (when it stopped at one) the option that
    raises it.

    Parameters
    ----------
    status : str
        The fit's status, ``"<status> (pre-fit) → <status> (refine)"`` when staged.
    converged : bool
        ``FitResult.success``.
    baseline : bool
        The fit is the discovery's base fit (nothing added yet), which may have been given
        with ``--physics-model``: the options then belong to ``clutchlab fit-physics``.

    Returns
    -------
    str
    """
    from ...physics.fit.fitter import SHORT_OF_TIME
    from ...physics.fit.nlp import ITERATION_LIMIT, WALL_TIME_LIMIT

    head = f"fit after: {status}, "
    if converged:
        if ITERATION_LIMIT in status and "(refine)" in status:
            return head + (
                "converged (the pre-fit converged; the refinement stopping at its iteration "
                "limit ends a staged fit, it is not a failure)"
            )
        return head + "converged"
    hints = []
    if ITERATION_LIMIT in status:
        hints.append("more solver iterations per fit (--max-iter)")
    if WALL_TIME_LIMIT in status or SHORT_OF_TIME in status:
        hints.append("more time per fit (--time-limit)")
    hint = f"; {' or '.join(hints)} may improve it" if hints else ""
    if hints and baseline:
        hint += " (for a base fit given with --physics-model: the same option of `clutchlab "
        hint += "fit-physics`)"
    return head + f"NOT converged (stopped at a limit; its best iterate is the model{hint})"


def sparse_text(r2: float) -> str:
    """The words before the sparse-regression equation: what ``r/σ``, the signal names and
    the coefficients in it are (the equation alone reads as if in bar and mA).

    Parameters
    ----------
    r2 : float
        Share of the residual variance the sparse model explains (0–1).

    Returns
    -------
    str
    """
    return (
        f"Sparse regression (pysindy STLSQ, R² {r2:.2f}; r/σ is the residual in units of its "
        "standard deviation, each signal name its standardized value (signal − mean) / SD, "
        "so the coefficients are dimensionless and comparable)"
    )


def _parameter_rows(parameters: list[dict]) -> list[list[str]]:
    """Rows of the "parameters after" table: name (marked "not identifiable" where the fit
    says so, as fit-physics does), value, ± SE, unit as a reader writes it (``N/A`` →
    ``N·A⁻¹``, which would read as "not applicable"; the JSON keeps ``N/A``)."""
    return [
        [
            p["name"] + (" (not identifiable)" if p.get("identifiable", True) is False else ""),
            _fmt(p["value"], ".5g"),
            _fmt(p["std_error"], ".3g"),
            unit_shown(p["unit"]),
        ]
        for p in parameters
    ]


def candidate_columns_note(min_novelty: float) -> str:
    """What the evidence table's columns and its status names mean, with their units.

    Parameters
    ----------
    min_novelty : float
        Novelty (0–1) below which a candidate is "confounded"
        (:data:`~clutchlab.validation.discover.scoring.MIN_NOVELTY`).

    Returns
    -------
    str
    """
    return (
        "Columns: statistic = n_eff·ln(RSS₀/RSS₁) (-), the drop of the residual sum of "
        "squares when the effect's linearized output is added; p = its χ² p-value; share = "
        "fraction (0–1) of the residual sum of squares that output explains; novelty = "
        "fraction (0–1) of that output the fitted parameters cannot mimic; linearized at = "
        "zero strength, a small probe strength or the profile's best point (tests scored); "
        "ΔBIC = information-criterion change of its refit (< 0: better; empty: not "
        "refitted); status: scored, confounded (novelty below "
        f"{min_novelty:g}: the fitted parameters mimic it, so it is not tested) or failed "
        "(with the reason)."
    )


def _md_table(head: list[str], rows: list[list[str]]) -> str:
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


def _html_table(head: list[str], rows: list[list[str]]) -> str:
    h = "".join(f"<th>{html.escape(x)}</th>" for x in head)
    b = "".join("<tr>" + "".join(f"<td>{html.escape(x)}</td>" for x in r) + "</tr>" for r in rows)
    return f"<table border='1' cellpadding='3' style='border-collapse:collapse'>{h}{b}</table>"


def _split_text(result: DiscoveryResult) -> str:
    """Which experiments were fitted on and which only scored, and the wall time."""
    train = f"Training: {len(result.train)} experiments ({', '.join(result.train)})"
    if result.test:
        test = f"test, only scored: {len(result.test)} ({', '.join(result.test)})"
    else:
        test = "no test experiments (the test rows of the tables are empty)"
    return f"{train}; {test}; wall time of the discovery {result.wall_s:.1f} s."


def write_report(
    result: DiscoveryResult, out: str | Path, command: str = "", interactive: bool = True
) -> Path:
    """Write ``discovery.json``, the figures, ``report.md`` and ``report.html`` into ``out``.

    Parameters
    ----------
    result : DiscoveryResult
        What :func:`~clutchlab.validation.discover.discover` returned.
    out : path
        Folder (created; written atomically, see :func:`clutchlab.data.write_folder_atomic`).
    command : str
        Command line recorded in the report.
    interactive : bool
        Draw the figures of ``report.html`` with Plotly (zoom, hover, experiments toggled
        from the legend; plotly.js embedded once, so the page works offline,
        :mod:`~clutchlab.validation.discover.interactive`); False: as PNG. The PNGs beside the
        report (used by ``report.md``) are written either way.

    Returns
    -------
    Path of ``report.html``.
    """
    out = Path(out)
    files: dict[str, bytes] = {}
    split = _split_text(result)
    md = [
        "# clutchlab discover — closing the loop",
        "",
        f"Command: `{command}`  " if command else "",
        split,
        "",
        f"**Result:** {result.summary}",
        "",
        *([result.stop_note(), ""] if result.time_limited else []),
        *([result.next_steps(), ""] if result.unexplained else []),
    ]
    parts_html = [
        "<h1>clutchlab discover — closing the loop</h1>",
        f"<p>Command: <code>{html.escape(command)}</code></p>" if command else "",
        f"<p>{html.escape(split)}</p>",
        f"<p><b>Result:</b> {html.escape(result.summary)}</p>",
        f"<p>{html.escape(result.stop_note())}</p>" if result.time_limited else "",
        f"<p>{html.escape(result.next_steps())}</p>" if result.unexplained else "",
    ]
    min_share = result.settings.get("min_share")
    for it in result.iterations:
        title = f"Iteration {it.index}: " + (it.effect or f"no effect added ({it.decision})")
        errs = [
            [
                "training",
                _fmt(it.before.train["rmse_bar"]),
                _fmt(it.after.train["rmse_bar"]),
                _fmt(it.before.train["fit_pct"], ".1f"),
                _fmt(it.after.train["fit_pct"], ".1f"),
            ],
            [
                "test",
                _fmt(it.before.test["rmse_bar"]),
                _fmt(it.after.test["rmse_bar"]),
                _fmt(it.before.test["fit_pct"], ".1f"),
                _fmt(it.after.test["fit_pct"], ".1f"),
            ],
        ]
        err_head = ["data", "RMSE before (bar)", "RMSE after (bar)", "fit % before", "fit % after"]
        record = it.to_dict()
        params = _parameter_rows(record["parameters_after"])
        fit_state = fit_state_text(
            record["fit_status_after"],
            record["fit_converged_after"],
            baseline=it.after.fit is result.baseline.fit,
        )
        fit = it.after.fit
        if note := correlation_note(fit.residual_correlation_time, fit.uncertainty_note):
            fit_state += f"; {note}"
        figs = {"residuals": plot_residuals(it)}
        if it.candidates:  # none scored (effect limit, no candidate left): no empty axes
            figs["evidence"] = plot_evidence(it, min_share)
        figs["diagnostics"] = plot_diagnostics(it)
        pngs = {k: _png(f, files, f"iteration{it.index}_{k}.png") for k, f in figs.items()}
        if it.candidates:
            rule = _significance_text(it.threshold_p, min_share)
            columns = candidate_columns_note(MIN_NOVELTY)
            evidence_md = [
                rule,
                "",
                _md_table(_CAND_HEAD, _candidate_rows(it, min_share)),
                "",
                columns,
            ]
            evidence_html = [
                f"<p>{html.escape(rule)}</p>",
                _html_table(_CAND_HEAD, _candidate_rows(it, min_share)),
                f"<p style='font-size:small'>{html.escape(columns)}</p>",
            ]
        else:
            evidence_md = [f"No candidate was scored ({it.decision})."]
            evidence_html = [f"<p>No candidate was scored ({html.escape(it.decision)}).</p>"]
        md += [
            f"## {title}",
            "",
            f"Residual before: {it.diagnostics.summary()}",
            "",
            f"{sparse_text(it.sparse.r2)}: `{it.sparse.equation()}`",
            "",
            *evidence_md,
            "",
            _md_table(err_head, errs),
            "",
            f"Parameters after (± standard error); {fit_state}:",
            "",
            _md_table(["parameter", "value", "± SE", "unit"], params),
            "",
            *(f"![{k}](iteration{it.index}_{k}.png)" for k in figs),
            "",
        ]
        parts_html += [
            f"<h2>{html.escape(title)}</h2>",
            f"<p>Residual before: {html.escape(it.diagnostics.summary())}</p>",
            f"<p>{html.escape(sparse_text(it.sparse.r2))}: "
            f"<code>{html.escape(it.sparse.equation())}</code></p>",
            *evidence_html,
            "<br>",
            _html_table(err_head, errs),
            f"<p>Parameters after (± standard error); {html.escape(fit_state)}:</p>",
            _html_table(["parameter", "value", "± SE", "unit"], params),
            *(
                figure_div(
                    _IPLOTS[k](it, min_share) if k == "evidence" else _IPLOTS[k](it),
                    f"plot-iteration{it.index}_{k}",
                )
                if interactive
                else f"<img src='data:image/png;base64,{p}' style='max-width:100%'>"
                for k, p in pngs.items()
            ),
        ]
    files["report.md"] = ("\n".join(md) + "\n").encode("utf-8")
    page = (
        "<!doctype html><html><head><meta charset='utf-8'><title>clutchlab discover</title>"
        + (plotlyjs_script() if interactive and result.iterations else "")
        + "</head><body style='font-family:sans-serif;max-width:1000px'>"
        + "".join(parts_html)
        + MARKER_SCRIPT
        + "</body></html>"
    )
    files["report.html"] = page.encode("utf-8")
    files["discovery.json"] = (result.to_json() + "\n").encode("utf-8")
    # One atomic step: a kill leaves the old report or the new one, a user's file is kept.
    write_folder_atomic(out, files, overwrite=True, what=REPORT_FOLDER)
    return out / "report.html"
