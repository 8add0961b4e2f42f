"""What the report calls its primary scores is what they are: a log without a dither has a
one-sample "dither-period mean" (its raw signal), and the report, its figures and
``clutchlab predict`` say so instead of calling it a dither-period mean.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import pandas as pd
import pytest

from clutchlab.data import load_dataset, save_dataset
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand
from clutchlab.validation import evaluate, fmt, report_figures, write_report
from clutchlab.validation.report import summary_lines

RAMPS = (RampProfile("fast", 1.0, 0.2), RampProfile("medium", 2.0, 0.2))


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """The same short stand runs twice: as logged (50 Hz dither), and as a user's log without
    a dither (commanded current only, no dither columns, nothing in the manifest)."""
    root = tmp_path_factory.mktemp("avg")
    run = run_stand(StandConfig(settings=(DitherSetting(50.0, "A"),), ramps=RAMPS), progress=False)
    dithered = save_dataset(run.dataset, root / "dithered")
    plain = root / "plain"
    plain.mkdir()
    experiments = []
    for entry in json.loads((dithered / "manifest.json").read_text())["experiments"]:
        frame = pd.read_csv(dithered / entry["file"])
        frame = frame.drop(columns=["current_mA", "dither_amp_mA", "dither_freq_Hz"])
        frame.to_csv(plain / entry["file"], index=False)
        experiments.append({"file": entry["file"], "ramp": entry["ramp"]})
    (plain / "manifest.json").write_text(json.dumps({"experiments": experiments}))
    return dithered, plain


def _report(folder: Path, out: Path):
    ev = evaluate(
        load_dataset(folder), ["physics_default"], train=["fast"], test=["medium"], progress=False
    )
    return ev, write_report(ev, out, interactive=False)


def test_a_log_without_dither_is_not_called_a_dither_period_mean(folders, tmp_path):
    ev, files = _report(folders[1], tmp_path / "plain")
    (name,) = ev.protocol.test_names
    window = files.doc["averaging"][name]
    assert window["samples"] == 1.0 and window["kind"] == "none"
    assert window["dither_freq_Hz"] is None
    # the primary and raw scores are then the same numbers
    assert files.doc["variants"]["physics_default"]["rmse_bar"] == pytest.approx(
        files.doc["raw"]["physics_default"]["rmse_bar"]
    )
    md = files.markdown.read_text(encoding="utf-8")
    html = files.html.read_text(encoding="utf-8")
    for text in (md, html):
        assert "dither-period mean (primary)" not in text
        assert "Variants on the test ramp (dither-period mean)" not in text
        assert "raw signal — no dither to average over" in text
        assert "averaging window is 1 sample" in text
        assert "no test experiment has dither" in text
    assert "Per test experiment (dither-period mean)" not in html
    # what reading the log noticed (printed to the terminal only, before) is in the report
    notes = files.doc["dataset"]["notes"][name]
    assert any(n.startswith("no dither amplitude") for n in notes)
    assert "Notes on the data" in md and "Notes on the data" in html
    assert "the physics model is driven without dither" in html
    figures, _ = report_figures(ev)
    for spec in figures:
        assert "dither-period mean" not in spec.caption, spec.key
        assert "dither-period mean" not in spec.figure.get_suptitle(), spec.key
    labels = {spec.key: spec.figure.axes[0].get_ylabel() for spec in figures}
    assert (
        labels["pressure_vs_current"]
        == "clutch pressure, raw signal — no dither to average over (bar)"
    )
    assert any("averaging window is 1 sample" in line for line in summary_lines(files.doc))
    rows = list(csv.DictReader(io.StringIO((files.folder / "metrics.csv").read_text())))
    said = {r["signal"]: r["averaged_over"] for r in rows}
    assert said == {"period_mean": "raw signal — no dither to average over", "raw": "nothing (raw)"}
    # the interactive (Plotly) figures' axis titles and titles too
    interactive = write_report(ev, tmp_path / "plain_interactive", interactive=True)
    assert "dither-period mean" not in interactive.html.read_text(encoding="utf-8")


def test_a_dithered_log_states_its_averaging_window(folders, tmp_path):
    ev, files = _report(folders[0], tmp_path / "dithered")
    (name,) = ev.protocol.test_names
    window = files.doc["averaging"][name]
    assert window["kind"] == "dither_period"
    assert window["samples"] == pytest.approx(20.0)  # 1 kHz log, 50 Hz dither
    assert window["window_ms"] == pytest.approx(20.0)
    assert window["dither_freq_Hz"] == pytest.approx(50.0)
    md = files.markdown.read_text(encoding="utf-8")
    assert "## Variants on the test ramp (dither-period mean)" in md
    assert "20 ms = 1/50 Hz" in md
    # nothing extra in the terminal summary when the scores are what they are called
    assert not any("Primary signal" in line for line in summary_lines(files.doc))


def test_the_wording_of_each_kind_of_window():
    from clutchlab.validation.averaging import averaging_note, averaging_window, scored_signal

    dithered = averaging_window(33.3333, 1000.0, 100.0)
    silent = averaging_window(20.0, 1000.0, 0.0)  # frequency logged, amplitude 0
    none = averaging_window(1.0, 1000.0, None)
    assert scored_signal(None) == scored_signal({"a": dithered}) == "dither-period mean"
    assert scored_signal({"a": none}) == "raw signal — no dither to average over"
    assert (
        scored_signal({"a": dithered, "b": none}) == "dither-period mean where dithered, else raw"
    )
    assert silent["kind"] == "no_dither_amplitude"
    assert "amplitude 0" in scored_signal({"b": silent})  # no log has a dither
    assert "dither-period" not in scored_signal({"a": dithered, "b": silent})
    note = averaging_note({"a": dithered, "b": silent, "c": none})
    assert "33.3 ms = 1/30 Hz (a)" in note
    assert "b: logged dither amplitude 0 mA" in note and "moving average" in note
    assert "c: no dither" in note and "1 sample" in note
    assert averaging_note(None) == ""
    unknown_rate = averaging_window(20.0, float("nan"), 100.0)  # a reference built by hand
    assert "20 samples" in averaging_note({"a": unknown_rate})


class _Flat:
    """A model that predicts the prime pressure everywhere (bar)."""

    def predict(self, trace):
        return trace.get("clutch_pressure_bar") * 0.0 + 0.5


def test_predict_says_over_what_its_scores_are_averaged(folders):
    from clutchlab.cli_predict import _metrics_csv
    from clutchlab.validation import LoadedModel, predict_traces, prediction_figure

    loaded = LoadedModel(_Flat(), "test double", ())
    for folder, samples, titled in ((folders[0], 20, "dither-period mean"),
                                    (folders[1], 1, "raw signal")):  # fmt: skip
        predictions, _ = predict_traces(loaded, list(load_dataset(folder)))
        rows = list(csv.DictReader(io.StringIO(_metrics_csv(predictions).decode())))
        assert [float(r["window_samples"]) for r in rows] == pytest.approx([samples] * len(rows))
        assert [float(r["window_ms"]) for r in rows] == pytest.approx([samples] * len(rows))
        title = prediction_figure(predictions[0]).get_suptitle()
        assert titled in title
        if samples == 1:
            assert "dither-period" not in title


def test_the_svc_gp_description_does_not_contradict_its_latch_decision(folders, tmp_path):
    """On one training experiment the local latch-event law cannot be fitted and the RBF-SVC
    decides; the report said "latch state from the local latch-event law" beside "latch
    decision: classifier rbf_svc"."""
    ev = evaluate(
        load_dataset(folders[0]), ["paper_svc_gp"], train=["fast"], test=["medium"],
        progress=False, classifiers=False,
    )  # fmt: skip
    details = write_report(ev, tmp_path / "svc", interactive=False).doc["details"]
    d = details["paper_svc_gp"]
    assert d["latch_decision"].startswith("classifier rbf_svc")
    assert not d["description"].startswith("latch state from the local latch-event law")
    assert "RBF-SVC when the training data hold fewer than two latch events" in d["description"]


