"""The comparison report: one self-contained HTML file, a Markdown summary, JSON and CSV.

Every number in ``report.html``, ``report.md`` and ``metrics.csv`` is rendered from the one
dictionary written as ``metrics.json`` (:meth:`Evaluation.to_dict`, made JSON-safe by
:func:`jsonable`), through one formatting function (:func:`fmt`). The HTML table cells also
carry the exact value (``data-value``), so a reader — or a test — can check them against
``metrics.json``.

Files are first written to a temporary folder beside the destination and then moved into
place (a new folder is renamed in one step; into an existing one each file is replaced
atomically, ``metrics.json`` last), so a failed run leaves no half-written report.
"""

from __future__ import annotations

import base64
import csv
import html
import io
import json
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._plotly import MARKER_SCRIPT as _MARKER
from ..data.output import write_file_atomic, write_folder_atomic
from ..physics.fit import correlation_note
from ..physics.units import unit_shown
from .averaging import averaging_note, scored_signal
from .figures import FigureSpec, report_figures
from .interactive import interactive_figures
from .metrics import ACCURACY_KEYS, COVERAGE_REGIONS, METRIC_KEYS
from .model_files import model_files

if TYPE_CHECKING:
    from .evaluate import Evaluation

__all__ = [
    "METRIC_LABELS",
    "REPORT_FOLDER",
    "ReportFiles",
    "fmt",
    "jsonable",
    "metrics_csv",
    "render_html",
    "render_markdown",
    "summary_lines",
    "write_json",
    "write_report",
]

#: What a report folder is called in messages and in its ownership record.
REPORT_FOLDER = "report folder"

#: Column heading and unit of each metric key.
METRIC_LABELS: dict[str, tuple[str, str]] = {
    "rmse_bar": ("RMSE", "bar"),
    "mae_bar": ("MAE", "bar"),
    "max_abs_bar": ("max |e|", "bar"),
    "fit_pct": ("fit", "%"),
    "hysteresis_width_err_bar": ("hysteresis width err", "bar"),
    "latch_on_err_mA": ("latch-on err", "mA"),
    "latch_off_err_mA": ("latch-off err", "mA"),
    "fit_s": ("fit time", "s"),
    "predict_s": ("predict time", "s"),
}

_DEFINITIONS = (
    "Errors e = predicted − measured clutch pressure on every test sample, pooled over the "
    "test experiments. Primary: both signals averaged over one dither period; secondary "
    "('raw'): unaveraged. RMSE, MAE, max |e| in bar; fit = 100·(1 − ‖e‖/‖y − ȳ‖) %. "
    "Hysteresis width = rising minus falling pressure at the centre of each {bin_mA} mA "
    "nominal-current bin (least-squares line per branch and bin); its error is the RMS over "
    "experiments × bins of predicted minus measured width, in the regulated bins (both "
    "branches covered; no latched sample in the bin or its neighbours). Latch-on / latch-off "
    "current = nominal current where the pressure snaps to / drops from line pressure on the "
    "rising / falling branch (midpoint between regulated and line pressure); error = mean "
    "over experiments of |predicted − measured| (mA); a missing snap counts at the peak "
    "current. Fit time includes the fit of a variant it builds on (hybrid: physics_fitted)."
)


def _definitions(doc: dict[str, Any], escape: Callable[[str], str] = str) -> str:
    """The metric definitions, with the averaging window the primary scores really used
    (its experiment names passed through ``escape``)."""
    note = averaging_note(doc.get("averaging"), "test experiment")
    bin_mA = (doc.get("analysis") or {}).get("bin_mA", 25.0)  # the bins the scores used
    return _DEFINITIONS.format(bin_mA=fmt(bin_mA)) + (" " + escape(note) if note else "")


def _test_ramps(doc: dict[str, Any]) -> str:
    """``"test ramp"``, or ``"test ramps"`` when the split has several test ramp labels."""
    return "test ramps" if len((doc.get("split") or {}).get("test_ramps", ())) > 1 else "test ramp"


def _signal(doc: dict[str, Any]) -> str:
    """What the primary scores average (:func:`~.averaging.scored_signal`)."""
    return scored_signal(doc.get("averaging"))


def jsonable(obj: Any) -> Any:
    """``obj`` with NaN / inf as None, numpy scalars and arrays as Python numbers and lists.

    Parameters
    ----------
    obj : object
        Nested dicts, lists, tuples, numbers, strings.

    Returns
    -------
    object
        Strict-JSON-serializable equivalent.
    """
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [jsonable(v) for v in obj.tolist()]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj


