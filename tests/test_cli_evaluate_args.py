"""``clutchlab evaluate``: usage errors are refused before any work, with exit status 2.

Exit status 1 means "a variant failed" (the report lists it); a bad option is not that.
"""

from __future__ import annotations

import pytest
from fit_support import synthetic_fit

from clutchlab.cli import main
from clutchlab.errors import DataError
from clutchlab.physics import CircuitModel


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--fmu-param", "reg_m=heavy", "--physics-fmu", "x.fmu"], "expected NAME=VALUE"),
        (["--fmu-param", "reg_m=40"], "no --physics-fmu was given"),
    ],
)
def test_a_bad_fmu_param_is_a_usage_error(tmp_path, capsys, extra, message):
    out = tmp_path / "report"
    code = main(["evaluate", str(tmp_path / "no-data"), "--out", str(out), "--quiet", *extra])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("clutchlab evaluate: error: --fmu-param") and message in err
    assert not out.exists()


def _fit_json(path, effects, train):
    """A fit result as `clutchlab fit-physics` writes it, at the datasheet values."""
    synthetic_fit({"reg_F0": CircuitModel().default_params()["reg_F0"]}, effects, train).to_json(
        path
    )
    return path


def test_a_given_physics_fit_without_the_asked_effects_is_refused_before_any_work(
    tmp_path, capsys, monkeypatch
):
    from synthetic import make_trace

    import clutchlab.validation as validation
    from clutchlab.data import Dataset, save_dataset

    traces = [
        make_trace([0, 0.5, 1.5, 2.0], [0, 0, 1100, 0], name=f"{ramp}_50Hz", ramp=ramp)
        for ramp in ("fast", "medium", "slow")
    ]
    save_dataset(Dataset(traces), tmp_path / "data")
    fit = _fit_json(tmp_path / "fit.json", [], ["fast_50Hz", "slow_50Hz"])

    def refuse(*args, **kwargs):
        raise AssertionError("the evaluation was started")

    monkeypatch.setattr(validation, "evaluate", refuse)
    argv = ["evaluate", str(tmp_path / "data"), "--out", str(tmp_path / "r"), "--quiet"]
    code = main([*argv, "--physics-model", str(fit), "--effects", "sensor_lag"])
    err = capsys.readouterr().err
    assert code == 2 and "lacks the effect(s) sensor_lag" in err
    assert not (tmp_path / "r").exists()


def test_fitted_physics_refuses_a_given_fit_without_the_models_effects(tmp_path):
    from synthetic import make_trace

    from clutchlab.errors import FitError
    from clutchlab.physics.fit import PhysicsFitter
    from clutchlab.validation.variants import FittedPhysics

    trace = make_trace([0, 0.5, 1.5, 2.0], [0, 0, 1100, 0], name="fast_50Hz")
    fitter = PhysicsFitter.load(_fit_json(tmp_path / "fit.json", [], ["fast_50Hz"]))
    model = CircuitModel().with_effects("sensor_lag")
    with pytest.raises(FitError, match="lacks the effect"):
        FittedPhysics(model, fitted=fitter).fit([trace])
    assert FittedPhysics(CircuitModel(), fitted=fitter).fit([trace]).converged_


def test_a_classifier_comparison_that_cannot_run_is_skipped_not_failed():
    """One training experiment: the comparison (not asked for by name) is left out with
    its reason; the evaluation has no failure (exit status 0, not 1)."""
    from synthetic import tiny_stand

    from clutchlab.validation import evaluate

    data = tiny_stand(4).select(names=["fast_30Hz_A", "medium_30Hz_A"])
    ev = evaluate(data, ["gp_base"], train=("fast",), progress=False, on_error="report")
    assert ev.failed == {} and "gp_base" in ev.scores
    assert "at least 2 training experiments" in ev.extra["classifier_comparison_skipped"]


@pytest.mark.parametrize("command", ["evaluate", "demo"])
def test_a_users_report_file_in_out_is_refused_before_the_work(
    tmp_path, capsys, monkeypatch, command
):
    import clutchlab.validation as validation

    def refuse(*args, **kwargs):
        raise AssertionError("the evaluation was started")

    monkeypatch.setattr(validation, "evaluate", refuse)
    monkeypatch.setattr(validation, "run_demo", refuse)
    out = tmp_path / "report"
    out.mkdir()
    (out / "metrics.json").write_text('{"mine": true}\n')
    (out / "notes.txt").write_text("kept\n")
    argv = ["evaluate", str(tmp_path / "no-data")] if command == "evaluate" else ["demo"]
    code = main([*argv, "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "metrics.json" in err and "notes.txt" not in err
    assert (out / "metrics.json").read_text() == '{"mine": true}\n'


def test_a_classifier_comparison_on_data_that_never_latch_is_skipped_not_failed():
    """Training data with one latch state: the comparison has nothing to classify."""
    from synthetic import make_trace

    from clutchlab.data import Dataset
    from clutchlab.validation import evaluate

    traces = []
    for ramp in ("fast", "medium", "slow"):
        tr = make_trace([0, 0.5, 1.5, 2.0], [0, 0, 500, 0], name=f"{ramp}_50Hz", ramp=ramp)
        traces.append(tr.with_signals(clutch_pressure_bar=0.5 + tr.get("current_cmd_mA") / 100))
    ev = evaluate(Dataset(traces), ["gp_base"], progress=False, on_error="report")
    assert ev.failed == {} and "gp_base" in ev.scores
    assert "only one latch state" in ev.extra["classifier_comparison_skipped"]
    with pytest.raises(DataError, match="only one latch state"):
        evaluate(Dataset(traces), ["gp_base"], progress=False, classifiers=True)


@pytest.mark.parametrize("out", [".", "", ".."])
def test_the_current_folder_as_report_folder_is_refused_before_the_work(
    tmp_path, capsys, monkeypatch, out
):
    """It cannot be swapped in atomically: the run ended with 'cannot write: Device or
    resource busy' after all its work."""
    import clutchlab.validation as validation

    def refuse(*args, **kwargs):
        raise AssertionError("the evaluation was started")

    monkeypatch.setattr(validation, "evaluate", refuse)
    here = tmp_path / "work"
    here.mkdir()
    monkeypatch.chdir(here)
    code = main(["evaluate", str(tmp_path / "no-data"), "--out", out, "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and ("is the current folder or holds it" in err or "empty name" in err)