def test_the_classifier_table_names_its_worst_experiment(folders, tmp_path):
    """The column "worst experiment" held a number (the lowest held-out accuracy), not an
    experiment; the reader could not tell which experiment the classifier got wrong."""
    from clutchlab.validation.report import render_html, render_markdown

    _, files = _report(folders[0], tmp_path / "clf")
    doc = dict(files.doc)
    doc["classifier_comparison"] = {
        "classifiers": {
            "rbf_svc": {
                "label": "Nonlinear (RBF) SVC",
                "accuracy": 0.9987,
                "min_accuracy": 0.9902,
                "fit_s": 0.35,
            },
        },
        "per_experiment": {"rbf_svc": {"fast_30Hz_A": 0.9991, "slow_50Hz_B": 0.9902}},
        "features": ["current_mA", "didt_mA_s"],
        "experiments": ["fast_30Hz_A", "slow_50Hz_B"],
    }
    md, html = render_markdown(doc, []), render_html(doc, [])
    for text in (md, html):
        assert "worst held-out experiment: accuracy (experiment)" in text
        assert "accuracy (fraction)" in text
    assert "| Nonlinear (RBF) SVC | 0.9987 | 0.9902 (slow_50Hz_B) | 0.35 |" in md
    assert "<td>0.9902 (slow_50Hz_B)</td>" in html


