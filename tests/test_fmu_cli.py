"""``clutchlab export-fmu`` through the console entry point; the slow end-to-end check."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from fmpy.validation import validate_fmu
from fmu_support import fit_json

from clutchlab.data import dither_period_mean, dither_period_samples, pressure_metrics
from clutchlab.errors import FitError
from clutchlab.physics import CircuitModel, SimulationSettings, simulate
from clutchlab.physics.fit import FitSettings, PhysicsFitter
from clutchlab.physics.fmu import FmuPhysics, export_physics_fmu
from clutchlab.physics.stand import RAMPS, DitherSetting, StandConfig, run_stand


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "clutchlab.cli", *args],
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_export_fmu_cli_writes_a_valid_fmu_and_json(tmp_path):
    out, js = tmp_path / "plant.fmu", tmp_path / "summary.json"
    res = _cli("export-fmu", str(fit_json()), "--out", str(out), "--json", str(js))
    assert res.returncode == 0, res.stderr
    assert "fmpy.validation: no problems" in res.stdout
    assert validate_fmu(str(out)) == []
    doc = json.loads(js.read_text())
    assert doc["inputs"][0] == "current_cmd_mA" and "latch_state" in doc["outputs"]
    assert doc["validation_problems"] == []


def test_export_fmu_out_never_replaces_a_users_file_or_the_input(tmp_path):
    """An earlier FMU is replaced; a user's file of another kind, or the fit itself, never."""
    from clutchlab.cli import main

    fit = fit_json()
    mine = tmp_path / "own.fmu"
    mine.write_text("my notes, not an FMU")
    assert main(["export-fmu", str(fit), "--out", str(mine)]) == 2
    assert mine.read_text() == "my notes, not an FMU"
    before = fit.read_bytes()
    assert main(["export-fmu", str(fit), "--out", str(fit)]) == 2
    assert fit.read_bytes() == before


def test_export_fmu_cli_names_a_file_that_is_not_a_fit(tmp_path):
    bad = tmp_path / "params.json"
    bad.write_text('{"vfs_K_m": 14.0}')
    res = _cli("export-fmu", str(bad), "--out", str(tmp_path / "x.fmu"))
    assert res.returncode == 2
    assert "export-fmu: error" in res.stderr and "not a fitted physics model" in res.stderr
    assert not (tmp_path / "x.fmu").exists()


def test_export_fmu_names_an_fmu_given_as_the_model(tmp_path):
    """An FMU as the model was "cannot read fit result ... 'utf-8' codec can't decode"."""
    from fmu_support import exported

    res = _cli("export-fmu", str(exported("command")), "--out", str(tmp_path / "x.fmu"))
    assert res.returncode == 2
    assert "is an FMU (a zip archive), not a model to export" in res.stderr
    assert "utf-8" not in res.stderr and not (tmp_path / "x.fmu").exists()


def test_export_fmu_cli_exports_a_saved_gp_model(tmp_path):
    from fmu_support import medium_trace

    from clutchlab.residual_ml import GPBaseline, save_model

    model = tmp_path / "gp_base.json"
    save_model(GPBaseline(max_points=100, n_hyper=200).fit([medium_trace()]), model)
    out = tmp_path / "gp.fmu"
    res = _cli("export-fmu", str(model), "--out", str(out), "--no-std")
    assert res.returncode == 0, res.stderr
    assert "outputs: clutch_pressure_bar [bar]" in res.stdout and validate_fmu(str(out)) == []


