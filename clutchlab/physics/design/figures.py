"""Figures of a sweep: tornado (sensitivity) chart and metric-vs-variable scatter plots.

matplotlib ``Figure`` objects only (no pyplot state): safe in workers and servers.
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from ...data.output import (
    OWNED_NAME,
    has_ownership_record,
    owned_files,
    ownership_record,
    write_file_atomic,
    write_folder_atomic,
)
from ...errors import OutputError
from .evaluate import STATUS_FAILED, STATUS_OK
from .metrics import METRIC_UNITS, metric_names
from .sensitivity import sensitivity_table, tornado_labels
from .spec import SweepSpec

if TYPE_CHECKING:  # matplotlib is imported on use: sweep workers import this package
    from matplotlib.figure import Figure

__all__ = [
    "FIGURE_FILES",
    "check_figures_folder",
    "metric_unit",
    "plot_metrics_vs_variables",
    "plot_tornado",
    "remove_figures",
    "write_figures",
]

#: The files :func:`write_figures` writes.
FIGURE_FILES = ("tornado.png", "metrics_vs_variables.png", "sensitivity.csv", "sweep.html")


def metric_unit(name: str) -> str:
    """Unit of metric column ``name``."""
    return METRIC_UNITS.get(name, "bar" if name.endswith("_bar") else "-")


def _metrics(spec: SweepSpec) -> tuple[str, ...]:
    sc = spec.scenario
    return metric_names(tuple(r.label for r in sc.ramps), sc.step is not None)


def plot_tornado(table: pd.DataFrame, spec: SweepSpec) -> Figure:
    """Tornado chart: per metric, the change over each variable's range, largest on top.

    Parameters
    ----------
    table : pandas.DataFrame
        Sweep results.
    spec : SweepSpec
        The sweep's spec.

    Returns
    -------
    matplotlib.figure.Figure
        One panel per metric; bars are the linear effects of :func:`sensitivity_table`
        (metric unit, variable low → high), R² of the linear fit in the title.
    """
    metrics = _metrics(spec)
    sens = sensitivity_table(table, spec, metrics)
    ncols = 3
    nrows = int(np.ceil(len(metrics) / ncols))
    height = max(1.2, 0.35 * len(spec.variables) + 0.9)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5.2 * ncols, height * nrows), constrained_layout=True)
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax, name in zip(axes, metrics, strict=False):
        s = sens[sens["metric"] == name].copy()
        s["mag"] = s["effect"].abs().fillna(-1.0)
        s = s.sort_values("mag")
        colors = ["tab:red" if e > 0 else "tab:blue" for e in s["effect"].fillna(0.0)]
        labels, message = tornado_labels(s)
        ax.barh(labels, s["effect"].fillna(0.0), color=colors)
        ax.axvline(0.0, color="0.3", lw=0.8)
        r2 = s["r2"].iloc[0] if len(s) else np.nan
        n = int(s["n"].iloc[0]) if len(s) else 0
        title = f"{name}  (R² {r2:.2f}, n {n})" if np.isfinite(r2) else f"{name}  (n {n})"
        ax.set_title(title, fontsize=9)
        if message:
            ax.text(0.5, 0.5, message, transform=ax.transAxes, ha="center")
        ax.set_xlabel(f"change low → high ({metric_unit(name)})", fontsize=8)
        ax.tick_params(labelsize=8)
        ax.grid(axis="x", alpha=0.3)
    for ax in axes[len(metrics) :]:
        ax.set_visible(False)
    fig.suptitle(
        f"{spec.name}: sensitivity (linear effect over each variable's range; "
        "red: the metric rises, blue: it falls)"
    )
    return fig


def plot_metrics_vs_variables(table: pd.DataFrame, spec: SweepSpec) -> Figure:
    """Scatter of every metric against every design variable (failed points marked).

    Returns
    -------
    matplotlib.figure.Figure
        Rows: metrics; columns: variables. Failed points are drawn as red crosses at the
        bottom of each panel.
    """
    metrics = _metrics(spec)
    variables = spec.variables
    ok = table[table["status"] == STATUS_OK]
    failed = table[table["status"] == STATUS_FAILED]
    w, h = 2.6 * max(len(variables), 1) + 1.2, 1.7 * len(metrics) + 0.9
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullFormatter

    fig = Figure(figsize=(w, h))  # fixed margins: constrained layout is slow for big grids
    # One x axis per column: the tick labels are drawn on the bottom row only, so every
    # panel above must share its range (a metric NaN for some points narrowed it).
    axes = fig.subplots(len(metrics), max(len(variables), 1), squeeze=False, sharex="col")
    fig.subplots_adjust(
        left=1.2 / w, right=1 - 0.15 / w, bottom=0.55 / h, top=1 - 0.6 / h, wspace=0.3, hspace=0.25
    )
    size = 6 if len(ok) < 500 else 2
    for r, name in enumerate(metrics):
        y = ok[name].to_numpy(dtype=float)
        lo = np.nanmin(y) if np.isfinite(y).any() else 0.0
        for c, v in enumerate(variables):
            ax = axes[r, c]
            ax.scatter(ok[v.name], y, s=size, alpha=0.6, lw=0)
            if len(failed):
                ax.scatter(failed[v.name], np.full(len(failed), lo), marker="x", c="tab:red", s=12)
            if v.scale == "log":
                ax.set_xscale("log")
                ticks = np.geomspace(v.low, v.high, 4)
                ax.set_xticks(ticks, [f"{x:.3g}" for x in ticks])
                ax.xaxis.set_minor_formatter(NullFormatter())
            if r == len(metrics) - 1:
                ax.set_xlabel(f"{v.name} ({v.unit})", fontsize=8)
            else:
                ax.tick_params(which="both", labelbottom=False)
            if c == 0:
                ax.set_ylabel(f"{name}\n({metric_unit(name)})", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
    fig.suptitle(f"{spec.name}: metrics vs design variables ({len(ok)} ok, {len(failed)} failed)")
    return fig


def check_figures_folder(folder: str | Path, what: str = "figures") -> Path:
    """Refuse a figures folder clutchlab may not write (``OutputError``), before any work.

    Missing or empty: fine. A folder clutchlab wrote (its ``.clutchlab-owned.json``) is
    written again: its figures are replaced, every other file is kept, but a user's file where
    a figure would go (a ``tornado.png`` clutchlab did not write) is refused by name. A
    non-empty folder without the record is not clutchlab's and is refused as a whole.
    """
    folder = Path(folder)
    if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
        raise OutputError(f"{what} {folder}: exists and is not a folder clutchlab wrote")
    if not folder.is_dir() or not any(folder.iterdir()):
        return folder
    if not has_ownership_record(folder):
        mine = sorted(n for n in FIGURE_FILES if (folder / n).exists() or (folder / n).is_symlink())
        named = f" (its {', '.join(mine)} would be replaced)" if mine else ""
        raise OutputError(
            f"{what} {folder}: folder exists and clutchlab did not create it (no "
            f"{OWNED_NAME}){named}; move it away or choose another --out (figures of a "
            "clutchlab older than this record carry none: delete them to have them drawn again)"
        )
    owned = owned_files(folder)
    clash = sorted(
        n
        for n in FIGURE_FILES
        if n not in owned and ((folder / n).exists() or (folder / n).is_symlink())
    )
    if clash:
        raise OutputError(
            f"{what} {folder}: clutchlab did not write these files and would replace them; "
            "move them away or choose another --out: " + ", ".join(clash)
        )
    return folder


def remove_figures(folder: str | Path) -> None:
    """Delete the figures clutchlab wrote in ``folder`` (an overwritten sweep's), nothing else.

    Only the files of the folder's ownership record go. A folder left empty goes too; one
    with a user's file stays, still recorded as clutchlab's figures folder (owning no file),
    so the next figures are written beside that file. A folder without clutchlab's record is
    left alone.
    """
    folder = Path(folder)
    if folder.is_symlink() or not folder.is_dir() or not has_ownership_record(folder):
        return
    for name in owned_files(folder):
        target = folder / name
        if target.is_file() or target.is_symlink():
            target.unlink(missing_ok=True)
    if any(p.name != OWNED_NAME for p in folder.iterdir()):
        write_file_atomic(folder / OWNED_NAME, ownership_record([], "figures"), overwrite=True)
        return
    (folder / OWNED_NAME).unlink(missing_ok=True)
    with contextlib.suppress(OSError):
        folder.rmdir()


def write_figures(table: pd.DataFrame, spec: SweepSpec, folder: str | Path) -> tuple[Path, ...]:
    """Write ``tornado.png``, ``metrics_vs_variables.png``, ``sensitivity.csv`` and ``sweep.html``.

    ``sweep.html`` holds the two figures interactive (zoom, hover for each point's id and
    values, finished / failed points toggled from the legend; plotly.js embedded, so it works
    offline): :func:`~clutchlab.physics.design.interactive.sweep_html`.

    The folder is written atomically with an ownership record
    (:func:`clutchlab.data.output.write_folder_atomic`): the figures of an earlier run are
    replaced, a user's other files in it are kept, and a folder clutchlab did not create, or a
    user's file where a figure would go, is refused (:func:`check_figures_folder`).

    Parameters
    ----------
    table : pandas.DataFrame
        Sweep results.
    spec : SweepSpec
        The sweep's spec.
    folder : path
        Output folder (created).

    Returns
    -------
    tuple of Path
        Files written.

    Raises
    ------
    OutputError
        The folder is not clutchlab's, or a user's file stands where a figure would go.
    """
    folder = check_figures_folder(folder)
    from .interactive import sweep_html

    tornado, scatter = plot_tornado(table, spec), plot_metrics_vs_variables(table, spec)
    csv = sensitivity_table(table, spec, _metrics(spec)).to_csv(index=False)
    files = {
        FIGURE_FILES[0]: lambda tmp: tornado.savefig(tmp, dpi=110, format="png"),
        FIGURE_FILES[1]: lambda tmp: scatter.savefig(tmp, dpi=90, format="png"),
        FIGURE_FILES[2]: csv.encode("utf-8"),
        FIGURE_FILES[3]: sweep_html(table, spec).encode("utf-8"),
    }
    write_folder_atomic(folder, files, overwrite=True, what="figures")
    return tuple(folder / n for n in FIGURE_FILES)