def _physics_fit_summary(*, settings=None, converged=False, **result):
    """Evaluate's summary of a one-parameter (``reg_F0``) physics fit made without fitting:
    ``result`` sets or overrides the fit result's fields (status, iterations, notes, …)."""
    from types import SimpleNamespace

    from clutchlab.physics import CircuitModel
    from clutchlab.validation.evaluate import Evaluation

    fields = {
        "model": CircuitModel, "free": ["reg_F0"], "values": {"reg_F0": -1.6},
        "std_errors": {"reg_F0": 0.01}, "units": {"reg_F0": "N"}, "unidentifiable": (),
        "effects": (), "per_experiment": {},
    }  # fmt: skip
    res = SimpleNamespace(**(fields | result))
    model = SimpleNamespace(result_=res, settings=settings, converged_=converged, fitted=None)
    return Evaluation.physics_fit(SimpleNamespace(models={"physics_fitted": model}))


def _fit_report(folder, out, fit):
    """The report's document with ``fit`` as its physics-fit summary, and its Markdown and
    HTML renderings."""
    from clutchlab.validation.report import jsonable, render_html, render_markdown

    _, files = _report(folder, out)
    doc = files.doc | {"physics_fit": jsonable(fit)}
    return doc, (render_markdown(doc, []), render_html(doc, []))


@pytest.mark.parametrize("converged", [False, True])
def test_a_fit_stopped_at_a_limit_says_which_limits_and_what_to_do(folders, tmp_path, converged):
    """The report gave "Status: Maximum_WallTime_Exceeded (pre-fit) (NOT converged — best
    iterate used)" and nothing on the limit it hit or how to get a converged fit."""

    from clutchlab.physics.fit import FitSettings

    fit = _physics_fit_summary(
        settings=FitSettings(time_limit_s=30.0, max_iter=7),
        converged=converged,
        status="Maximum_WallTime_Exceeded",
        success=converged,
        iterations=4,
        wall_s=29.0,
    )
    assert (fit["time_limit_s"], fit["max_iter"]) == (30.0, 7)
    _, texts = _fit_report(folders[0], tmp_path / "fit", fit)
    for text in texts:
        said = "wall-time limit of 30 s (--fit-time-limit)" in text
        assert said is not converged
        assert ("an iteration limit of 7 (--fit-max-iter)" in text) is not converged
        assert ("--physics-model" in text) is not converged
        assert "effects: none" in text


