"""``clutchlab train`` / ``classifiers`` on a user's odd inputs: clear errors, before any fit,
nothing written."""

from __future__ import annotations

import json

import numpy as np
import pytest

from clutchlab.cli import main
from clutchlab.data import Dataset, Trace, save_dataset
from clutchlab.errors import DataError, ModelError
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand
from clutchlab.residual_ml import GPBaseline, PhysicsPredictor, compare_classifiers, load_model


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """Two short ramps at one dither setting (seconds to build, never fitted here)."""
    config = StandConfig(
        settings=(DitherSetting(50.0, "A"),),
        ramps=(RampProfile("fast", 0.8, 0.2), RampProfile("slow", 2.0, 0.2)),
        substeps=2,
        seed=2,
    )
    data = tmp_path_factory.mktemp("tiny") / "stand"
    save_dataset(run_stand(config, progress=False).dataset, data)
    return data


@pytest.mark.parametrize(
    ("name", "content", "expected"),
    [
        ("missing.json", None, "missing.json"),
        ("list.json", "[1, 2]", "a JSON object is expected"),
        ("no_substeps.json", {"kind": "PhysicsPredictor", "effects": [], "params": {}}, "substeps"),
        (
            "bad_effect.json",
            {"kind": "PhysicsPredictor", "effects": ["nope"], "params": {}, "substeps": 4},
            "unknown effect 'nope'",
        ),
        (
            "bad_param.json",
            {"kind": "PhysicsPredictor", "effects": [], "params": {"nope": 1.0}, "substeps": 4},
            "unknown parameter 'nope'",
        ),
    ],
)
def test_train_physics_file_problems_are_one_clear_error(
    tiny, tmp_path, capsys, name, content, expected
):
    """A bad ``--physics`` file is an error naming it and its problem (no traceback; a
    PhysicsPredictor description is not reported as a malformed fit result), before any fit
    and with no model folder written."""
    path = tmp_path / name
    if content is not None:
        path.write_text(content if isinstance(content, str) else json.dumps(content))
    out = tmp_path / "model"
    argv = ["train", str(tiny), "--variant", "hybrid", "--out", str(out), "--quiet"]
    assert main([*argv, "--physics", str(path)]) == 2
    err = capsys.readouterr().err
    assert name in err and expected in err
    assert "Traceback" not in err
    if isinstance(content, dict):  # its own problems, not those of a fit result
        assert "PhysicsPredictor description" in err and "fit result" not in err
    assert not out.exists()


def test_physics_predictor_load_errors_are_model_errors(tmp_path):
    """PhysicsPredictor.load raises ModelError (never OSError / KeyError / AttributeError)."""
    with pytest.raises(ModelError, match=r"missing\.json"):
        PhysicsPredictor.load(tmp_path / "missing.json")
    (tmp_path / "list.json").write_text("[1]")
    with pytest.raises(ModelError, match="JSON object"):
        PhysicsPredictor.load(tmp_path / "list.json")
    (tmp_path / "partial.json").write_text('{"kind": "PhysicsPredictor", "effects": []}')
    with pytest.raises(ModelError, match="params: missing key"):
        PhysicsPredictor.load(tmp_path / "partial.json")
    good = PhysicsPredictor(("sensor_lag",), {"slag_tau": 2.0})
    good.save(tmp_path / "good.json")
    assert PhysicsPredictor.load(tmp_path / "good.json") == good


@pytest.mark.parametrize(
    ("name", "content"), [("model.npz", b"my arrays"), ("model.json", b'{"mine": 1}')]
)
def test_train_refuses_a_users_model_file_before_fitting(tiny, tmp_path, capsys, name, content):
    """A file of the user's where ``train`` writes model.json / model.npz is refused before
    the fit (was: after it, the fit's time lost), and is left as it was."""
    out = tmp_path / "model"
    out.mkdir()
    (out / name).write_bytes(content)
    argv = ["train", str(tiny), "--variant", "gp_base", "--out", str(out)]
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert f"{name}: exists and is not" in captured.err
    assert "fitting" not in captured.out
    assert (out / name).read_bytes() == content and [p.name for p in out.iterdir()] == [name]


