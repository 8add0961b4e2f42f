"""The report folder keeps the fitted models: the models scored there are the models a user
then predicts new logs with or exports as an FMU, without fitting again (evaluate and demo
kept none: the physics fit had to be run again for `export-fmu`)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fit_support import synthetic_fit

from clutchlab.cli import main
from clutchlab.physics import CircuitModel
from clutchlab.physics.fit import PhysicsFitter
from clutchlab.physics.fmu import physics_source
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand
from clutchlab.residual_ml import load_model
from clutchlab.validation import evaluate, write_report


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    ramps = (("fast", 0.8), ("medium", 1.4), ("slow", 2.0))
    config = StandConfig(
        settings=(DitherSetting(50.0, "A"), DitherSetting(70.0, "B")),
        ramps=tuple(RampProfile(r, d, 0.2) for r, d in ramps),
        substeps=2,
        seed=4,
    )
    ds = run_stand(config, progress=False).dataset
    reg_f0 = CircuitModel().default_params()["reg_F0"] * 1.03
    fit = synthetic_fit(
        {"reg_F0": reg_f0}, train=[t.name for t in ds.select(ramps=["fast", "slow"])]
    )
    fitter = PhysicsFitter.load(fit.to_json())
    ev = evaluate(
        ds,
        ["physics_default", "physics_fitted", "gp_didt", "hybrid"],
        options={"physics_fitted": {"fitted": fitter}},
        progress=False,
        classifiers=False,
        bands=False,
        command="pytest",
    )
    out = tmp_path_factory.mktemp("report_models") / "report"
    files = write_report(ev, out, interactive=False)
    return ev, out, files, ds


def test_every_fitted_variant_is_saved_and_listed(report):
    _ev, out, files, _ = report
    assert sorted(p.name for p in (out / "models").iterdir()) == [
        "gp_didt.json", "gp_didt.npz", "hybrid.json", "hybrid.npz", "physics_fitted.json",
    ]  # fmt: skip
    models = files.doc["models"]
    assert models["files"]["physics_fitted"] == ["models/physics_fitted.json"]
    assert "params --out" in models["not_saved"]["physics_default"]
    assert json.loads((out / "metrics.json").read_text())["models"] == models
    md = (out / "report.md").read_text()
    assert "## Saved models" in md and "clutchlab predict models/<variant>.json" in md
    assert "Saved models" in (out / "report.html").read_text()


def test_the_saved_models_predict_as_the_scored_ones(report):
    ev, out, _, ds = report
    medium = ds.select(ramps=["medium"])[0]
    for name in ("gp_didt", "hybrid"):
        loaded = load_model(out / "models" / f"{name}.json")
        np.testing.assert_array_equal(loaded.predict(medium), ev.models[name].predict(medium))
    _model, params = physics_source(out / "models" / "physics_fitted.json")  # as export-fmu
    assert params["reg_F0"] == ev.models["physics_fitted"].fitter_.params_["reg_F0"]
    hybrid = load_model(out / "models" / "hybrid.json")
    assert sorted(hybrid.train_experiments_) == sorted(ev.protocol.train_names)


def test_predict_takes_a_saved_model_of_the_report(report, tmp_path, capsys):
    ev, out, _, ds = report
    data = tmp_path / "data"
    from clutchlab.data import save_dataset

    save_dataset(ds, data)
    pred = tmp_path / "pred"
    argv = ["predict", str(out / "models" / "physics_fitted.json"), str(data), "--out", str(pred)]
    assert main([*argv, "--ramps", "medium", "--no-figures", "--quiet", "--json",
                 str(tmp_path / "p.json")]) == 0  # fmt: skip
    doc = json.loads((tmp_path / "p.json").read_text())
    assert doc["overall"]["metrics"]["rmse_bar"] == pytest.approx(
        ev.scores["physics_fitted"].metrics["rmse_bar"], rel=1e-9
    )


def test_an_augmented_physics_is_saved_as_the_model_it_simulates(report):
    """augmented_hybrid's physics (the discovery's model and values) is written as a
    PhysicsPredictor with its effects; it predicts what the augmented physics does."""
    from clutchlab.residual_ml.persist import _as_predictor
    from clutchlab.validation.discover.variant import AugmentedPhysics

    _, _, _, ds = report
    aug = AugmentedPhysics()
    aug.model_ = CircuitModel().with_effects("sensor_lag")
    aug.params_ = aug.model_.default_params().replace(slag_tau=12.0)
    aug.train_experiments_ = ["a", "b"]
    saved = _as_predictor(aug)
    assert saved.effects == ("sensor_lag",) and saved.params["slag_tau"] == 12.0
    assert saved.train_experiments == ("a", "b")
    medium = ds.select(ramps=["medium"])[0]
    np.testing.assert_array_equal(saved.predict(medium), aug.predict(medium))