def test_a_fit_whose_staged_start_is_the_model_says_so(folders, tmp_path):
    """A fit whose solver never got below its staged start keeps the staged start
    (FitResult.note): the report and the terminal summary say the staged start is scored,
    not "best iterate"."""

    from clutchlab.validation.report import summary_lines

    note = "the solver did not get below the staged start, …: the staged start is the model"
    fit = _physics_fit_summary(
        status="Maximum_WallTime_Exceeded (pre-fit)",
        success=False,
        iterations=12,
        wall_s=112.7,
        note=note,
    )
    assert fit["note"] == note
    doc, texts = _fit_report(folders[0], tmp_path / "fit", fit)
    for text in texts:
        assert "NOT converged — staged start used" in text
        assert "The solver did not get below the staged start" in text
    lines = summary_lines(doc | {"variants": {"physics_fitted": {"rmse_bar": 0.3}}})
    assert any("its staged start is scored" in line for line in lines), lines


def test_a_fit_whose_sensitivities_diverged_reports_no_standard_errors(folders, tmp_path):
    """A fit whose output sensitivities diverged (FitResult.uncertainty_note) has NaN
    standard errors: the report says why and marks nothing identifiable or not (it printed
    1e-90 "standard errors" and "not identifiable" before)."""

    from clutchlab.physics.fit import diverged_sensitivities

    note = diverged_sensitivities([[1.45e89]])
    fit = _physics_fit_summary(
        std_errors={"reg_F0": float("nan")},
        status="Error_In_Step_Computation (pre-fit)",
        success=False,
        iterations=11,
        wall_s=57.4,
        uncertainty_note=note,
    )
    assert fit["uncertainty_note"] == note
    assert fit["parameters"]["reg_F0"]["identifiable"] is None
    _, texts = _fit_report(folders[0], tmp_path / "fit", fit)
    for text in texts:
        assert "Standard errors, correlations and identifiability are not reported" in text
        assert "up to 1.45e+89 bar per scaled parameter unit" in text


def test_every_hysteresis_panel_above_a_hidden_one_has_its_current_axis(folders):
    """With three sources (measured + two models) the top-right panel sat above a hidden
    one: shared x axis, no tick labels, no "nominal VFS current (mA)" under it."""
    from clutchlab.physics.fit import FitSettings
    from clutchlab.validation import plot_hysteresis_bands

    quick = FitSettings(max_iter=1, workers=1, prefit_samples=None, progress=False)
    ev = evaluate(
        load_dataset(folders[0]), ["physics_default", "physics_fitted"], train=["fast"],
        test=["medium"], progress=False, physics_settings=quick,
    )  # fmt: skip
    fig = plot_hysteresis_bands(ev)
    fig.savefig(io.BytesIO(), format="png")  # tick labels get their text when drawn
    shown = [ax for ax in fig.axes if ax.get_visible()]
    assert len(shown) == 3
    for ax in shown:
        below = [
            other for other in shown
            if other is not ax and abs(other.get_position().x0 - ax.get_position().x0) < 1e-6
            and other.get_position().y0 < ax.get_position().y0
        ]  # fmt: skip
        if not below:  # the lowest drawn panel of its column
            assert ax.get_xlabel() == "nominal VFS current (mA)"
            assert any(t.get_visible() and t.get_text() for t in ax.get_xticklabels())


def test_the_report_states_the_current_bins_the_scores_used(folders, tmp_path):
    """The definitions and the hysteresis-band caption said "25 mA" whatever bins
    (``AnalysisSettings.bin_mA``) the hysteresis widths were computed in."""
    from clutchlab.validation import AnalysisSettings

    ev = evaluate(
        load_dataset(folders[0]), ["physics_default"], train=["fast"], test=["medium"],
        progress=False, analysis=AnalysisSettings(bin_mA=50.0),
    )  # fmt: skip
    files = write_report(ev, tmp_path / "bins", interactive=False)
    for path in (files.markdown, files.html):
        text = path.read_text(encoding="utf-8")
        assert "centre of each 50 mA nominal-current bin" in text
        assert "25 mA" not in text
    (caption,) = [s.caption for s in report_figures(ev)[0] if s.key == "hysteresis_bands"]
    assert "in 50 mA bins" in caption