@pytest.mark.slow
def test_fitted_model_exported_with_effects_matches_and_reproduces_physics_fitted(tmp_path):
    """End to end on a real fit: stand data with its effects, fit with two effects switched
    on, export both drives, compare on every medium experiment."""
    config = StandConfig(
        settings=(DitherSetting(30.0, "A"), DitherSetting(70.0, "C", "triangle")),
        ramps=(RAMPS["fast"], RAMPS["medium"]),
        seed=5,
    )
    data = run_stand(config, progress=False).dataset
    fitter = PhysicsFitter(
        CircuitModel().with_effects("sensor_lag", "flow_force"),
        FitSettings(train_ramps=("fast",), max_iter=5, progress=False, workers=1),
    )
    try:
        fitter.fit(data)
    except FitError as exc:  # a fit stopped by its iteration limit still has an iterate
        best = exc.result
        fitter = PhysicsFitter.load(best.to_json())
    fit_path = tmp_path / "fit.json"
    fitter.save(fit_path)
    medium = list(data.select(ramps=["medium"]))
    for drive in ("command", "measured"):
        fmu = export_physics_fmu(fit_path, tmp_path / f"{drive}.fmu", drive=drive)
        assert validate_fmu(str(fmu)) == []
        physics = FmuPhysics(fmu)
        for tr in medium:
            ref = simulate(fitter.model_, fitter.params_, tr, SimulationSettings(drive=drive))
            assert np.abs(physics.predict(tr) - ref.pressure_bar).max() <= 0.01
    meas, a, b = [], [], []
    physics = FmuPhysics(tmp_path / "measured.fmu")
    for tr in medium:
        n = dither_period_samples(tr)
        meas.append(dither_period_mean(tr.get("clutch_pressure_bar"), n))
        a.append(dither_period_mean(fitter.predict(tr), n))
        b.append(dither_period_mean(physics.predict(tr), n))
    ma = pressure_metrics(np.concatenate(meas), np.concatenate(a))
    mb = pressure_metrics(np.concatenate(meas), np.concatenate(b))
    assert abs(ma["rmse_bar"] - mb["rmse_bar"]) <= 0.01


def test_export_fmu_cli_exports_a_design_before_any_fit(tmp_path, capsys):
    """A design engineer's parameter file was refused as 'not a fitted physics model' (then,
    session 42, with a Python recipe): ``params --out`` writes the datasheet values to edit,
    and ``export-fmu`` exports them with the effects their parameters belong to."""
    from clutchlab.cli import main
    from clutchlab.physics import drive_trace, knot_profile

    design = tmp_path / "design.json"
    assert (
        main(
            [
                "params",
                "--effects",
                "sensor_lag",
                "--out",
                str(design),
                "--json",
                str(tmp_path / "t.json"),
            ]
        )
        == 0
    )
    doc = json.loads(design.read_text(encoding="utf-8"))
    doc["parameters"]["vfs_d_orf"]["value"] = 0.6
    doc["parameters"]["slag_tau"]["value"] = 5.0
    design.write_text(json.dumps(doc), encoding="utf-8")
    out = tmp_path / "d.fmu"
    assert main(["export-fmu", str(design), "--out", str(out)]) == 0, capsys.readouterr().err
    assert "fmpy.validation: no problems" in capsys.readouterr().out
    model = CircuitModel().with_effects("sensor_lag")
    params = model.default_params().replace(vfs_d_orf=0.6, slag_tau=5.0)
    t, i = knot_profile([0.0, 0.3, 2.3, 2.6, 4.6], [0.0, 0.0, 1100.0, 1100.0, 0.0])
    trace = drive_trace(t, i, dither_amp_mA=100.0, dither_freq_Hz=50.0)
    ref = simulate(model, params, trace).pressure_bar
    sim = FmuPhysics(out).simulate(trace).pressure_bar
    assert np.ptp(ref) > 5.0 and np.abs(sim - ref).max() <= 0.01
    # a name that no model has is named; nothing is written
    doc["parameters"]["nope"] = {"value": 1.0, "unit": "-"}
    design.write_text(json.dumps(doc), encoding="utf-8")
    assert main(["export-fmu", str(design), "--out", str(tmp_path / "e.fmu")]) == 2
    assert "nope" in capsys.readouterr().err and not (tmp_path / "e.fmu").exists()