def fmt(value: Any) -> str:
    """A number as the report shows it: 4 significant digits; ``n/a`` for None / NaN."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _head(key: str) -> str:
    label, unit = METRIC_LABELS.get(key, (key, ""))
    return f"{label} ({unit})" if unit else label


def _best(rows: dict[str, dict[str, Any]], key: str) -> str | None:
    vals = {n: r.get(key) for n, r in rows.items() if isinstance(r.get(key), (int, float))}
    if len(vals) < 2 or key not in ACCURACY_KEYS:
        return None
    pick = max if key == "fit_pct" else min
    return pick(vals, key=vals.get)


# ---- Markdown ---------------------------------------------------------------------------------


_MD_SPECIAL = re.compile(r"([\\`*_\[\]()#|~!])")


def _md_text(text: Any) -> str:
    """A user-provided string (ramp label, path, message) as literal Markdown text: HTML and
    Markdown syntax characters escaped, so a label renders as written and injects nothing."""
    return _MD_SPECIAL.sub(r"\\\1", html.escape(str(text), quote=False))


def _md_code(text: Any) -> str:
    """``text`` as an inline code span, whatever backticks it contains."""
    text = str(text).replace("\n", " ")
    fence = "`" * (max((len(r) for r in re.findall(r"`+", text)), default=0) + 1)
    return f"{fence} {text} {fence}"


def _md_cell(text: str) -> str:
    return str(text).replace("|", "\\|")


def _parameter_table(fit: dict, name: Callable[[str], str]) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the fitted-parameter table (``name`` formats a parameter's name);
    the meaning column is empty for a metrics file written before it was recorded."""
    header = ["parameter", "default", "fitted", "± std err", "unit", "identifiable", "meaning"]
    rows = [
        [
            name(n),
            fmt(p["default"]),
            fmt(p["value"]),
            fmt(p["std_error"]),
            unit_shown(p["unit"]),
            fmt(p["identifiable"]),
            p.get("description", ""),
        ]
        for n, p in fit["parameters"].items()
    ]
    return header, rows


def _fit_status(fit: dict[str, Any]) -> str:
    """The physics fit's status line; for a fit stopped at a limit, which limits it ran under
    and how to get a converged one (the status alone, e.g. ``Maximum_WallTime_Exceeded``,
    told the reader neither)."""
    kept = "staged start" if fit.get("note") else "best iterate"
    state = "converged" if fit["converged"] else f"NOT converged — {kept} used"
    text = (
        f"Status: {fit['status']} ({state}); {fit['iterations']} iterations; "
        f"{fmt(fit['wall_s'])} s; effects: {', '.join(fit.get('effects') or []) or 'none'}."
    )
    for key in ("note", "uncertainty_note"):  # the staged start kept; no standard errors
        if fit.get(key):
            text += f" {fit[key][0].upper()}{fit[key][1:]}."
    if note := correlation_note(
        fit.get("residual_correlation_time"), fit.get("uncertainty_note", "")
    ):
        text += f" {note[0].upper()}{note[1:]}."
    if fit["converged"]:
        return text
    limits = []
    if fit.get("time_limit_s") is not None:  # absent in older reports, None for a given fit
        limits.append(f"a wall-time limit of {fmt(fit['time_limit_s'])} s (--fit-time-limit)")
    if fit.get("max_iter") is not None:
        limits.append(f"an iteration limit of {fit['max_iter']} (--fit-max-iter)")
    ran = f" It ran under {' and '.join(limits)}." if limits else ""
    return (
        text
        + ran
        + " Its scores are those of the best iterate and may change with a longer fit: raise "
        "the limit it stopped at, or fit once with clutchlab fit-physics and pass the "
        "result with --physics-model."
    )


def _md_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(map(_md_cell, header)) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(map(_md_cell, r)) + " |" for r in rows]
    return "\n".join(lines)


def _md_metrics(rows: dict[str, dict[str, Any]], keys: tuple[str, ...]) -> str:
    best = {k: _best(rows, k) for k in keys}
    body = []
    for name, r in rows.items():
        cells = [f"**{fmt(r.get(k))}**" if best[k] == name else fmt(r.get(k)) for k in keys]
        body.append([f"`{name}`", *cells])
    return _md_table(["variant", *(_head(k) for k in keys)], body)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and math.isfinite(v)


def _pct(share: Any) -> str:
    """A share (0–1) as a whole per cent, ``–`` when it is not a number."""
    return f"{100 * share:.0f} %" if _is_number(share) else "–"


#: The error regions (:data:`~.metrics.COVERAGE_REGIONS`) as the report names them.
_REGION_NAMES = {
    r: {"latched": "latched plateau", "latch_window": "latch window"}.get(r, r)
    for r in COVERAGE_REGIONS
}


def _region_table(doc: dict[str, Any]) -> tuple[str, list[str], list[list[str]]] | None:
    """Where each variant's test error lies: a caption, a header and one row per variant
    (RMSE and share of the squared error per region of the measured pressure); None when no
    variant has the regions (a document written before them)."""
    rows, samples = [], None
    for name, d in doc["details"].items():
        pm = d.get("period_mean") or {}
        if f"rmse_{next(iter(_REGION_NAMES))}_bar" not in pm:
            continue
        samples = samples or {r: pm.get(f"samples_share_{r}") for r in _REGION_NAMES}
        cells = []
        for r in _REGION_NAMES:
            cells += [fmt(pm.get(f"rmse_{r}_bar")), _pct(pm.get(f"sq_error_share_{r}"))]
        rows.append([name, *cells])
    if not rows:
        return None
    window = (doc.get("analysis") or {}).get("latch_window_s")
    caption = (
        f"Error of the {_signal(doc)} on the {_test_ramps(doc)} per region of the measured "
        "pressure: "
        + ", ".join(
            f"{_REGION_NAMES[r]} {100 * v:.0f} % of the samples"
            for r, v in samples.items()
            if _is_number(v)
        )
        + (
            f" (latch window: within {fmt(window)} s of a measured snap or release)"
            if window is not None
            else ""
        )
        + ". A large share of the squared error in the few latch-window samples is latch "
        "timing; in the regulated region it is the characteristic and its hysteresis."
    )
    head = ["variant"]
    for r in _REGION_NAMES.values():
        head += [f"{r} RMSE (bar)", f"{r} share of e²"]
    return caption, head, rows