def test_the_split_at_the_top_names_the_experiments(folders, tmp_path):
    """The top line said "test = medium (1 experiments, ...)": a count (in the wrong
    number), not which logs were held out."""
    ev, files = _report(folders[0], tmp_path / "split")
    (train,), (test,) = ev.protocol.train_names, ev.protocol.test_names
    md = files.markdown.read_text(encoding="utf-8").replace("\\_", "_")
    html = files.html.read_text(encoding="utf-8")
    assert f"(1 experiment: {train})" in md and f"(1 experiment: {test}; never" in md
    assert f"(1 experiment: {train})" in html and f"(1 experiment: {test})" in html
    assert "1 experiments" not in md + html


def test_newton_per_ampere_is_not_written_as_not_applicable(folders, tmp_path):
    """vfs_K_m's unit "N/A" (newton per ampere) stood in the unit column, where "N/A"
    reads "not applicable"."""
    from clutchlab.validation.report import render_html, render_markdown

    _, files = _report(folders[0], tmp_path / "unit")
    parameter = {"value": 14.4, "std_error": 0.005, "default": 14.0, "identifiable": True,
                 "description": "magnetic force gain at saturation"}  # fmt: skip
    fit = {
        "status": "Solve_Succeeded", "converged": True, "iterations": 9, "wall_s": 50.0,
        "effects": [], "unidentifiable": [], "train_rmse_bar": {},
        "parameters": {"vfs_K_m": parameter | {"unit": "N/A"},
                       "vfs_gain": parameter | {"unit": "bar/A"}},
    }  # fmt: skip
    doc = files.doc | {"physics_fit": fit}
    md, html = render_markdown(doc, []), render_html(doc, [])
    assert "| `vfs_K_m` | 14 | 14.4 | 0.005 | N·A⁻¹ | yes |" in md
    assert "| `vfs_gain` | 14 | 14.4 | 0.005 | bar/A | yes |" in md
    assert "<td>N/A</td>" not in html and "<td>N·A⁻¹</td>" in html
    # the fit's own table (fit-physics) and the parameter listing (clutchlab params) alike
    from fit_support import synthetic_fit

    table = synthetic_fit({"vfs_K_m": 15.0}).table()
    assert "N·A⁻¹" in table and "N/A" not in table
    assert synthetic_fit({"vfs_K_m": 15.0}).units["vfs_K_m"] == "N/A"  # files keep it