def _ramp(name: str, ramp: str, peak_mA: float, line: bool = True) -> Trace:
    """0 → peak → 0 mA in 2 s at 50 Hz dither; latched (line pressure) above 800 mA."""
    t = np.arange(0.0, 2.0005, 1e-3)
    current = np.interp(t, [0.0, 1.0, 2.0], [0.0, peak_mA, 0.0])
    n = t.size
    signals = {
        "time_s": t,
        "current_cmd_mA": current,
        "dither_amp_mA": np.full(n, 50.0),
        "dither_freq_Hz": np.full(n, 50.0),
        "clutch_pressure_bar": np.where(current > 800.0, 17.7, current / 100.0),
    }
    if line:
        signals["line_pressure_bar"] = np.full(n, 17.7)
    return Trace(name, signals, meta={"ramp": ramp, "dither_freq_Hz": 50.0})


def test_classifiers_with_a_latch_state_in_one_experiment_only(tmp_path, capsys):
    """Only one training experiment latches (the other stays below the latch current): each
    leave-one-experiment-out fold without it has one class. Was a scikit-learn ValueError
    traceback from a worker process; now one DataError naming that experiment."""
    traces = [_ramp("full", "fast", 1100.0), _ramp("partial", "slow", 600.0)]
    with pytest.raises(DataError, match="each latch state in at least 2") as exc:
        compare_classifiers(traces, names=["logistic_regression"], workers=1)
    assert exc.value.problems == ["only experiment 'full' has latched samples"]

    data, out = tmp_path / "data", tmp_path / "clf"
    save_dataset(Dataset(traces), data)
    assert main(["classifiers", str(data), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "only experiment 'full' has latched samples" in err and "Traceback" not in err
    assert not out.exists()


def test_predict_on_nan_names_the_experiment_signal_and_row(tiny):
    """A trace built in Python (not read through the data checks) with a NaN input: was
    "x has a non-finite value at row N" (no experiment, no signal) for the current, and
    silently NaN predictions for the dither amplitude or frequency. Now one DataError as
    in fit, naming experiment, signal and first row."""
    from clutchlab.data import load_dataset

    ds = load_dataset(tiny)
    model = GPBaseline().fit(ds.select(ramps=["fast"]))
    trace = ds.select(ramps=["slow"])[0]
    assert np.isfinite(model.predict(trace)).all()
    for signal in ("current_cmd_mA", "dither_amp_mA", "dither_freq_Hz"):
        values = trace.get(signal).copy()
        values[[99, 120]] = np.nan
        with pytest.raises(DataError, match="predicted experiments") as info:
            model.predict(trace.with_signals(**{signal: values}))
        assert info.value.problems == [
            f"experiment {trace.name!r}: {signal} has 2 non-finite value(s), the first at "
            "row 100 (t = 0.099 s)"
        ]


def test_didt_features_without_dither_average_the_current_noise():
    """A log without dither (no dither columns, no manifest frequency) and only the measured
    current: the dI/dt window was 5 "dither periods" of 1 sample each (5 ms), so dI/dt
    swung by ±4000 mA/s on a 220 mA/s ramp and the direction of travel flipped thousands
    of times. It now uses the data layer's window without dither (5 periods of 50 Hz, as
    nominal_didt), and the direction follows the ramp."""
    from clutchlab.residual_ml import FeatureBuilder

    t = np.arange(0.0, 11.0005, 1e-3)
    ramp = np.interp(t, [0.0, 0.5, 5.5, 6.0, 11.0], [0.0, 0.0, 1100.0, 1100.0, 0.0])
    noisy = np.round((ramp + np.random.default_rng(0).normal(0.0, 2.0, t.size)) * 2) / 2
    trace = Trace(
        "no_dither", {"time_s": t, "current_mA": noisy, "clutch_pressure_bar": ramp / 100}
    )
    X = FeatureBuilder(("didt_mA_s", "direction")).build(trace)
    up, down = (t > 1.0) & (t < 5.0), (t > 6.5) & (t < 10.5)
    assert np.abs(X[up | down, 0]).max() < 300.0  # the ramp is 220 mA/s
    assert (X[up, 1] == 1).all() and (X[down, 1] == -1).all()
    assert np.count_nonzero(np.diff(X[:, 1])) < 30


def test_features_of_a_command_only_log_name_what_is_missing_and_take_the_manifest():
    """A log with the command current only (no current_mA) and no dither columns: training
    failed with "trace 'x': no current_mA to demodulate", which the user never asked for.
    The error now names the signal the features need and where to give it; given as a
    manifest constant (as the physics model already takes it), it is used."""
    from clutchlab.residual_ml import FeatureBuilder

    t = np.arange(0.0, 2.0005, 1e-3)
    cmd = np.interp(t, [0.0, 1.0, 2.0], [0.0, 1000.0, 0.0])
    signals = {"time_s": t, "current_cmd_mA": cmd, "clutch_pressure_bar": cmd / 100}
    features = ("current_mA", "dither_amp_mA", "dither_freq_Hz", "didt_mA_s")
    bare = Trace("r5s", signals, meta={"ramp": "fast"}, source="logs/r5s.csv")
    with pytest.raises(DataError) as info:
        FeatureBuilder(features).build(bare)
    assert str(info.value).startswith(
        "r5s (logs/r5s.csv): no dither_amp_mA column, and no measured current_mA to "
        "demodulate it from; the model's features need dither_amp_mA"
    ), str(info.value)
    given = Trace("r5s", signals, meta={"ramp": "fast", "dither_freq_Hz": 50, "dither_amp_mA": 80})
    X = FeatureBuilder(features).build(given)
    np.testing.assert_array_equal(X[:, 0], cmd)
    assert (X[:, 1] == 80.0).all() and (X[:, 2] == 50.0).all()


@pytest.mark.parametrize("name", ["model.json", "model.npz"])
def test_train_json_summary_may_not_replace_the_model(tiny, tmp_path, capsys, name):
    """``--json OUT/model.json`` (or ``model.npz``) was accepted: the summary, written last,
    replaced the model just saved, which then no longer loaded. Refused before the fit."""
    out = tmp_path / "model"
    argv = ["train", str(tiny), "--variant", "gp_base", "--out", str(out)]
    assert main([*argv, "--json", str(out / name)]) == 2
    captured = capsys.readouterr()
    assert (
        f"--json {out / name}: is" in captured.err and "write the summary elsewhere" in captured.err
    )
    assert "fitting" not in captured.out and not out.exists()


def test_train_out_may_not_be_a_folder_clutchlab_wrote(tiny, capsys):
    """``train DS --out DS`` wrote model.json + model.npz into the dataset folder clutchlab
    had written (another kind of output, which the README says is never written there).
    Refused before the fit; the dataset is left as it was."""
    before = sorted(p.name for p in tiny.iterdir())
    assert main(["train", str(tiny), "--variant", "gp_base", "--out", str(tiny)]) == 2
    captured = capsys.readouterr()
    assert f"--out {tiny}: holds other output clutchlab wrote" in captured.err
    assert "fitting" not in captured.out and sorted(p.name for p in tiny.iterdir()) == before


def test_train_hybrid_states_its_form(tiny, tmp_path, capsys):
    """``train --variant hybrid`` printed the residual GPs and the latch decision but not
    which form the hybrid predicts with; a hybrid that chose the physics alone (as on two
    training experiments) looked like a residual model. The form and its leave-one-
    experiment-out scores are now printed and in ``--json``."""
    out, js = tmp_path / "hybrid", tmp_path / "train.json"
    argv = ["train", str(tiny), "--variant", "hybrid", "--out", str(out), "--quiet"]
    assert main([*argv, "--json", str(js)]) == 0
    stdout = capsys.readouterr().out
    model = load_model(out / "model.json")
    assert f"hybrid form: {model.form_} (leave-one-experiment-out RMSE" in stdout
    doc = json.loads(js.read_text())
    assert doc["hybrid_form"] == model.form_
    assert doc["hybrid_form_loeo_rmse_bar"] == pytest.approx(model.form_scores_)
    kappa = doc["hybrid_standalone_handicap"]  # the handicap the form choice used
    assert kappa == pytest.approx(model.standalone_handicap_) and kappa >= 1.0
    assert f"standalone compared after ÷ {kappa:.3g}" in stdout


@pytest.mark.parametrize("line", [True, False])
def test_train_says_why_nothing_latched(tmp_path, capsys, line):
    """A circuit whose clutch never came within the label margin of line pressure (e.g. a
    12 bar system without line pressure logged: 17.7 bar is assumed) got a model without
    latch, and train said only "none (one latch state in the training data)". It now
    notes how close the clutch came to line pressure and what was assumed."""
    traces = [_ramp("a", "fast", 600.0, line), _ramp("b", "slow", 650.0, line)]
    data = tmp_path / "data"
    save_dataset(Dataset(traces), data)
    argv = ["train", str(data), "--variant", "paper_faithful", "--out", str(tmp_path / "m")]
    assert main([*argv, "--quiet"]) == 0
    captured = capsys.readouterr()
    assert "latch decision: none (one latch state" in captured.out
    assert (
        "note: no training sample was labelled latched: the clutch pressure came within "
        "11.2" in captured.err
    )  # 17.7 - 6.5 bar, to the period mean's rounding
    assert ("17.7 bar assumed" in captured.err) is not line


def test_train_has_no_latch_note_when_it_latched(tmp_path, capsys):
    traces = [_ramp(n, r, 1100.0) for n, r in (("a", "fast"), ("b", "slow"), ("c", "slow"))]
    data = tmp_path / "data"
    save_dataset(Dataset(traces), data)
    argv = ["train", str(data), "--variant", "paper_faithful", "--out", str(tmp_path / "m")]
    assert main([*argv, "--quiet"]) == 0
    assert "note:" not in capsys.readouterr().err


def _strict(text: str):
    """JSON as a strict reader takes it: NaN / Infinity are errors."""

    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


def test_train_json_is_strict_json_when_a_metric_is_not_finite(tiny, tmp_path, monkeypatch):
    """The fit % of a constant experiment is NaN, and ``train --json`` wrote ``NaN``, which
    JSON readers (and other languages' parsers) refuse; it is now ``null``."""
    import clutchlab.residual_ml as ml

    real = ml.score_traces

    def with_nan(model, traces, **kw):
        out = real(model, traces, **kw)
        for m in out["per_experiment"].values():
            m["fit_pct"] = float("nan")
        return out

    monkeypatch.setattr(ml, "score_traces", with_nan)
    js = tmp_path / "train.json"
    argv = ["train", str(tiny), "--variant", "gp_base", "--out", str(tmp_path / "m")]
    assert main([*argv, "--json", str(js), "--quiet"]) == 0
    doc = _strict(js.read_text(encoding="utf-8"))
    assert all(m["fit_pct"] is None for m in doc["training"]["per_experiment"].values())


def test_compare_classifiers_compares_a_repeated_name_once_and_names_an_unknown_one():
    """``compare_classifiers(names=[a, a])`` gave two rows of the same classifier in its
    table and CSV through the API (the CLI removed repeats); unknown names are listed."""
    traces = [_ramp("a", "fast", 1100.0), _ramp("b", "slow", 1100.0), _ramp("c", "fast", 1000.0)]
    result = compare_classifiers(traces, names=["logistic_regression"] * 2, workers=1)
    assert result.csv_text().count("logistic_regression,") == 1
    assert result.table().count("Logistic regression") == 1
    with pytest.raises(ModelError, match=r"unknown classifier\(s\) \['nope', 'nix'\]"):
        compare_classifiers(traces, names=["nope", "logistic_regression", "nix"], workers=1)


def test_train_latched_reference_none_predicts_where_line_pressure_is_not_logged(tmp_path, capsys):
    """A model trained from the CLI on a log with line pressure could not predict on one
    without it, and its error said "fit with latched_reference='none'", which no command
    could do. ``train --latched-reference none`` does it."""
    traces = [_ramp(n, r, 1100.0) for n, r in (("a", "fast"), ("b", "slow"), ("c", "slow"))]
    data = tmp_path / "data"
    save_dataset(Dataset(traces), data)
    unlogged = _ramp("d", "fast", 1100.0, line=False)
    fitted = {}
    for ref in ("line", "none"):
        out = tmp_path / ref
        argv = ["train", str(data), "--variant", "paper_svc_gp", "--out", str(out), "--quiet"]
        assert main([*argv, "--latched-reference", ref]) == 0
        fitted[ref] = load_model(out / "model.json")
        assert fitted[ref].latched_reference_ == ref
    with pytest.raises(DataError, match="clutchlab train --latched-reference none"):
        fitted["line"].predict(unlogged)
    assert np.isfinite(fitted["none"].predict(unlogged)).all()


def test_train_latched_reference_is_refused_for_a_variant_without_it(tiny, tmp_path, capsys):
    out = tmp_path / "m"
    argv = ["train", str(tiny), "--variant", "gp_didt", "--out", str(out)]
    assert main([*argv, "--latched-reference", "none"]) == 2
    err = capsys.readouterr().err
    assert "--latched-reference is only used by paper_svc_gp and paper_faithful" in err
    assert not out.exists()