#: Most experiment names listed in the split line at the top of a report.
_MAX_NAMED = 12


def _experiments(names: list[str]) -> str:
    """``"3 experiments: a, b, c"`` (``"1 experiment: a"``); the count alone past
    :data:`_MAX_NAMED` (metrics.json's ``split`` lists them all)."""
    count = f"{len(names)} experiment{'' if len(names) == 1 else 's'}"
    if not names or len(names) > _MAX_NAMED:
        return count
    return f"{count}: {', '.join(names)}"


def _maps_text(data: dict[str, Any]) -> str:
    """``", read through channel map X"`` for the dataset line ("" without one)."""
    maps = data.get("channel_maps") or []  # absent in reports before session 41
    if not maps:
        return ""
    return f", read through channel map{'s' if len(maps) > 1 else ''} {', '.join(maps)}"


def _rate_note(split: dict[str, Any]) -> str | None:
    """What the reader must know when test experiments lie outside the training ramp rates
    (None otherwise, and in reports written before the rates were recorded)."""
    rates = split.get("ramp_rates_mA_s") or {}
    names = rates.get("extrapolated") or []
    if not names or not rates.get("train"):
        return None
    lo, hi = rates["train"]
    shown = ", ".join(f"{n} {fmt(rates['test'][n])}" for n in names[:6])
    more = f" and {len(names) - 6} more" if len(names) > 6 else ""
    return (
        f"{len(names)} test experiment(s) lie outside the training ramp rates ({shown}{more} "
        f"mA/s; trained {fmt(lo) if lo == hi else f'{fmt(lo)}–{fmt(hi)}'} mA/s): there every "
        "variant extrapolates in ramp "
        "rate (the widening of the hysteresis band and the latch delays), and the ML "
        "variants' ±2σ band was never calibrated at such a rate. Train on ramps that bracket "
        "the test ramps to score an interpolation."
    )


def _data_notes(data: dict[str, Any]) -> list[tuple[str, str]]:
    """(experiment, note) of every note reading the logs gave (absent in older reports)."""
    return [(name, note) for name, notes in (data.get("notes") or {}).items() for note in notes]


def summary_lines(doc: dict[str, Any]) -> list[str]:
    """A terminal summary of a report document: per variant its test RMSE (bar, dither-period
    mean), the share of its squared error within the latch window, and its RMSE in the
    regulated region (bar) — the numbers of the report's first two tables.

    Parameters
    ----------
    doc : dict
        The ``metrics.json`` document.

    Returns
    -------
    list of str
        A heading line and one line per scored variant; then, when a test log has no
        dither (its "dither-period mean" is its raw signal), a line saying what the scores
        average; when the physics fit stopped before converging, a line saying so (the
        report says both too).
    """
    rows = doc.get("variants") or {}
    if not rows:
        return []
    width = max(len(n) for n in rows)
    out = [f"{'variant':{width}s}  RMSE (bar)  e² in latch window  regulated RMSE (bar)"]
    for name, m in rows.items():
        pm = (doc.get("details", {}).get(name) or {}).get("period_mean") or {}
        rmse, reg = (m.get("rmse_bar"), pm.get("rmse_regulated_bar"))
        rmse_txt, reg_txt = (f"{v:.4f}" if _is_number(v) else "–" for v in (rmse, reg))
        share_txt = _pct(pm.get("sq_error_share_latch_window"))
        out.append(f"{name:{width}s}  {rmse_txt:>10s}  {share_txt:>18s}  {reg_txt:>20s}")
    if _signal(doc) != scored_signal(None):
        out.append(averaging_note(doc.get("averaging"), "test experiment"))
    if rate := _rate_note(doc.get("split") or {}):
        out.append(rate)
    fit = doc.get("physics_fit") or {}
    if fit and not fit.get("converged", True) and "physics_fitted" in rows:
        out.append(
            f"physics_fitted: its fit did NOT converge ({fit.get('status')}, "
            f"{fit.get('iterations')} iterations): its "
            + ("staged start" if fit.get("note") else "best iterate")
            + " is scored; a longer fit time or iteration limit may change it"
        )
    disc = doc.get("discovery") or {}
    if disc.get("time_limited") and "augmented_hybrid" in rows:
        out.append(
            f"augmented_hybrid: its discovery stopped at its time budget "
            f"({fmt(disc.get('time_limit_s'))} s) before it decided; it claims no effect it "
            "did not confirm in full (the summary in the report says where it stopped)"
        )
    return out


#: Columns of the latch-classifier table: accuracies are fractions of the held-out samples.
_CLASSIFIER_HEAD = [
    "classifier",
    "accuracy (fraction)",
    "worst held-out experiment: accuracy (experiment)",
    "fit (s, median per fold)",
]