def test_the_markdown_has_the_per_experiment_latch_currents_and_the_dataset(folders, tmp_path):
    """Only report.html had the per-test-experiment table (latch-on / latch-off current,
    measured and predicted, mA) and the signals and sample rates; report.md had neither."""
    ev, files = _report(folders[0], tmp_path / "per")
    (test,) = ev.protocol.test_names
    md = files.markdown.read_text(encoding="utf-8")
    per = files.doc["per_experiment"]["physics_default"][test]["period_mean"]
    assert "## Per test experiment (dither-period mean)" in md
    row = next(ln for ln in md.splitlines() if ln.startswith(f"| {test} |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[3] == fmt(per["latch_on_measured_mA"])
    assert cells[4] == fmt(per["latch_on_predicted_mA"])
    assert "latch-on measured (mA)" in md
    assert "## Dataset" in md and "sample rate(s) 1000 Hz" in md


def test_two_test_ramps_are_called_test_ramps(tmp_path):
    """With --test medium,slow the report said "Variants on the test ramp"."""
    ramps = (RampProfile("fast", 1.0, 0.2), RampProfile("medium", 2.0, 0.2),
             RampProfile("slow", 3.0, 0.2))  # fmt: skip
    run = run_stand(StandConfig(settings=(DitherSetting(50.0, "A"),), ramps=ramps), progress=False)
    ev = evaluate(
        run.dataset, ["physics_default"], train=["fast"], test=["medium", "slow"], progress=False
    )
    files = write_report(ev, tmp_path / "two", interactive=False)
    md, html = files.markdown.read_text(), files.html.read_text()
    assert "## Variants on the test ramps (dither-period mean)" in md
    assert "<h2>Variants on the test ramps — dither-period mean (primary)</h2>" in html
    assert "on the test ramps per region" in md


def test_predict_cli_prints_and_records_the_window_of_a_log_without_dither(
    folders, tmp_path, capsys
):
    """`clutchlab predict` printed "scores on dither-period means" on a log without dither;
    its metrics.csv and --json did not say over what the scores were averaged."""
    from clutchlab.cli import main

    design, out, js = tmp_path / "design.json", tmp_path / "out", tmp_path / "p.json"
    assert main(["params", "--out", str(design)]) == 0
    argv = [str(design), str(folders[1]), "--ramps", "medium", "--no-figures", "--quiet"]
    assert main(["predict", *argv, "--out", str(out), "--json", str(js)]) == 0
    printed = capsys.readouterr().out
    assert "dither-period" not in printed
    assert "scores on the raw signal — no dither to average over" in printed
    rows = list(csv.DictReader((out / "metrics.csv").open()))
    assert [r["window_samples"] for r in rows] == ["1"]
    (exp,) = json.loads(js.read_text())["experiments"].values()
    assert exp["averaging"]["kind"] == "none" and exp["averaging"]["samples"] == 1.0


def test_a_physics_fit_that_did_not_converge_is_flagged_beside_its_scores(folders, tmp_path):
    """The variant lines under the score tables said "physics_fitted: circuit model,
    parameters fitted to the training experiments" for a fit stopped at its limit with a
    worse test RMSE than the datasheet; only a section further down said NOT converged."""
    from clutchlab.physics.fit import FitSettings

    stopped = FitSettings(max_iter=1, workers=1, prefit_samples=None, progress=False)
    ev = evaluate(
        load_dataset(folders[0]), ["physics_fitted"], train=["fast"], test=["medium"],
        progress=False, physics_settings=stopped,
    )  # fmt: skip
    files = write_report(ev, tmp_path / "nc", interactive=False)
    assert files.doc["physics_fit"]["converged"] is False
    md = files.markdown.read_text(encoding="utf-8")
    line = next(ln for ln in md.splitlines() if ln.startswith("- `physics_fitted`:"))
    assert "its fit did NOT converge" in line
    assert "its fit did NOT converge" in files.html.read_text(encoding="utf-8")
    from clutchlab.validation.report import _describe

    fit = files.doc["physics_fit"]
    hybrid = {"description": "fitted physics + GP", "requires": ["physics_fitted"]}
    assert "built on physics_fitted, whose fit did NOT converge" in _describe(
        "hybrid", hybrid, html_=False, fit=fit
    )
    assert "NOT converge" not in _describe("hybrid", hybrid, False, fit | {"converged": True})


def test_test_ramps_outside_the_training_rates_are_called_an_extrapolation(folders, tmp_path):
    """Trained on one ramp rate and scored on another, every variant extrapolates in rate
    (a one-ramp training set gave a ±2σ coverage of 1 % on the test ramp) and the report
    did not say so. It names the test experiments, their rates and the trained range."""
    from clutchlab.validation.report import _rate_note, render_html, render_markdown

    ev, files = _report(folders[0], tmp_path / "rates")
    rates = files.doc["split"]["ramp_rates_mA_s"]
    (name,) = ev.protocol.test_names
    lo, _ = rates["train"]
    assert rates["extrapolated"] == [name]
    assert rates["test"][name] < lo / 1.1  # 2 s ramps against 1 s ones: half the rate
    md, html = render_markdown(files.doc, []), render_html(files.doc, [])
    for text in (md, html):
        assert "Extrapolation in ramp rate:" in text
        assert f"{fmt(rates['test'][name])} mA/s; trained {fmt(lo)} mA/s" in text
    assert any("outside the training ramp rates" in line for line in summary_lines(files.doc))
    # a test rate inside the trained range (or within 10 % of it) is no extrapolation
    inside = {"train": [100.0, 400.0], "test": {"m": 105.0}, "extrapolated": []}
    assert _rate_note({"ramp_rates_mA_s": inside}) is None
    assert ev.protocol.ramp_rates is ev.protocol.ramp_rates  # read once
