"""``clutchlab discover`` / ``select-structure`` / ``classifiers``: input and output checks.

Fast: every check here must refuse before the expensive work, so the work itself is
replaced by a stub that fails the test if it is reached.
"""

from __future__ import annotations

import pytest
from synthetic import make_trace

import clutchlab.validation.discover as discover_pkg
from clutchlab.cli import main
from clutchlab.data import Dataset, save_dataset
from clutchlab.physics.fit import StructureSelector


@pytest.fixture(scope="module")
def dataset_dir(tmp_path_factory):
    """Three 2 s command-only experiments, ramps fast / medium / slow."""
    traces = [
        make_trace([0, 0.5, 1.5, 2.0], [0, 0, 1100, 0], name=f"{ramp}_50Hz", ramp=ramp)
        for ramp in ("fast", "medium", "slow")
    ]
    out = tmp_path_factory.mktemp("cli_checks") / "data"
    save_dataset(Dataset(traces), out)
    return out


@pytest.fixture
def no_work(monkeypatch):
    """Make reaching the discovery or a structure fit an error of the test."""

    def refuse(*args, **kwargs):
        raise AssertionError("the expensive work was started")

    monkeypatch.setattr(discover_pkg, "discover", refuse)
    monkeypatch.setattr(StructureSelector, "fit", refuse)


@pytest.mark.parametrize(
    "extra",
    [["--train", "fast,fats"], ["--test", "meduim"], ["--train", "fats", "--test", "medium"]],
)
def test_discover_refuses_an_unknown_ramp_label(dataset_dir, tmp_path, capsys, no_work, extra):
    out = tmp_path / "report"
    code = main(["discover", str(dataset_dir), "--out", str(out), "--quiet", *extra])
    err = capsys.readouterr().err
    assert code == 2
    assert "unknown ramp label" in err and "'fast', 'medium', 'slow'" in err
    assert not out.exists()


def test_discover_training_on_medium_without_test_has_no_test_set(
    dataset_dir, tmp_path, monkeypatch
):
    seen = {}

    def stop(dataset, model, settings, baseline=None):
        seen["test"] = settings.test_ramps
        raise KeyboardInterrupt

    monkeypatch.setattr(discover_pkg, "discover", stop)
    argv = ["discover", str(dataset_dir), "--out", str(tmp_path / "r"), "--quiet"]
    assert main([*argv, "--train", "fast,medium,slow"]) == 130 and seen["test"] == ()


def test_discover_without_a_medium_ramp_runs_without_a_test_set(tmp_path, monkeypatch):
    traces = [
        make_trace([0, 0.5, 1.5, 2.0], [0, 0, 1100, 0], name=f"{ramp}_50Hz", ramp=ramp)
        for ramp in ("fast", "slow")
    ]
    save_dataset(Dataset(traces), tmp_path / "data")
    seen = {}

    def stop(dataset, model, settings, baseline=None):
        seen["test"] = settings.test_ramps
        raise KeyboardInterrupt

    monkeypatch.setattr(discover_pkg, "discover", stop)
    code = main(["discover", str(tmp_path / "data"), "--out", str(tmp_path / "r"), "--quiet"])
    assert code == 130 and seen["test"] == ()


