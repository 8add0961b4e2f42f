"""The comparison report on a tiny stand: metrics.json complete and finite, the HTML, Markdown
and CSV numbers equal to it, figures embedded, atomic writing, and ``clutchlab evaluate`` on a
dataset that the stand code did not write (Parquet, renamed channels, other units, a map).
"""

from __future__ import annotations

import base64
import csv
import dataclasses
import io
import json
import math
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from clutchlab.data import load_dataset, nominal_current, save_dataset
from clutchlab.physics.fit import FitSettings
from clutchlab.physics.stand import DEFAULT_SETTINGS, StandConfig, run_stand
from clutchlab.physics.stand.scenarios import RampProfile
from clutchlab.validation import (
    ACCURACY_KEYS,
    METRIC_KEYS,
    VariantSpec,
    evaluate,
    fmt,
    register_variant,
    write_report,
)
from clutchlab.validation import report as report_module
from clutchlab.validation import variants as variants_module

TINY_RAMPS = (
    RampProfile("fast", 0.8, 0.3),
    RampProfile("medium", 1.6, 0.3),
    RampProfile("slow", 3.2, 0.3),
)
FAST_FIT = FitSettings(max_iter=3, workers=1, prefit_samples=None, progress=False)


class Lookup:
    """Test double with a predictive std: mean training pressure per 25 mA current bin."""

    def fit(self, traces):
        i = np.concatenate([nominal_current(t) for t in traces])
        p = np.concatenate([t.get("clutch_pressure_bar") for t in traces])
        k = np.clip((i // 25).astype(int), 0, 44)
        self.table_ = np.array([p[k == j].mean() if (k == j).any() else 0.0 for j in range(45)])
        self.train_experiments_ = [t.name for t in traces]
        return self

    def predict(self, trace, return_std=False):
        k = np.clip((nominal_current(trace) // 25).astype(int), 0, 44)
        mean = self.table_[k]
        return (mean, np.full(mean.shape, 0.5)) if return_std else mean


# ---- report consistency checks (also used by the slow demo test) -----------------------------


class _Cells(HTMLParser):
    """Metric cells of the report's tables, the embedded images and the interactive plots."""

    def __init__(self):
        super().__init__()
        self.cells, self.images, self.plots, self._cell = {}, [], [], None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "td" and "data-metric" in a:
            self._cell = (a["data-table"], a["data-variant"], a["data-metric"], a["data-value"])
            self.cells[self._cell[:3]] = [a["data-value"], ""]
        elif tag == "img":
            self.images.append(a.get("src", ""))
        elif tag == "div" and "plotly-graph-div" in (a.get("class") or "").split():
            self.plots.append(a.get("id", ""))

    def handle_data(self, data):
        if self._cell is not None:
            self.cells[self._cell[:3]][1] += data

    def handle_endtag(self, tag):
        if tag == "td":
            self._cell = None


def check_report(folder: Path) -> dict:
    """Every variant and metric present and finite in metrics.json; the report's numbers
    (HTML cells, Markdown tables, CSV) equal to metrics.json. Returns the document."""
    doc = json.loads((folder / "metrics.json").read_text(encoding="utf-8"))
    assert doc["variants"], "no variant scored"
    for name, row in doc["variants"].items():
        assert list(row) == list(METRIC_KEYS), name
        for key in METRIC_KEYS:
            assert row[key] is not None and math.isfinite(row[key]), (name, key)
        for key in ACCURACY_KEYS:
            assert doc["raw"][name][key] is not None and math.isfinite(doc["raw"][name][key])
    html = (folder / "report.html").read_text(encoding="utf-8")
    parser = _Cells()
    parser.feed(html)
    for table, keys in (("variants", METRIC_KEYS), ("raw", ACCURACY_KEYS)):
        for name, row in doc[table].items():
            for key in keys:
                exact, shown = parser.cells[(table, name, key)]
                assert json.loads(exact) == row[key], (table, name, key)
                assert shown == fmt(row[key]), (table, name, key)
    assert len(parser.cells) == len(doc["variants"]) * (len(METRIC_KEYS) + len(ACCURACY_KEYS))
    md = (folder / "report.md").read_text(encoding="utf-8")
    for table, heading, keys in (
        ("variants", "## Variants on the test ramp", METRIC_KEYS),
        ("raw", "## Raw signal", ACCURACY_KEYS),
    ):
        rows = _md_table(md, heading)
        assert list(rows) == list(doc[table]), table
        for name, row in doc[table].items():
            assert rows[name] == [fmt(row[k]) for k in keys], (table, name)
    with open(folder / "metrics.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2 * len(doc["variants"])
    for r in rows:
        src = doc["variants" if r["signal"] == "period_mean" else "raw"][r["variant"]]
        for key in ACCURACY_KEYS:
            assert float(r[key]) == src[key]
    # Every drawn figure is an interactive plot or an embedded PNG; plotly.js is inline, once;
    # nothing is loaded from outside the file.
    drawn = doc["figures"]["drawn"]
    assert len(parser.images) + len(parser.plots) == len(drawn) > 0
    assert parser.plots == [f"plot-{k}" for k in drawn if f"plot-{k}" in parser.plots]
    if parser.plots:
        assert html.count("Plotly.newPlot(") >= len(parser.plots)
        assert html.count("* plotly.js v") == 1  # the library, embedded once
    for src in parser.images:
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
    # (Outside the inline scripts: plotly.js holds URLs of map tiles it never loads here;
    # the headless-Chromium test runs the page with the network disabled.)
    markup = re.sub(r"<script>.*?</script>", "<script></script>", html, flags=re.S)
    assert not re.search(r"<script[^>]*\ssrc=", markup)
    assert not re.search(r"(src|href)=['\"](?!data:|#)", markup)
    for key in doc["figures"]["drawn"]:
        assert (folder / "figures" / f"{key}.png").stat().st_size > 1000
    return doc


def _md_table(md: str, heading: str) -> dict[str, list[str]]:
    """Rows of the Markdown table under ``heading``: variant → cell texts (bold removed)."""
    lines = md.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith(heading))
    rows = {}
    for ln in lines[k + 1 :]:
        if ln.startswith("## "):
            break
        if ln.startswith("| `"):
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", ln.strip())[1:-1]]
            rows[cells[0].strip("`")] = [c.strip("*") for c in cells[1:]]
    return rows


# ---- fixtures --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny():
    return run_stand(
        StandConfig(settings=DEFAULT_SETTINGS[::4][:2], ramps=TINY_RAMPS), progress=False
    ).dataset


@pytest.fixture(scope="module")
def evaluation(tiny):
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(variants_module, "_REGISTRY", dict(variants_module._REGISTRY))
        register_variant(VariantSpec("lookup", "test double with a std", lambda c: Lookup()))
        return evaluate(
            tiny,
            ["physics_default", "physics_fitted", "lookup"],
            physics_settings=FAST_FIT,
            progress=False,
            command="pytest evaluation",
        )


@pytest.fixture(scope="module")
def report(evaluation, tmp_path_factory):
    return write_report(evaluation, tmp_path_factory.mktemp("rep") / "report")


# ---- tests -----------------------------------------------------------------------------------


def test_metrics_json_complete_and_report_numbers_equal(report):
    doc = check_report(report.folder)
    assert list(doc["variants"]) == ["physics_default", "physics_fitted", "lookup"]
    assert doc["split"]["test"] == ["medium_30Hz_A", "medium_50Hz_B"]
    assert not set(doc["split"]["train"]) & set(doc["split"]["test"])
    assert doc["command"] == "pytest evaluation"
    assert {"clutchlab", "python", "numpy", "casadi"} <= set(doc["versions"])
    assert doc["details"]["lookup"]["uncertainty"] is True
    assert set(doc["figures"]["drawn"]) >= {
        "prediction_vs_time",
        "pressure_vs_current",
        "hysteresis_bands",
        "residuals",
        "uncertainty",
    }


def test_fitted_physics_beats_the_datasheet_and_its_parameters_are_reported(report):
    doc = report.doc
    default, fitted = doc["variants"]["physics_default"], doc["variants"]["physics_fitted"]
    assert fitted["rmse_bar"] < 0.5 * default["rmse_bar"]
    assert fitted["fit_s"] > 0 and default["fit_s"] < 0.1
    fit = doc["physics_fit"]
    assert fit["parameters"] and all(
        math.isfinite(p["value"]) and p["std_error"] is not None for p in fit["parameters"].values()
    )
    html = report.html.read_text(encoding="utf-8")
    assert "Fitted physics parameters" in html
    for name, p in fit["parameters"].items():
        assert f"<td>{fmt(p['value'])}</td><td>{fmt(p['std_error'])}</td>" in html, name


def test_rewrite_keeps_other_files_and_a_failure_writes_nothing(evaluation, tmp_path, monkeypatch):
    # PNG rendering is not what this test is about: skip its cost.
    monkeypatch.setattr(report_module, "_png", lambda fig: b"\x89PNG\r\n\x1a\n")
    out = tmp_path / "demo"
    (out / "stand_data").mkdir(parents=True)
    (out / "stand_data" / "manifest.json").write_text("{}")
    write_report(evaluation, out)
    assert (out / "stand_data" / "manifest.json").read_text() == "{}"
    before = (out / "metrics.json").read_bytes()

    def boom(*args, **kwargs):
        raise RuntimeError("rendering failed")

    monkeypatch.setattr(report_module, "render_html", boom)
    with pytest.raises(RuntimeError):
        write_report(evaluation, out)
    with pytest.raises(RuntimeError):
        write_report(evaluation, tmp_path / "fresh")
    assert (out / "metrics.json").read_bytes() == before
    assert not (tmp_path / "fresh").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_evaluate_cli_on_parquet_with_renamed_channels(tiny, tmp_path):
    """Issue 6 must-show 4: a dataset not written by the stand code path of this process."""
    pq = tmp_path / "logs"
    pq.mkdir()
    entries = []
    one_setting = tiny.select(names=[t.name for t in tiny if t.name.endswith("30Hz_A")])
    for trace in one_setting:
        df = trace.to_pandas()
        df = df.rename(
            columns={
                "time_s": "Time",
                "current_mA": "I_VFS",
                "current_cmd_mA": "I_cmd",
                "clutch_pressure_bar": "P_clutch",
                "line_pressure_bar": "P_line",
                "prime_pressure_bar": "P_prime",
                "oil_temp_C": "T_oil",
                "dither_amp_mA": "Dither_amp",
                "dither_freq_Hz": "Dither_freq",
            }
        )
        df["Time"] *= 1000.0  # ms
        df["I_VFS"] /= 1000.0  # A
        df["P_clutch"] *= 100.0  # kPa
        df.attrs = {}
        df.to_parquet(pq / f"{trace.name}.parquet")
        entries.append({"file": f"{trace.name}.parquet", **trace.meta})
    (pq / "stand_b.toml").write_text(
        "[signals]\n"
        'time_s = { channel = "Time", unit = "ms" }\n'
        'current_mA = { channel = "I_VFS", unit = "A" }\n'
        'current_cmd_mA = "I_cmd"\n'
        'clutch_pressure_bar = { channel = "P_clutch", unit = "kPa" }\n'
        'line_pressure_bar = "P_line"\n'
        'prime_pressure_bar = "P_prime"\n'
        'oil_temp_C = "T_oil"\n'
        'dither_amp_mA = "Dither_amp"\n'
        'dither_freq_Hz = "Dither_freq"\n'
    )
    (pq / "manifest.json").write_text(
        json.dumps({"channel_map": "stand_b.toml", "experiments": entries})
    )
    exe = shutil.which("clutchlab")
    cmd = [exe] if exe else [sys.executable, "-m", "clutchlab.cli"]
    out, js = tmp_path / "rep", tmp_path / "m.json"
    args = [
        "evaluate",
        str(pq),
        "--out",
        str(out),
        "--variants",
        "physics_default",
        "--no-classifiers",
    ]
    res = subprocess.run(
        [*cmd, *args, "--json", str(js), "--quiet"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().endswith(f"report: {out / 'report.html'}")
    doc = check_report(out)
    # the terminal summary: each variant's RMSE and where its error lies, as in metrics.json
    pm = doc["details"]["physics_default"]["period_mean"]
    line = next(ln for ln in res.stdout.splitlines() if ln.startswith("physics_default"))
    assert line.split()[1:] == [
        f"{doc['variants']['physics_default']['rmse_bar']:.4f}",
        f"{100 * pm['sq_error_share_latch_window']:.0f}",
        "%",
        f"{pm['rmse_regulated_bar']:.4f}",
    ]
    assert json.loads(js.read_text()) == doc
    # how the measured signals were read is in the report (found by session 41's hunt: only
    # the command line said so, and not at all for a manifest's own map)
    assert doc["dataset"]["channel_maps"] == [str(pq / "stand_b.toml")]
    html = (out / "report.html").read_text(encoding="utf-8")
    assert f"read through channel map {pq / 'stand_b.toml'}" in html
    assert doc["command"].startswith("clutchlab evaluate ") and "--variants" in doc["command"]
    # Same numbers as the in-process evaluation of the canonical CSV dataset.
    csv_dir = tmp_path / "csv"
    save_dataset(one_setting, csv_dir)
    ref = evaluate(load_dataset(csv_dir), ["physics_default"], progress=False, bands=False)
    for key in ACCURACY_KEYS:
        assert doc["variants"]["physics_default"][key] == pytest.approx(
            ref.scores["physics_default"].metrics[key], rel=1e-4, abs=1e-4
        )


class FakeComparison:
    """Stands in for residual_ml's ClassifierComparison (that one is tested there)."""

    def to_dict(self):
        rows = {"rbf_svc": ("Nonlinear (RBF) SVC", 0.9987), "lr": ("Logistic regression", 0.98)}
        return {
            "classifiers": {
                n: {"label": lab, "accuracy": a, "min_accuracy": a - 0.01, "fit_s": 0.5}
                for n, (lab, a) in rows.items()
            },
            "features": ["current_mA", "didt_mA_s"],
        }

    def figure(self):
        from matplotlib.figure import Figure

        fig = Figure(figsize=(4, 3))
        fig.subplots().plot([0, 1], [0, 1])
        return fig


def test_classifier_comparison_table_and_figure(evaluation, tmp_path):
    ev = dataclasses.replace(evaluation, classifier_comparison=FakeComparison())
    files = write_report(ev, tmp_path / "rep")
    doc = check_report(files.folder)
    assert doc["classifier_comparison"]["classifiers"]["rbf_svc"]["accuracy"] == 0.9987
    assert doc["figures"]["drawn"][0] == "classifier_comparison"
    html, md = files.html.read_text(), files.markdown.read_text()
    assert '<td class="name">Nonlinear (RBF) SVC</td><td>0.9987</td>' in html
    assert "| Nonlinear (RBF) SVC | 0.9987 |" in md


def test_markdown_tables_escape_pipes_and_render_as_tables(report):
    md = report.markdown.read_text(encoding="utf-8")
    header = next(ln for ln in md.splitlines() if ln.startswith("| variant |"))
    assert "max \\|e\\| (bar)" in header
    assert header.count("|") - header.count("\\|") == len(METRIC_KEYS) + 2
    assert io.StringIO(md).read().count("![") == len(report.doc["figures"]["drawn"])


def test_the_report_says_where_each_variants_error_lies(report):
    """The region table (Markdown and HTML) shows each variant's RMSE and share of the
    squared error per region, equal to metrics.json; the shares add up to one."""
    doc = json.loads((report.folder / "metrics.json").read_text(encoding="utf-8"))
    md = (report.folder / "report.md").read_text(encoding="utf-8")
    rows = _md_table(md, "## Where the error lies")
    assert list(rows) == list(doc["variants"])
    regions = ("regulated", "latched", "latch_window")
    for name, cells in rows.items():
        pm = doc["details"][name]["period_mean"]
        expected = []
        for r in regions:
            expected += [fmt(pm[f"rmse_{r}_bar"]), f"{100 * pm[f'sq_error_share_{r}']:.0f} %"]
        assert cells == expected, name
        assert sum(pm[f"sq_error_share_{r}"] for r in regions) == pytest.approx(1.0)
        assert sum(pm[f"samples_share_{r}"] for r in regions) == pytest.approx(1.0)
        # the pooled RMSE is the regions' RMSEs weighted by their samples
        ms = sum(pm[f"samples_share_{r}"] * pm[f"rmse_{r}_bar"] ** 2 for r in regions)
        assert math.sqrt(ms) == pytest.approx(doc["variants"][name]["rmse_bar"], rel=1e-9)
    html = (report.folder / "report.html").read_text(encoding="utf-8")
    assert "<h3>Where the error lies</h3>" in html
    assert "% of the samples" in md and "latch window: within 0.15 s" in md


def test_the_report_gives_the_true_reason_for_a_missing_classifier_figure(report, evaluation):
    """It said the installation provides no comparison whenever the figure was missing."""
    md = report.markdown.read_text(encoding="utf-8")
    assert (
        "figure `classifier_comparison` not drawn: the comparison was not run: no "
        "paper-pipeline (ML) variant was evaluated" in md
    )
    failed = dataclasses.replace(
        evaluation, failed={**evaluation.failed, "classifier_comparison": "ValueError: boom"}
    )
    from clutchlab.validation.figures import report_figures

    assert "failed (ValueError: boom)" in report_figures(failed)[1]["classifier_comparison"]