def _classifier_table(clf: dict[str, Any]) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the latch-classifier comparison: pooled leave-one-experiment-out
    accuracy, and the lowest accuracy of one held-out experiment with that experiment's name
    (the column said "worst experiment" above a number)."""
    rows = []
    for key, c in clf["classifiers"].items():
        held = (clf.get("per_experiment") or {}).get(key, {})  # absent: older reports
        per = {e: a for e, a in held.items() if _is_number(a)}
        worst = min(per, key=per.get) if per else None
        cell = fmt(c["min_accuracy"]) + (f" ({worst})" if worst is not None else "")
        rows.append([c["label"], fmt(c["accuracy"]), cell, fmt(c["fit_s"])])
    return _CLASSIFIER_HEAD, rows


#: Columns of the closing-the-loop evidence table.
_DISCOVERY_HEAD = [
    "effect",
    "statistic",
    "p",
    "share",
    "significant",
    "ΔBIC screening",
    "ΔBIC all training",
    "flexible alternatives",
    "status",
]


def _discovery_rows(it: dict[str, Any]) -> list[list[str]]:
    return [
        [
            c["effect"] + (" ✔" if c["effect"] == it["effect"] else ""),
            fmt(c["statistic"]),
            fmt(c["p_value"]),
            fmt(c["share"]),
            fmt(c["significant"]),
            fmt(c["delta_bic_screening"]) if c["delta_bic_screening"] is not None else "",
            fmt(c["delta_bic"]) if c["delta_bic"] is not None else "",
            c.get("flexible_alternatives", ""),  # absent in reports before issue 17's rule
            c["status"],
        ]
        for c in it["candidates"]
    ]


def _discovery_intro(disc: dict[str, Any]) -> str:
    reused = []
    if disc["baseline_reused"]:
        reused.append("it starts from physics_fitted's fit")
    if disc["hybrid_reused"]:
        reused.append("no effect was added, so augmented_hybrid is the hybrid itself")
    return (
        f"augmented_hybrid's discovery on the training experiments ({fmt(disc['wall_s'])} s"
        + ("; " + "; ".join(reused) if reused else "")
        + f"): {disc['summary']}"
    )


def _discovery_title(it: dict[str, Any]) -> str:
    what = it["effect"] or f"no effect added ({it['decision']})"
    where = f"; screened on {it['screening']}" if it.get("screening") else ""
    return (
        f"Iteration {it['index']}: {what} — training RMSE {fmt(it['train_rmse_before_bar'])} → "
        f"{fmt(it['train_rmse_after_bar'])} bar{where}"
    )


def _md_regions(doc: dict[str, Any]) -> list[str]:
    table = _region_table(doc)
    if table is None:
        return []
    caption, head, rows = table
    body = [[f"`{r[0]}`", *r[1:]] for r in rows]
    return ["## Where the error lies", "", caption, "", _md_table(head, body), ""]


_MODELS_INTRO = (
    "The fitted models of this report, to predict other logs with (`clutchlab predict "
    "models/<variant>.json DATASET --out DIR`) or to export for co-simulation (`clutchlab "
    "export-fmu models/<variant>.json --out model.fmu`) without fitting again."
)


def _models_rows(doc: dict[str, Any]) -> list[list[str]]:
    models = doc.get("models") or {}
    rows = [[n, ", ".join(f)] for n, f in models.get("files", {}).items()]
    rows += [[n, f"not saved: {why}"] for n, why in models.get("not_saved", {}).items()]
    return rows


def _md_models(doc: dict[str, Any]) -> list[str]:
    rows = _models_rows(doc)
    if not rows:
        return []
    body = [[f"`{n}`", _md_text(f)] for n, f in rows]
    return ["## Saved models", "", _MODELS_INTRO, "", _md_table(["variant", "files"], body), ""]


def _html_models(doc: dict[str, Any]) -> list[str]:
    rows = _models_rows(doc)
    if not rows:
        return []
    intro = _e(_MODELS_INTRO).replace("`", "")
    return ["<h2>Saved models</h2>", f"<p>{intro}</p>", _html_rows(["variant", "files"], rows)]


def render_markdown(doc: dict[str, Any], figure_files: list[tuple[str, str, str]]) -> str:
    """The Markdown summary of a report document.

    Parameters
    ----------
    doc : dict
        The ``metrics.json`` document (JSON-safe).
    figure_files : list of (title, relative path, caption)
        Figures written beside the report.

    Returns
    -------
    str
    """
    split, data = doc["split"], doc["dataset"]
    out = [
        "# clutchlab validation report",
        "",
        f"Command: {_md_code(doc['command'])}  ",
        f"Created {doc['created_utc']} · clutchlab {doc['versions']['clutchlab']} · "
        f"total {fmt(doc['timings'].get('total_s', doc['timings'].get('evaluate_s')))} s",
        "",
        f"Dataset: {data['experiments']} experiments ({_md_text(data['root'] or 'in memory')}"
        f"{_md_text(_maps_text(data))}); "
        f"train = {_md_text(', '.join(split['train_ramps']))} "
        f"({_md_text(_experiments(split['train']))}), "
        f"test = {_md_text(', '.join(split['test_ramps']))} "
        f"({_md_text(_experiments(split['test']))}; never used for fitting or model "
        "selection).",
        "",
    ]
    if rate := _rate_note(split):
        out += [f"**Extrapolation in ramp rate:** {_md_text(rate)}", ""]
    if notes := _data_notes(data):
        out.append("**Notes on the data** (as `clutchlab data check` gives them):")
        out += [f"- {_md_text(name)}: {_md_text(note)}" for name, note in notes]
        out.append("")
    if doc["failed"] or doc["unavailable"]:
        out.append("**Not in this report:**")
        out += [f"- `{n}` failed: {_md_text(why)}" for n, why in doc["failed"].items()]
        out += [f"- `{n}` not available: {_md_text(why)}" for n, why in doc["unavailable"].items()]
        out.append("")
    out += [
        f"## Variants on the {_test_ramps(doc)} ({_signal(doc)})",
        "",
        *(
            [_md_text(note), ""]
            if (note := averaging_note(doc.get("averaging"), "test experiment"))
            else []
        ),
        _md_metrics(doc["variants"], METRIC_KEYS),
        "",
        *_md_regions(doc),
        "## Raw signal (secondary)",
        "",
        _md_metrics(doc["raw"], ACCURACY_KEYS),
        "",
        *(
            _describe(n, d, html_=False, fit=doc.get("physics_fit"))
            for n, d in doc["details"].items()
        ),
        "",
    ]
    fit = doc.get("physics_fit")
    if fit:
        out += [
            "## Fitted physics parameters",
            "",
            _fit_status(fit),
            "",
            _md_table(*_parameter_table(fit, lambda n: f"`{n}`")),
            "",
        ]
    clf = doc.get("classifier_comparison")
    if clf:
        out += [
            "## Latch classifiers (leave-one-experiment-out on the training experiments)",
            "",
            _md_table(*_classifier_table(clf)),
            "",
        ]
    disc = doc.get("discovery")
    if disc:
        out += ["## Closing the loop (augmented_hybrid)", "", _md_text(_discovery_intro(disc)), ""]
        for it in disc["iterations"]:
            out += [f"**{_md_text(_discovery_title(it))}**", ""]
            if it["candidates"]:
                out += [_md_table(_DISCOVERY_HEAD, _discovery_rows(it)), ""]
    out += _md_models(doc)
    out += ["## Figures", ""]
    for title, rel, caption in figure_files:
        out += [f"### {title}", "", f"![{title}]({rel})", "", caption, ""]
    for key, why in doc.get("figures", {}).get("missing", {}).items():
        out += [f"- figure `{key}` not drawn: {why}"]
    out += ["", *_md_per_experiment(doc)]
    out += [
        "## Timings (s)",
        "",
        _md_table(["stage", "wall (s)"], [[k, fmt(v)] for k, v in doc["timings"].items()]),
        "",
        "## Versions",
        "",
        _md_table(["component", "version"], [[k, v] for k, v in doc["versions"].items()]),
        "",
        "## Metric definitions",
        "",
        _definitions(doc, _md_text),
        "",
    ]
    return "\n".join(out)


# ---- HTML -------------------------------------------------------------------------------------

_CSS = """
body{font-family:system-ui,sans-serif;max-width:1100px;margin:1.5em auto;padding:0 1em;
color:#222}
table{border-collapse:collapse;margin:.6em 0;font-size:.9em}
th,td{border:1px solid #ccc;padding:.25em .55em;text-align:right}
th{background:#f2f2f2} td.name,th.name{text-align:left}
td.best{font-weight:bold;background:#e8f5e9}
code{background:#f4f4f4;padding:0 .2em}
.warn{background:#fff3e0;border-left:4px solid #fb8c00;padding:.5em 1em}
figure{margin:1.2em 0} figure img{max-width:100%;border:1px solid #ddd}
figcaption{font-size:.9em;color:#555}
.note{font-size:.85em;color:#555}
figure .plotly-graph-div{border:1px solid #ddd}
"""


def _e(x: Any) -> str:
    return html.escape(str(x))


def _html_metrics(rows: dict[str, dict[str, Any]], keys: tuple[str, ...], table: str) -> str:
    best = {k: _best(rows, k) for k in keys}
    head = "".join(f"<th>{_e(_head(k))}</th>" for k in keys)
    body = []
    for name, r in rows.items():
        cells = []
        for k in keys:
            v = r.get(k)
            cls = ' class="best"' if best[k] == name else ""
            cells.append(
                f'<td{cls} data-table="{table}" data-variant="{_e(name)}" data-metric="{k}" '
                f'data-value="{_e(json.dumps(v))}">{_e(fmt(v))}</td>'
            )
        body.append(f'<tr><td class="name"><code>{_e(name)}</code></td>{"".join(cells)}</tr>')
    return (
        f'<table id="{table}"><tr><th class="name">variant</th>{head}</tr>'
        + "".join(body)
        + "</table>"
    )


def _describe(name: str, d: dict[str, Any], html_: bool, fit: dict[str, Any] | None = None) -> str:
    """One variant's line under the tables: what it is and what its fit decided. ``fit``
    is the physics fit (``physics_fit``): a physics_fitted that stopped at a limit is
    flagged here, beside its scores, not only under "Fitted physics parameters"."""
    text = d["description"]
    if fit and not fit.get("converged", True):
        stopped = f"({fit.get('status')}, {fit.get('iterations')} iterations)"
        if name == "physics_fitted":
            text += (
                f"; its fit did NOT converge {stopped}: the scores above are its best "
                "iterate's (see Fitted physics parameters)"
            )
        elif "physics_fitted" in d.get("requires", ()):
            text += f"; built on physics_fitted, whose fit did NOT converge {stopped}"
    if d.get("classifier_accuracy") is not None:
        text += (
            "; latch-classifier accuracy on the test experiments "
            f"{fmt(d['classifier_accuracy'])} (fraction of samples)"
        )
    if d.get("latch_decision"):
        text += f"; latch decision: {d['latch_decision']}"
    if d.get("residual_form"):
        scores = d.get("residual_form_loeo_rmse_bar") or {}
        why = ", ".join(f"{k} {fmt(v)} bar" for k, v in scores.items())
        text += f"; form: {d['residual_form']}" + (
            f" (leave-one-experiment-out RMSE on the training ramps: {why})" if why else ""
        )
    cov = d.get("coverage_2sigma") or {}
    if cov:
        on = d.get("coverage_experiments") or []
        text += (
            "; ±2σ coverage"
            + (f" ({', '.join(on)})" if on else "")
            + " "
            + ", ".join(
                f"{k.replace('_', ' ')} {100 * v:.0f} %" for k, v in cov.items() if v is not None
            )
        )
    if d.get("gp_at_bounds"):
        text += "; GP hyperparameters on a bound of their range: " + "; ".join(d["gp_at_bounds"])
    if html_:
        return f"<code>{_e(name)}</code>: {_e(text)}<br>"
    return f"- `{name}`: {text}"


def _html_rows(header: list[str], rows: list[list[Any]]) -> str:
    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    body = "".join(
        "<tr>"
        + "".join(
            f'<td class="name">{_e(c)}</td>' if j == 0 else f"<td>{_e(c)}</td>"
            for j, c in enumerate(r)
        )
        + "</tr>"
        for r in rows
    )
    return f"<table><tr>{head}</tr>{body}</table>"


def _html_regions(doc: dict[str, Any]) -> str:
    table = _region_table(doc)
    if table is None:
        return ""
    caption, head, rows = table
    return f"<h3>Where the error lies</h3><p>{_e(caption)}</p>" + _html_rows(head, rows)


#: Columns of the per-test-experiment tables: key of ``per_experiment`` and heading.
_PER_EXPERIMENT = (
    ("rmse_bar", "RMSE (bar)"),
    ("hysteresis_width_err_bar", "hysteresis width err (bar)"),
    ("latch_on_measured_mA", "latch-on measured (mA)"),
    ("latch_on_predicted_mA", "latch-on predicted (mA)"),
    ("latch_off_measured_mA", "latch-off measured (mA)"),
    ("latch_off_predicted_mA", "latch-off predicted (mA)"),
)


def _per_experiment_tables(doc: dict[str, Any]) -> list[tuple[str, list[str], list[list[str]]]]:
    """Per variant: its name, the header and one row per test experiment (primary signal)."""
    head = ["experiment", *(h for _, h in _PER_EXPERIMENT)]
    return [
        (
            name,
            head,
            [
                [exp, *(fmt(v["period_mean"].get(k)) for k, _ in _PER_EXPERIMENT)]
                for exp, v in per.items()
            ],
        )
        for name, per in doc["per_experiment"].items()
    ]


def _per_experiment_html(doc: dict[str, Any]) -> str:
    return "".join(
        f"<h4><code>{_e(name)}</code></h4>" + _html_rows(head, rows)
        for name, head, rows in _per_experiment_tables(doc)
    )


def _md_per_experiment(doc: dict[str, Any]) -> list[str]:
    """The per-test-experiment tables (latch currents measured and predicted, mA) and the
    dataset's signals and sample rates, which only the HTML report had."""
    out = [f"## Per test experiment ({_signal(doc)})", ""]
    for name, head, rows in _per_experiment_tables(doc):
        out += [
            f"**`{name}`**",
            "",
            _md_table(head, [[html.escape(c, quote=False) for c in r] for r in rows]),
            "",
        ]
    data = doc["dataset"]
    out += [
        "## Dataset",
        "",
        f"Signals: {_md_text(', '.join(data['signals']))}; sample rate(s) "
        f"{', '.join(fmt(r) for r in data['sample_rate_Hz'])} Hz.",
        "",
    ]
    return out


def render_html(
    doc: dict[str, Any],
    figures: list[tuple[FigureSpec, bytes]],
    interactive: Mapping[str, Any] | None = None,
) -> str:
    """The self-contained HTML report: interactive Plotly figures, the others as PNG.

    Parameters
    ----------
    doc : dict
        The ``metrics.json`` document (JSON-safe).
    figures : list of (FigureSpec, bytes)
        Each figure with its PNG bytes.
    interactive : mapping of str to plotly.graph_objects.Figure, optional
        Figure key → interactive form (:func:`~clutchlab.validation.interactive.
        interactive_figures`); such a figure is drawn by plotly.js (embedded once, inline)
        instead of its PNG. None or empty: every figure as PNG, no JavaScript library.

    Returns
    -------
    str
    """
    interactive = dict(interactive or {})
    split, data, t = doc["split"], doc["dataset"], doc["timings"]
    total = t.get("total_s", t.get("evaluate_s"))
    drawn = {spec.key for spec, _ in figures}
    plotly_js = ""
    if any(k in drawn for k in interactive):
        from .interactive import plotlyjs_script

        plotly_js = plotlyjs_script()
    s = [
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>",
        "<title>clutchlab validation report</title>",
        f"<style>{_CSS}</style>{plotly_js}</head><body>",
        "<h1>clutchlab validation report</h1>",
        f"<p>Command: <code id='command'>{_e(doc['command'])}</code><br>",
        f"Created {_e(doc['created_utc'])} · clutchlab {_e(doc['versions']['clutchlab'])} · "
        f"total {_e(fmt(total))} s</p>",
        f"<p>Dataset: {data['experiments']} experiments "
        f"(<code>{_e(data['root'] or 'in memory')}</code>{_e(_maps_text(data))}), "
        f"{data['samples']} samples, "
        f"{_e(fmt(data['duration_s']))} s. Train ramps: <b>{_e(', '.join(split['train_ramps']))}"
        f"</b> ({_e(_experiments(split['train']))}); test ramps: "
        f"<b>{_e(', '.join(split['test_ramps']))}</b> ({_e(_experiments(split['test']))}) — "
        "never used for fitting or model selection; models see only their inputs.</p>",
    ]
    if rate := _rate_note(split):
        s.append(f"<div class='warn'><b>Extrapolation in ramp rate:</b> {_e(rate)}</div>")
    if notes := _data_notes(data):
        items = "".join(f"<li>{_e(name)}: {_e(note)}</li>" for name, note in notes)
        s.append(
            "<div class='warn'><b>Notes on the data</b> (as <code>clutchlab data check</code> "
            f"gives them)<ul>{items}</ul></div>"
        )
    if doc["failed"] or doc["unavailable"]:
        items = [f"<li><code>{_e(n)}</code> failed: {_e(w)}</li>" for n, w in doc["failed"].items()]
        items += [
            f"<li><code>{_e(n)}</code> not available: {_e(w)}</li>"
            for n, w in doc["unavailable"].items()
        ]
        s.append(f"<div class='warn'><b>Not in this report</b><ul>{''.join(items)}</ul></div>")
    s += [
        f"<h2>Variants on the {_e(_test_ramps(doc))} — {_e(_signal(doc))} (primary)</h2>",
        *(
            [f"<p class='note'>{_e(note)}</p>"]
            if (note := averaging_note(doc.get("averaging"), "test experiment"))
            else []
        ),
        _html_metrics(doc["variants"], METRIC_KEYS, "variants"),
        _html_regions(doc),
        "<h3>Raw signal (secondary)</h3>",
        _html_metrics(doc["raw"], ACCURACY_KEYS, "raw"),
        "<p>"
        + "".join(
            _describe(n, d, html_=True, fit=doc.get("physics_fit"))
            for n, d in doc["details"].items()
        )
        + "</p>",
    ]
    fit = doc.get("physics_fit")
    if fit:
        s += [
            "<h2>Fitted physics parameters</h2>",
            f"<p>{_e(_fit_status(fit))}</p>",
            _html_rows(*_parameter_table(fit, str)),
        ]
    clf = doc.get("classifier_comparison")
    if clf:
        s += [
            "<h2>Latch classifiers</h2>",
            "<p>Leave-one-experiment-out accuracy on the training experiments (latch-event "
            f"samples excluded); inputs: {_e(', '.join(clf['features']))}.</p>",
            _html_rows(*_classifier_table(clf)),
        ]
    disc = doc.get("discovery")
    if disc:
        s += [
            "<h2>Closing the loop (augmented_hybrid)</h2>",
            f"<p>{_e(_discovery_intro(disc))}</p>",
        ]
        for it in disc["iterations"]:
            s.append(f"<h3>{_e(_discovery_title(it))}</h3>")
            if it["candidates"]:
                s.append(_html_rows(_DISCOVERY_HEAD, _discovery_rows(it)))
    s += _html_models(doc)
    s.append("<h2>Figures</h2>")
    if plotly_js:
        s.append(
            "<p class='note'>Interactive figures: drag to zoom, double-click to reset, hover "
            "for values; click a legend entry to hide or show that variant, double-click it "
            "to show it alone.</p>"
        )
    for spec, png in figures:
        if spec.key in interactive:
            from .interactive import figure_div

            body = figure_div(interactive[spec.key], f"plot-{spec.key}")
        else:
            b64 = base64.b64encode(png).decode("ascii")
            body = f"<img alt='{_e(spec.title)}' src='data:image/png;base64,{b64}'>"
        s.append(
            f"<figure id='fig-{spec.key}'><h3>{_e(spec.title)}</h3>{body}"
            f"<figcaption>{_e(spec.caption)}</figcaption></figure>"
        )
    for key, why in doc.get("figures", {}).get("missing", {}).items():
        s.append(f"<p>Figure <code>{_e(key)}</code> not drawn: {_e(why)}.</p>")
    s += [
        f"<h2>Per test experiment ({_e(_signal(doc))})</h2>",
        "<details><summary>show</summary>",
        _per_experiment_html(doc),
        "</details>",
        "<h2>Dataset</h2>",
        f"<p>Signals: {_e(', '.join(data['signals']))}; sample rate(s) "
        f"{_e(', '.join(fmt(r) for r in data['sample_rate_Hz']))} Hz.</p>",
        "<details><summary>experiments</summary>",
        _html_rows(
            ["experiment", "ramp", "samples", "duration (s)", "metadata"],
            [
                [
                    r["name"],
                    r["ramp"],
                    r["samples"],
                    fmt(r["duration_s"]),
                    ", ".join(
                        f"{k}={v}"
                        for k, v in r.items()
                        if k not in ("name", "ramp", "samples", "duration_s")
                    ),
                ]
                for r in data["table"]
            ],
        ),
        "</details>",
        "<h2>Timings</h2>",
        _html_rows(["stage", "wall (s)"], [[k, fmt(v)] for k, v in t.items()]),
        "<h2>Versions</h2>",
        _html_rows(["component", "version"], [[k, v] for k, v in doc["versions"].items()]),
        "<h2>Metric definitions</h2>",
        f"<p>{_e(_definitions(doc))}</p>",
        _MARKER,
        "</body></html>",
    ]
    return "\n".join(s)


# ---- CSV / JSON -------------------------------------------------------------------------------


def metrics_csv(doc: dict[str, Any]) -> str:
    """One row per variant and signal kind; columns the metric keys (units in the names) and,
    last, ``averaged_over``: what the row's signal is averaged over (the ``period_mean`` rows
    of a log without dither are its raw signal, and this column says so)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["variant", "signal", *METRIC_KEYS, "averaged_over"])
    primary = _signal(doc)
    for name, row in doc["variants"].items():
        values = (_csv_value(row.get(k)) for k in METRIC_KEYS)
        w.writerow([name, "period_mean", *values, primary])
        raw = doc["raw"].get(name, {})
        w.writerow([name, "raw", *(_csv_value(raw.get(k)) for k in METRIC_KEYS), "nothing (raw)"])
    return buf.getvalue()


def _csv_value(v: Any) -> str:
    return "" if v is None else repr(v) if isinstance(v, float) else str(v)


def _json_text(doc: dict[str, Any]) -> str:
    return json.dumps(doc, indent=2, ensure_ascii=False, allow_nan=False) + "\n"


def write_json(doc: dict[str, Any], path: str | Path) -> Path:
    """Write a report document as strict JSON, atomically.

    Parameters
    ----------
    doc : dict
        JSON-safe document (:func:`jsonable`).
    path : path
        Destination file.

    Returns
    -------
    Path
    """
    return write_file_atomic(path, _json_text(doc).encode("utf-8"), overwrite=True)


# ---- writing ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class ReportFiles:
    """Where a report was written.

    Attributes
    ----------
    folder, html, markdown, json, csv : Path
        The report folder, ``report.html``, ``report.md``, ``metrics.json``, ``metrics.csv``.
    figures : tuple of Path
        ``figures/<key>.png``.
    doc : dict
        The document written as ``metrics.json``.
    """

    folder: Path
    html: Path
    markdown: Path
    json: Path
    csv: Path
    figures: tuple[Path, ...]
    doc: dict


def _png(fig: Any) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


def write_report(ev: Evaluation, out: str | Path, interactive: bool = True) -> ReportFiles:
    """Render and write the report of an evaluation into the folder ``out``.

    Parameters
    ----------
    ev : Evaluation
        The scored variants.
    out : path
        Report folder (created). Written in one atomic step: the files of an earlier report
        are replaced, every file clutchlab did not write (cached stand data, notes) is kept,
        and one in the way of a report file is an error (``OutputError``, nothing written).
    interactive : bool
        Draw the figures of ``report.html`` with Plotly (zoom, hover, variants toggled from
        the legend; plotly.js embedded, so the page works offline) where an interactive form
        exists (:mod:`~clutchlab.validation.interactive`); False: every figure as PNG. The
        PNGs in ``figures/`` (used by ``report.md``) are written either way.

    Returns
    -------
    ReportFiles
    """
    out = Path(out)
    figures, missing = report_figures(ev)
    doc = ev.to_dict()
    doc["figures"] = {"drawn": [f.key for f in figures], "missing": missing}
    saved, not_saved = model_files(ev.models)
    doc["models"] = {
        "files": {n: sorted(files) for n, files in saved.items()},
        "not_saved": not_saved,
    }
    doc = jsonable(doc)
    json.loads(_json_text(doc))  # strict JSON before anything is written
    pngs = [(spec, _png(spec.figure)) for spec in figures]
    rel = [(spec.title, f"figures/{spec.key}.png", spec.caption) for spec, _ in pngs]
    files: dict[str, bytes] = {f"figures/{spec.key}.png": png for spec, png in pngs}
    for variant_files in saved.values():
        files |= variant_files
    files["metrics.csv"] = metrics_csv(doc).encode("utf-8")
    files["report.md"] = render_markdown(doc, rel).encode("utf-8")
    iplots = interactive_figures(ev, [spec.key for spec in figures]) if interactive else {}
    files["report.html"] = render_html(doc, pngs, iplots).encode("utf-8")
    files["metrics.json"] = _json_text(doc).encode("utf-8")  # last: its presence = complete
    # One atomic swap of the whole folder: a kill leaves the old report or the new one; a
    # user's file in the way is refused, every other file (cached stand data) is kept, and
    # figures of an earlier report that this one does not draw go.
    write_folder_atomic(out, files, overwrite=True, what=REPORT_FOLDER)
    return ReportFiles(
        folder=out,
        html=out / "report.html",
        markdown=out / "report.md",
        json=out / "metrics.json",
        csv=out / "metrics.csv",
        figures=tuple(out / name for name in files if name.startswith("figures/")),
        doc=doc,
    )
