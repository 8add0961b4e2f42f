"""Must-show 2 through the report: ``clutchlab evaluate --physics-fmu`` with an FMU that
clutchlab exported gives the in-process fitted model's numbers, and a hybrid on top of it."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest
from fmu_support import exported, fit_json

from clutchlab.data import load_dataset, save_dataset
from clutchlab.errors import ClutchlabError
from clutchlab.physics.fit import PhysicsFitter
from clutchlab.physics.fmu import FmuError, FmuPhysics
from clutchlab.residual_ml import HybridModel, PhysicsPredictor
from clutchlab.validation import Protocol
from clutchlab.validation.evaluate import resolve_variants
from clutchlab.validation.variants import FMU_VARIANT, fmu_variants

#: Must-show 2: the FMU's report numbers against the in-process model's.
SAME_RMSE_BAR = 0.01
ACCURACY_KEYS = ("rmse_bar", "mae_bar", "max_abs_bar")


def _cli() -> list[str]:
    exe = shutil.which("clutchlab")
    return [exe] if exe else [sys.executable, "-m", "clutchlab.cli"]


@pytest.mark.slow
def test_evaluate_physics_fmu_reports_the_in_process_numbers_and_trains_a_hybrid(
    stand_run, tmp_path
):
    """The fitted model exported (measured-current drive, as the in-process model runs on
    stand data) and imported by ``clutchlab evaluate --physics-fmu``: ``physics_fmu`` has the
    numbers the in-process fitted model gets from the same protocol, and the hybrid trained
    on the FMU has those of the hybrid trained on the in-process physics."""
    data = tmp_path / "data"
    save_dataset(stand_run.dataset, data)
    fmu = exported("measured")
    out, js = tmp_path / "report", tmp_path / "metrics.json"
    args = ["evaluate", str(data), "--out", str(out), "--variants", f"{FMU_VARIANT},hybrid"]
    args += ["--physics-fmu", str(fmu), "--fmu-timeout", "300", "--no-classifiers"]
    res = subprocess.run(
        [*_cli(), *args, "--json", str(js), "--quiet"],
        capture_output=True,
        text=True,
        timeout=1200,
    )
    assert res.returncode == 0, res.stderr
    doc = json.loads(js.read_text())
    assert doc["failed"] == {}
    assert list(doc["variants"]) == [FMU_VARIANT, "hybrid"]  # no physics fit was run
    assert doc["details"]["hybrid"]["requires"] == [FMU_VARIANT]
    assert doc["physics_fmu"]["fmu"] == str(fmu)
    assert (out / "report.html").exists()

    protocol = Protocol(load_dataset(data))
    fitter = PhysicsFitter.load(str(fit_json()))
    ref = protocol.score("physics_fitted", fitter).metrics
    got = doc["variants"][FMU_VARIANT]
    for key in ACCURACY_KEYS:
        assert abs(got[key] - ref[key]) <= SAME_RMSE_BAR, (key, got, ref)
    assert ref["rmse_bar"] > 0.02  # a real model error, not a trivial comparison

    hybrid, _ = protocol.fit(HybridModel(physics=PhysicsPredictor.from_fitter(fitter)))
    ref_h = protocol.score("hybrid", hybrid).metrics
    got_h = doc["variants"]["hybrid"]
    print(f"physics_fmu {got}\nin-process {ref}\nhybrid on FMU {got_h}\nin-process {ref_h}")
    # Not max |e|: it sits on a latch snap (~4 bar), where the knots of the estimators' path
    # prediction move with the 1e-11 bar differences between the two physics runs.
    for key in ("rmse_bar", "mae_bar"):
        assert abs(got_h[key] - ref_h[key]) <= SAME_RMSE_BAR, (key, got_h, ref_h)
    assert got_h["mae_bar"] < got["mae_bar"]  # the residual model corrects the physics


def test_physics_fmu_variants_replace_the_fitted_physics_under_the_hybrid():
    """Without --physics-fmu nothing changes; with it the hybrid requires the FMU, not the
    physics fit, and physics_fmu sits beside physics_fitted in the report order."""
    assert FMU_VARIANT not in resolve_variants(None)
    assert resolve_variants(["hybrid"]) == ["physics_fitted", "hybrid"]
    with pytest.raises(ClutchlabError, match=r"unknown variant 'physics_fmu'"):
        resolve_variants([FMU_VARIANT])
    fmu = FmuPhysics(exported("measured"))
    specs = fmu_variants(fmu)
    assert resolve_variants(["hybrid"], specs) == [FMU_VARIANT, "hybrid"]
    both = resolve_variants(["physics_fitted", "hybrid"], specs)
    assert both == ["physics_fitted", FMU_VARIANT, "hybrid"]
    assert FMU_VARIANT in resolve_variants(None, specs)
    assert fmu.label in specs[FMU_VARIANT].description


def test_fmu_parameter_outside_its_declared_range_is_refused():
    """``--fmu-param vfs_K_m=-5`` was accepted although the FMU declares min 5, max 30
    (RMSE 10 bar); now every bad value is named with its bounds, before any run."""
    fmu = exported("measured")
    with pytest.raises(FmuError) as exc:
        FmuPhysics(fmu, parameters={"vfs_K_m": -5.0, "reg_F0": float("nan")})
    text = str(exc.value)
    assert "vfs_K_m = -5 N/A: outside the FMU's declared range [5, 30] N/A" in text
    assert "reg_F0 = nan: not a finite number" in text
    with pytest.raises(FmuError, match=r"vfs_K_m = 31 N/A: outside .* \[5, 30\]"):
        FmuPhysics(fmu, start_values={"vfs_K_m": 31.0})
    FmuPhysics(fmu, parameters={"vfs_K_m": 30.0})  # the bound itself is inside


def test_fmu_parameters_set_and_left_at_start_value_are_reported():
    """``evaluate --help`` promised the parameters left at the FMU's start value in the
    report; neither report.md nor metrics.json named any parameter. Now metrics.json's
    ``physics_fmu`` lists those set, set from each experiment and left at start value, and
    the variant's description (report and metrics.json) names them."""
    from clutchlab.data import Dataset
    from clutchlab.physics.stand import RAMPS, DitherSetting, StandConfig, run_stand
    from clutchlab.validation.evaluate import evaluate

    config = StandConfig(
        settings=(DitherSetting(50.0, "B", "sine"),),
        ramps=(RAMPS["fast"], RAMPS["medium"]),
        seed=5,
    )
    data = Dataset(list(run_stand(config, progress=False).dataset))
    fmu = FmuPhysics(exported("measured"), parameters={"vfs_K_m": 14.0}, isolate=False)
    ev = evaluate(
        data,
        variants=[FMU_VARIANT],
        train=("fast",),
        test=("medium",),
        physics_fmu=fmu,
        progress=False,
        classifiers=False,
        bands=False,
    )
    doc = json.loads(json.dumps(ev.to_dict(), default=str))
    info = doc["physics_fmu"]
    assert info["parameters_set"] == {"vfs_K_m": 14.0}
    assert "dither_wave_sine" in info["parameters_from_trace"]
    left = info["parameters_at_start_value"]
    assert "vfs_K_m" not in left and left["reg_F_c"] == pytest.approx(1.08)
    description = doc["details"][FMU_VARIANT]["description"]
    assert "parameters set: vfs_K_m = 14" in description
    assert f"left at the FMU's start value ({len(left)}): " in description
    assert "reg_F_c" in description