def test_select_structure_refuses_an_unknown_ramp_label(dataset_dir, capsys, no_work):
    code = main(["select-structure", str(dataset_dir), "--train", "fast,fats", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "unknown ramp label" in err and "fats" in err


def test_select_structure_never_writes_its_model_over_the_input_manifest(
    dataset_dir, capsys, no_work
):
    manifest = dataset_dir / "manifest.json"
    before = manifest.read_bytes()
    code = main(["select-structure", str(dataset_dir), "--out", str(manifest), "--quiet"])
    assert code == 2 and "manifest of this command's input" in capsys.readouterr().err
    assert manifest.read_bytes() == before


@pytest.mark.parametrize("kind", ["folder", "text"])
def test_select_structure_refuses_a_bad_out_before_fitting(
    dataset_dir, tmp_path, capsys, no_work, kind
):
    out = tmp_path / "model.json"
    if kind == "folder":
        out.mkdir()
    else:
        out.write_text("my notes\n")
    code = main(["select-structure", str(dataset_dir), "--out", str(out), "--quiet"])
    assert code == 2 and str(out) in capsys.readouterr().err
    assert kind == "folder" or out.read_text() == "my notes\n"


@pytest.fixture
def no_comparison(monkeypatch):
    import clutchlab.residual_ml as residual_ml

    def refuse(*args, **kwargs):
        raise AssertionError("the classifier comparison was started")

    monkeypatch.setattr(residual_ml, "compare_classifiers", refuse)


def test_classifiers_refuse_a_users_file_in_out_before_the_comparison(
    dataset_dir, tmp_path, capsys, no_comparison
):
    out = tmp_path / "cls"
    out.mkdir()
    (out / "classifiers.png").write_bytes(b"my own figure")
    code = main(["classifiers", str(dataset_dir), "--out", str(out), "--quiet"])
    assert code == 2 and "classifiers.png" in capsys.readouterr().err
    assert (out / "classifiers.png").read_bytes() == b"my own figure"


def test_classifiers_refuse_a_dataset_folder_as_out_before_the_comparison(
    dataset_dir, capsys, no_comparison
):
    code = main(["classifiers", str(dataset_dir), "--out", str(dataset_dir), "--quiet"])
    assert code == 2 and "dataset folder" in capsys.readouterr().err


def test_classifiers_named_twice_are_compared_once(dataset_dir, tmp_path, monkeypatch):
    import clutchlab.residual_ml as residual_ml

    seen = {}

    def stop(traces, names=None, progress=True):
        seen["names"] = names
        raise KeyboardInterrupt

    monkeypatch.setattr(residual_ml, "compare_classifiers", stop)
    argv = ["classifiers", str(dataset_dir), "--out", str(tmp_path / "c"), "--quiet"]
    assert main([*argv, "--classifiers", "rbf_svc,linear_svc,rbf_svc"]) == 130
    assert seen["names"] == ["rbf_svc", "linear_svc"]


def _fake_selection(*statuses):
    from clutchlab.physics.fit.structure import CandidateScore, StructureSelection

    names = ("plain", "force", "play")
    cands = [
        CandidateScore(n, [], 8, 0.35, -20.0, status=s, converged=s == "Solve_Succeeded")
        for n, s in zip(names, statuses, strict=False)
    ]
    return StructureSelection("plain", [], "BIC", 425, 21.0, cands, ["fast_50Hz"], 1.0)


@pytest.mark.parametrize(
    ("statuses", "warned"),
    [
        (("not run", "Maximum_Iterations_Exceeded"), "2 of 2 candidate fits stopped"),
        (("Solve_Succeeded", "Solve_Succeeded; kept its start (the iterate was worse)"), None),
    ],
)
def test_select_structure_warns_when_the_choice_rests_on_unfinished_fits(
    dataset_dir, capsys, monkeypatch, statuses, warned
):
    def fake_fit(self, data):
        self.selection_ = _fake_selection(*statuses)
        return self

    monkeypatch.setattr(StructureSelector, "fit", fake_fit)
    assert main(["select-structure", str(dataset_dir), "--quiet"]) == 0
    err = capsys.readouterr().err
    if warned:
        assert warned in err and "plain (not run)" in err and "--time-limit" in err
    else:
        assert "warning" not in err


def test_select_structure_fits_a_candidate_named_twice_once(dataset_dir, monkeypatch):
    seen = {}

    def stop(self, data):
        seen["candidates"] = self.candidates
        raise KeyboardInterrupt

    monkeypatch.setattr(StructureSelector, "fit", stop)
    argv = ["select-structure", str(dataset_dir), "--candidates", "plain,force,plain", "--quiet"]
    assert main(argv) == 130
    assert seen["candidates"] == ("plain", "force")


def test_discover_scores_a_candidate_named_twice_once(dataset_dir, tmp_path, monkeypatch):
    seen = {}

    def stop(dataset, model, settings, baseline=None):
        seen["candidates"] = settings.candidates
        raise KeyboardInterrupt

    monkeypatch.setattr(discover_pkg, "discover", stop)
    argv = ["discover", str(dataset_dir), "--out", str(tmp_path / "r"), "--quiet"]
    assert main([*argv, "--candidates", "sensor_lag,supply_droop,sensor_lag"]) == 130
    assert seen["candidates"] == ("sensor_lag", "supply_droop")


@pytest.mark.parametrize(
    ("extra", "effects", "hint"),
    [
        ([], [], "clutchlab evaluate {data} --out REPORT"),
        (
            ["--out", "{tmp}/m.json", "--train", "slow"],
            ["vfs_force_monotone"],
            "clutchlab evaluate {data} --physics-model {tmp}/m.json "
            "--effects vfs_force_monotone --train slow --out REPORT",
        ),
    ],
)
def test_select_structure_hints_at_an_evaluate_command_that_works(
    dataset_dir, tmp_path, capsys, monkeypatch, extra, effects, hint
):
    from clutchlab.physics.fit import FitResult

    def fake_fit(self, data):
        self.selection_ = _fake_selection("Solve_Succeeded")
        self.selection_.effects = effects
        return self

    monkeypatch.setattr(StructureSelector, "fit", fake_fit)
    monkeypatch.setattr(FitResult, "to_json", lambda self, path=None: "{}")
    monkeypatch.setattr(
        type(_fake_selection()), "best_result", lambda self: FitResult.__new__(FitResult)
    )
    argv = [a.format(tmp=tmp_path) for a in extra]
    assert main(["select-structure", str(dataset_dir), "--quiet", *argv]) == 0
    out = capsys.readouterr().out
    assert "score it with: " + hint.format(data=dataset_dir, tmp=tmp_path) in out
    assert "''" not in out


@pytest.mark.parametrize("name", ["report.html", "discovery.json"])
def test_discover_refuses_a_users_report_file_in_out_before_the_work(
    dataset_dir, tmp_path, capsys, no_work, name
):
    out = tmp_path / "report"
    out.mkdir()
    (out / name).write_text("mine\n")
    code = main(["discover", str(dataset_dir), "--out", str(out), "--quiet"])
    assert code == 2 and name in capsys.readouterr().err
    assert (out / name).read_text() == "mine\n"


def test_a_classifier_folder_is_named_as_such_when_another_output_would_replace_it(
    dataset_dir, tmp_path, capsys, no_work
):
    """Its ownership record said kind '--out' ('holds a --out clutchlab wrote'); one written
    so before is still recognized, and a classifier run may write into it again."""
    import json

    from clutchlab.data.output import OWNED_NAME

    out = tmp_path / "clf"
    out.mkdir()
    (out / "classifiers.csv").write_text("name\n")
    record = {"written_by": "clutchlab", "kind": "--out", "files": ["classifiers.csv"]}
    (out / OWNED_NAME).write_text(json.dumps(record))
    code = main(["discover", str(dataset_dir), "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "holds a classifier comparison folder clutchlab wrote" in err
    from clutchlab.cli_ml import _check_classifiers_out

    _check_classifiers_out(out)  # the same kind: accepted


@pytest.mark.parametrize(
    ("command", "out", "json_name"),
    [
        ("select-structure", "m.json", "m.json"),
        ("discover", "report", "report"),
        ("discover", "report", "report/report.html"),
        ("classifiers", "clf", "clf/classifiers.csv"),
    ],
)
def test_json_and_out_naming_the_same_file_are_refused_before_the_work(
    dataset_dir, tmp_path, capsys, no_work, no_comparison, command, out, json_name
):
    argv = [command, str(dataset_dir), "--out", str(tmp_path / out)]
    code = main([*argv, "--json", str(tmp_path / json_name), "--quiet"])
    assert code == 2 and "which this command writes (--out)" in capsys.readouterr().err
    assert not (tmp_path / out).exists()


def test_json_inside_the_report_folder_as_its_own_json_is_accepted(
    dataset_dir, tmp_path, monkeypatch
):
    def stop(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(discover_pkg, "discover", stop)
    argv = ["discover", str(dataset_dir), "--out", str(tmp_path / "r"), "--quiet"]
    assert main([*argv, "--json", str(tmp_path / "r" / "discovery.json")]) == 130


def test_classifiers_into_the_current_folder_is_refused_before_the_comparison(
    dataset_dir, tmp_path, capsys, monkeypatch, no_comparison
):
    monkeypatch.chdir(tmp_path)
    code = main(["classifiers", str(dataset_dir), "--out", ".", "--quiet"])
    assert code == 2 and "is the current folder or holds it" in capsys.readouterr().err
