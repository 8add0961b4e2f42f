"""``clutchlab predict``: a saved model (train's model.json, a fit-physics result, a design
file) on a dataset, without fitting again — predictions, scores and figures, or a clear
refusal with nothing written."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from fit_support import synthetic_fit

from clutchlab.cli import main
from clutchlab.data import Dataset, Trace, load_dataset, save_dataset
from clutchlab.physics import CircuitModel
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand
from clutchlab.residual_ml import GPWithDerivative, PhysicsPredictor
from clutchlab.validation import load_predictor, predict_traces


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """Three short ramps at one dither setting (seconds to build)."""
    config = StandConfig(
        settings=(DitherSetting(50.0, "A"),),
        ramps=tuple(
            RampProfile(r, d, 0.2) for r, d in (("fast", 0.8), ("medium", 1.4), ("slow", 2.0))
        ),
        substeps=2,
        seed=3,
    )
    root = tmp_path_factory.mktemp("predict")
    data = root / "stand"
    save_dataset(run_stand(config, progress=False).dataset, data)
    ds = load_dataset(data)
    model = GPWithDerivative().fit(ds.select(ramps=["fast", "slow"]))
    model.save(root / "gp" / "model.json")
    reg_f0 = CircuitModel().default_params()["reg_F0"] * 1.05
    train = [t.name for t in ds.select(ramps=["fast", "slow"])]
    synthetic_fit({"reg_F0": reg_f0}, train=train).to_json(root / "fit.json")  # fmt: skip
    return root, data, ds


def _run(*argv) -> int:
    return main(["predict", *map(str, argv), "--quiet"])


def test_an_ml_model_predicts_scores_and_marks_its_training_experiments(tiny, capsys):
    root, data, ds = tiny
    out, js = root / "out_gp", root / "gp.json"
    assert _run(root / "gp" / "model.json", data, "--out", out, "--std", "--json", js) == 0
    text = capsys.readouterr().out
    medium = ds.select(ramps=["medium"])[0]
    model = GPWithDerivative.load(root / "gp" / "model.json")
    mean, std = model.predict(medium, return_std=True)
    frame = pd.read_csv(out / "predictions" / f"{medium.name}.csv")
    assert list(frame.columns) == [
        "time_s", "current_nominal_mA", "clutch_pressure_bar", "predicted_bar",
        "residual_bar", "std_bar",
    ]  # fmt: skip
    np.testing.assert_allclose(frame["predicted_bar"], mean, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(frame["std_bar"], std, rtol=1e-5, atol=1e-5)
    doc = json.loads(js.read_text())
    assert doc["model_kind"] == "gp_didt model (clutchlab train)"
    trained = {name for name, row in doc["experiments"].items() if row["trained"]}
    assert trained == {t.name for t in ds.select(ramps=["fast", "slow"])}
    assert doc["overall"]["experiments"] == "not trained on"
    assert doc["overall"]["metrics"]["rmse_bar"] == pytest.approx(
        doc["experiments"][medium.name]["rmse_bar"]
    )  # the one experiment it was not trained on
    assert "all (not trained on)" in text and "in-sample" in text
    metrics = pd.read_csv(out / "metrics.csv")
    assert sorted(metrics["experiment"]) == sorted(t.name for t in ds)
    assert {p.name for p in (out / "figures").iterdir()} == {f"{t.name}.png" for t in ds}


def test_physics_fit_design_and_description_predict_as_the_simulation(tiny, capsys):
    root, data, ds = tiny
    medium = ds.select(ramps=["medium"])
    design = root / "design.json"
    assert main(["params", "--out", str(design)]) == 0
    PhysicsPredictor(params={"reg_F0": 10.0}).save(root / "phys.json")
    fit = json.loads((root / "fit.json").read_text())["values"]["reg_F0"]
    for path, kind, reg_f0 in (
        (root / "fit.json", "fitted physics model (clutchlab fit-physics)", fit),
        (design, "physics design", None),
        (root / "phys.json", "physics model", 10.0),
    ):
        loaded = load_predictor(path)
        assert loaded.kind == kind and not loaded.has_std
        (p,) = predict_traces(loaded, list(medium))[0]
        params = {"reg_F0": reg_f0} if reg_f0 is not None else {}
        expected = PhysicsPredictor(params=params).predict(medium[0])
        np.testing.assert_array_equal(p.predicted_bar, expected)
    out = root / "out_fit"
    assert _run(root / "fit.json", data, "--out", out, "--ramps", "medium", "--format",
                "parquet", "--no-figures") == 0  # fmt: skip
    assert sorted(q.name for q in out.iterdir() if not q.name.startswith(".")) == [
        "metrics.csv", "predictions",
    ]  # fmt: skip
    frame = pd.read_parquet(out / "predictions" / f"{medium[0].name}.parquet")
    assert "std_bar" not in frame


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--std"], "has no predictive std"),
        (["--substeps", "0"], "substeps 0 is not an integer in 1..64"),
        (["--experiments", "nope"], "nope"),
    ],
)
def test_refusals_before_any_prediction_write_nothing(tiny, capsys, extra, message):
    root, data, _ = tiny
    out = root / "refused"
    assert _run(root / "fit.json", data, "--out", out, *extra) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_an_ml_model_has_no_substeps_and_a_dataset_is_not_a_model(tiny, capsys):
    root, data, _ = tiny
    out = root / "refused"
    assert _run(root / "gp" / "model.json", data, "--out", out, "--substeps", "8") == 2
    assert "an ML model has none to set" in capsys.readouterr().err
    assert _run(data / "manifest.json", data, "--out", out) == 2
    assert "not a model clutchlab can predict with" in capsys.readouterr().err
    assert _run(root / "missing.json", data, "--out", out) == 2
    assert "missing.json: not a model file" in capsys.readouterr().err
    assert not out.exists()


def test_a_users_file_and_a_dataset_folder_are_refused_as_out(tiny, capsys):
    root, data, ds = tiny
    out = root / "mine"
    (out / "predictions").mkdir(parents=True)
    mine = out / "predictions" / f"{ds[0].name}.csv"
    mine.write_text("my own numbers\n")
    assert _run(root / "fit.json", data, "--out", out) == 2
    assert "clutchlab did not write these files" in capsys.readouterr().err
    assert mine.read_text() == "my own numbers\n"
    assert _run(root / "fit.json", data, "--out", data) == 2
    assert "holds a dataset" in capsys.readouterr().err


def test_a_failed_prediction_writes_nothing(tiny, tmp_path, capsys):
    """A model fitted relative to line pressure, on data without it: the DataError names the
    experiment, and no half-written folder is left."""
    from clutchlab.residual_ml import SVCPartitionedGP

    ds = tiny[2]
    train = ds.select(ramps=["fast", "slow"])
    model = SVCPartitionedGP(latch_model="classifier").fit(train)
    assert model.latched_reference_ == "line"
    model.save(tmp_path / "svc" / "model.json")
    unlogged = Dataset(
        [
            Trace(t.name, {k: v for k, v in t.signals.items() if k != "line_pressure_bar"},
                  meta=dict(t.meta))
            for t in ds
        ]
    )  # fmt: skip
    save_dataset(unlogged, tmp_path / "noline")
    out = tmp_path / "out"
    assert _run(tmp_path / "svc" / "model.json", tmp_path / "noline", "--out", out) == 2
    assert "no line_pressure_bar" in capsys.readouterr().err
    assert not out.exists()


def test_logs_under_the_loggers_names_are_read_through_map(tiny, tmp_path, capsys):
    from test_cli_map import LOGGER, MAP_TOML

    root, _, ds = tiny
    logs, canonical = tmp_path / "logs", tmp_path / "canonical"
    for folder in (logs, canonical):
        save_dataset(ds, folder)
    for tr in ds:  # the same signals both ways: the logger's names and kPa, or canonical
        df = pd.read_csv(canonical / f"{tr.name}.csv")
        df = df[[c for c in df.columns if c in LOGGER]]
        df.to_csv(canonical / f"{tr.name}.csv", index=False)
        df = pd.DataFrame({LOGGER[c][0]: df[c] * LOGGER[c][1] for c in df.columns})
        df.to_csv(logs / f"{tr.name}.csv", index=False)
    cmap = tmp_path / "logger.toml"
    cmap.write_text(MAP_TOML, encoding="utf-8")
    argv = [root / "fit.json", "--ramps", "medium", "--no-figures", "--out"]
    assert _run(argv[0], logs, *argv[1:], tmp_path / "unmapped") == 2
    assert "clutch_pressure_bar" in capsys.readouterr().err
    assert _run(argv[0], logs, *argv[1:], tmp_path / "mapped", "--map", cmap) == 0
    assert _run(argv[0], canonical, *argv[1:], tmp_path / "plain") == 0
    mapped = pd.read_csv(tmp_path / "mapped" / "metrics.csv")
    plain = pd.read_csv(tmp_path / "plain" / "metrics.csv")
    pd.testing.assert_frame_equal(mapped, plain, rtol=1e-6)


def test_an_exported_fmu_predicts_like_the_model_it_was_exported_from(tiny, tmp_path, capsys):
    from clutchlab.physics.fmu import export_physics_fmu

    root, data, ds = tiny
    fmu = export_physics_fmu(root / "fit.json", tmp_path / "fit.fmu", drive="measured")
    out, js = tmp_path / "out", tmp_path / "p.json"
    argv = [fmu, data, "--ramps", "medium", "--no-figures", "--json", js, "--out", out]
    assert _run(*argv) == 0
    doc = json.loads(js.read_text())
    assert doc["model_kind"] == "FMU"
    (name,) = doc["experiments"]
    frame = pd.read_csv(out / "predictions" / f"{name}.csv")
    in_process = load_predictor(root / "fit.json").model.predict(ds[name])
    gap = np.max(np.abs(frame["predicted_bar"] - in_process))
    assert gap < 1e-3, gap  # bar: the same model (measured 5e-5, the CSV's 6 digits)
    assert _run(fmu, data, "--out", tmp_path / "no", "--substeps", "8") == 2
    assert "not used by an FMU" in capsys.readouterr().err
