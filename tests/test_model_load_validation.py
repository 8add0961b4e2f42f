"""Saved models are checked on load, save and FMU export (issue 18, item 9).

Each test damages a valid saved model in one way (a missing key, a wrong shape, a NaN
array, a zero scale, a wrong type, ...) and asserts one ``ModelFileError`` that names the
file and the key or array. Before ``clutchlab.residual_ml.model_check`` these loaded with
KeyError / TypeError / broadcast tracebacks, or loaded and predicted NaN, and
``export-fmu`` wrote an FMU of them ("no problems").
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clutchlab.errors import FitError, ModelError, ModelFileError
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand
from clutchlab.residual_ml import (
    GPBaseline,
    HybridModel,
    PhysicsPredictor,
    SVCPartitionedGP,
    check_model,
    load_model,
    save_model,
)
from clutchlab.residual_ml.hybrid import HYBRID_FEATURES

#: Tiny GPs: these tests check the loader, not accuracy (each model fits in < 0.2 s).
SMALL = {"n_hyper": 100, "max_points": 60}


@pytest.fixture(scope="module")
def trace():
    """One short fast-ramp stand experiment (2.9 s at 1 kHz, 30 Hz dither)."""
    config = StandConfig(
        settings=(DitherSetting(30.0, "A"),),
        ramps=(RampProfile("fast", 1.0, 0.3),),
        substeps=2,
        seed=1,
    )
    return run_stand(config, progress=False).dataset[0]


@pytest.fixture(scope="module")
def saved(trace, tmp_path_factory):
    """Valid saved models: GP baseline, SVC-partitioned GP (with its classifier), hybrid."""
    folder = tmp_path_factory.mktemp("saved")
    models = {
        "gp": GPBaseline(**SMALL),
        "svc": SVCPartitionedGP(**SMALL),
        "hybrid": HybridModel(
            physics=PhysicsPredictor(substeps=2),
            residual=SVCPartitionedGP(features=HYBRID_FEATURES, **SMALL),
        ),
    }
    out = {}
    for name, model in models.items():
        model.fit([trace])
        save_model(model, folder / f"{name}.json")
        out[name] = folder / f"{name}.json"
    assert load_model(out["svc"]).decision_ is not None  # the classifier's arrays are there
    return out


def damaged(src: Path, folder: Path, doc=None, arrays=None) -> Path:
    """A copy of the saved model ``src`` in ``folder`` (as ``m.json`` + ``m.npz``), its
    document passed through ``doc(d)`` and its arrays through ``arrays(a)`` (in place)."""
    d = json.loads(src.read_text())
    with np.load(src.with_suffix(".npz"), allow_pickle=False) as f:
        a = {k: f[k] for k in f.files}
    if doc is not None:
        doc(d)
    if arrays is not None:
        arrays(a)
    d["arrays"] = "m.npz"
    folder.mkdir(parents=True, exist_ok=True)
    np.savez(folder / "m.npz", **a)
    (folder / "m.json").write_text(json.dumps(d))
    return folder / "m.json"


def refused(path: Path) -> ModelFileError:
    with pytest.raises(ModelFileError) as info:
        load_model(path)
    assert str(path) in str(info.value)
    return info.value


def test_valid_models_load_and_predict_as_saved(saved, trace):
    for path in saved.values():
        model = load_model(path)
        assert np.isfinite(model.predict(trace)).all()
        check_model(model)  # the in-memory check passes on a valid model


def test_every_constructor_parameter_has_a_rule():
    """A parameter added to an estimator must get a rule in the check, or files carrying
    a bad value for it would load unchecked."""
    from clutchlab.residual_ml.model_check import _PARAM_RULES, MODEL_CLASSES

    for cls in MODEL_CLASSES.values():
        assert set(cls._get_param_names()) <= set(_PARAM_RULES), cls.__name__


def test_missing_keys_are_named(saved, tmp_path):
    def drop(d):
        del d["state"]["feature_names"]
        del d["state"]["gps"]["0"]["y_scale"]

    err = refused(damaged(saved["svc"], tmp_path, doc=drop))
    assert "state.feature_names: missing key" in err.problems
    assert "state.gps.0.y_scale: missing key" in err.problems
    assert isinstance(err, ModelError) and isinstance(err, ValueError)


def test_missing_array_is_named(saved, tmp_path):
    err = refused(damaged(saved["gp"], tmp_path, arrays=lambda a: a.pop("gp.dual_coef")))
    assert err.problems == ["array 'gp.dual_coef' in m.npz: missing"]


def test_wrong_shapes_are_named_with_the_expected_shape(saved, tmp_path):
    def reshape(a):
        a["gp0.x_scale"] = a["gp0.x_scale"][:2]
        a["gp0.dual_coef"] = a["gp0.dual_coef"][:-1]
        a["clf.support"] = a["clf.support"][:, :3]

    err = refused(damaged(saved["svc"], tmp_path, arrays=reshape))
    text = "\n".join(err.problems)
    assert "array 'gp0.x_scale' in m.npz: has shape (2,), expected (5,)" in text
    assert "array 'gp0.dual_coef' in m.npz: has shape" in text and "expected (" in text
    assert "array 'clf.support' in m.npz: has shape" in text
    assert len(err.problems) == 3  # every problem at once


def test_nan_and_inf_arrays_are_refused(saved, tmp_path):
    def poison(a):
        a["gp0.dual_coef"][3] = np.nan
        a["gp0.X_bins"][0, 1] = np.inf
        a["clf.coef"][0] = -np.inf

    err = refused(damaged(saved["svc"], tmp_path, arrays=poison))
    text = "\n".join(err.problems)
    assert "array 'gp0.dual_coef' in m.npz: 1 value(s) not finite, first at index 3" in text
    assert "array 'gp0.X_bins' in m.npz: 1 value(s) not finite, first at index (0, 1)" in text
    assert "array 'clf.coef' in m.npz" in text


def test_zero_and_negative_scales_are_refused(saved, tmp_path):
    def zero(a):
        a["gp0.x_scale"][0] = 0.0
        a["gp0.w_bins"][1] = -1.0
        a["clf.scale"][2] = 0.0
        a["gp0.theta"][1] = -1e4  # exp(−10⁴) = 0: a zero length scale

    def zero_doc(d):
        d["state"]["gps"]["0"]["y_scale"] = 0.0

    err = refused(damaged(saved["svc"], tmp_path, doc=zero_doc, arrays=zero))
    text = "\n".join(err.problems)
    assert "state.gps.0.y_scale: must be > 0, got 0.0" in text
    assert "array 'gp0.x_scale' in m.npz: 1 value(s) not positive" in text
    assert "array 'gp0.w_bins' in m.npz: 1 value(s) not positive" in text
    assert "array 'clf.scale' in m.npz: 1 value(s) not positive" in text
    assert (
        "array 'gp0.theta' in m.npz: log-hyperparameter(s) log_length_0 = [-10000.0] outside "
        "the fit's bounds" in text
    )


def test_finite_values_no_fit_gives_are_refused(saved, tmp_path):
    """Positive and finite, but the prediction would overflow to inf / NaN."""

    def extreme(a):
        a["gp.x_scale"][1] = 1e-320  # z = (x − mean) / scale = inf
        a["gp.dual_coef"][0] = 1e308  # Σ weights · s² overflows
        a["gp.w_bins"][2] = 1e-320  # bin noise σ² / w = inf
        a["gp.X_bins"][3, 0] = 1e300  # 10³⁰⁰ standard deviations from the training data

    err = refused(damaged(saved["gp"], tmp_path, arrays=extreme))
    assert err.problems == [
        "array 'gp.x_scale' in m.npz: value(s) at index [1] below 1e-12·max(1, |x_mean|) "
        "(no fit gives them)",
        "array 'gp.X_bins' in m.npz: standardized value(s) beyond 1e+06 standard deviations",
        "array 'gp.w_bins' in m.npz: weight(s) so small that the bin noise σ²/w is infinite",
        "array 'gp.dual_coef' in m.npz: weights so large that the predictive mean overflows",
    ]


def test_wrong_types_are_named(saved, tmp_path):
    def retype(d):
        d["state"]["feature_names"] = 5
        d["state"]["gps"]["0"]["y_mean"] = "x"
        d["params"]["n_hyper"] = "lots"
        d["params"]["knot_tol"] = None

    def text_array(a):
        a["gp0.x_mean"] = np.array(["a"] * a["gp0.x_mean"].size)

    err = refused(damaged(saved["svc"], tmp_path, doc=retype, arrays=text_array))
    text = "\n".join(err.problems)
    assert "state.feature_names: must be a list of strings, got 5" in text
    assert "state.gps.0.y_mean: must be a number, got 'x'" in text
    assert "params.n_hyper: must be an integer, got 'lots'" in text
    assert "params.knot_tol: must be a number, got None" in text
    assert "array 'gp0.x_mean' in m.npz: must hold real numbers, has dtype <U1" in text


def test_unknown_version_class_and_keys_are_refused(saved, tmp_path):
    def alien(d):
        d["version"] = 2
        d["params"]["residual"] = {"__estimator__": {"class": "os.system", "params": {}}}
        d["state"]["physics"]["params"]["nope"] = 1.0
        d["state"]["extra"] = 1

    err = refused(damaged(saved["hybrid"], tmp_path, doc=alien))
    text = "\n".join(err.problems)
    assert "version: format version 2 is unknown (this release reads 1)" in text
    assert "params.residual.__estimator__.class: must be one of" in text and "os.system" in text
    assert "state.physics:" in text and "nope" in text
    assert "state: unknown key(s) extra" in text
    d = json.loads(saved["gp"].read_text())
    d["class"] = "LocalGPRegressor"
    (tmp_path / "c.json").write_text(json.dumps(d))
    assert "class: must be one of" in "\n".join(refused(tmp_path / "c.json").problems)


def test_an_array_file_outside_the_model_folder_is_never_read(saved, tmp_path):
    d = json.loads(saved["gp"].read_text())
    (tmp_path / "up").mkdir()
    d["arrays"] = "../" + saved["gp"].with_suffix(".npz").name
    (tmp_path / "up" / "m.json").write_text(json.dumps(d))
    err = refused(tmp_path / "up" / "m.json")
    assert "arrays: must be a file name beside the JSON (no folder)" in err.problems[0]
    # a symlink beside the JSON that points out of the folder
    (tmp_path / "link").mkdir()
    d["arrays"] = "m.npz"
    (tmp_path / "link" / "m.json").write_text(json.dumps(d))
    os.symlink(saved["gp"].with_suffix(".npz"), tmp_path / "link" / "m.npz")
    with pytest.raises(ModelFileError, match="links outside the model's folder"):
        load_model(tmp_path / "link" / "m.json")


class _Marker:
    """Unpickling this creates the file ``path`` (it must never happen)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self):
        return (Path.touch, (self.path,))


def test_a_pickle_in_the_npz_is_refused_and_never_unpickled(saved, tmp_path):
    marker = tmp_path / "unpickled"

    def add_pickle(a):
        a["gp.x_mean"] = np.array([_Marker(marker)], dtype=object)

    path = damaged(saved["gp"], tmp_path / "m", arrays=add_pickle)
    with np.load(path.with_suffix(".npz"), allow_pickle=True) as f:  # it is a real pickle
        assert f["gp.x_mean"].dtype == object
    marker.unlink()
    err = refused(path)
    assert err.problems[0].startswith("array file m.npz: cannot be read: ValueError")
    assert "allow_pickle=False" in err.problems[0]
    assert not marker.exists()


def test_a_truncated_or_foreign_npz_is_refused(saved, tmp_path):
    path = damaged(saved["svc"], tmp_path)
    npz = path.with_suffix(".npz")
    npz.write_bytes(npz.read_bytes()[: npz.stat().st_size // 2])
    with pytest.raises(ModelFileError, match=r"array file m\.npz: cannot be read"):
        load_model(path)
    np.save(npz.with_suffix(".npy"), np.zeros(3))
    npz.write_bytes(npz.with_suffix(".npy").read_bytes())  # one array, not an archive
    with pytest.raises(ModelFileError, match=r"array file m\.npz: not an NPZ archive"):
        load_model(path)


def test_leftover_arrays_and_inconsistent_features_are_refused(saved, tmp_path):
    def extra(a):
        a["gp9.theta"] = np.zeros(3)

    def features(d):
        d["params"]["features"] = ["current_mA", "dither_amp_mA", "didt_mA_s"]

    err = refused(damaged(saved["gp"], tmp_path, doc=features, arrays=extra))
    text = "\n".join(err.problems)
    assert "arrays in m.npz: unexpected array(s) 'gp9.theta'" in text
    assert "state.feature_names: ['current_mA', 'dither_amp_mA', 'dither_freq_Hz'] are not" in text


def test_a_model_damaged_in_memory_is_neither_saved_nor_exported(saved, tmp_path):
    model = load_model(saved["gp"])
    model.gp_.x_scale_ = np.zeros_like(model.gp_.x_scale_)
    with pytest.raises(ModelFileError, match=r"in-memory GPBaseline") as info:
        check_model(model)
    assert info.value.problems == [
        "array 'gp.x_scale' in model.npz: 3 value(s) not positive, first at index 0: 0.0"
    ]
    with pytest.raises(ModelFileError, match="x_scale"):
        save_model(model, tmp_path / "bad.json")
    assert list(tmp_path.iterdir()) == []  # nothing written


def _cli(*args: str) -> subprocess.CompletedProcess:
    root = Path(__file__).resolve().parents[1]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]),
    }
    return subprocess.run(
        [sys.executable, "-m", "clutchlab.cli", *args],
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )


def test_export_fmu_of_a_corrupt_model_fails_before_writing(saved, tmp_path):
    def zero(a):
        a["gp.x_scale"][0] = 0.0
        a["gp.dual_coef"][0] = np.nan

    path = damaged(saved["gp"], tmp_path / "m", arrays=zero)
    out = tmp_path / "gp.fmu"
    res = _cli("export-fmu", str(path), "--out", str(out))
    assert res.returncode == 2, res.stdout + res.stderr
    assert "export-fmu: error" in res.stderr and str(path) in res.stderr
    assert "array 'gp.x_scale' in m.npz: 1 value(s) not positive" in res.stderr
    assert "array 'gp.dual_coef' in m.npz: 1 value(s) not finite" in res.stderr
    assert "Traceback" not in res.stderr and not out.exists()
    # a damaged model that lost its "class" is still read as a model, not as a fit result
    d = json.loads(path.read_text())
    del d["class"]
    path.write_text(json.dumps(d))
    res = _cli("export-fmu", str(path), "--out", str(out))
    assert res.returncode == 2 and "class: missing key" in res.stderr and not out.exists()


def test_fit_result_with_unknown_nonfinite_or_out_of_bounds_values_is_refused(tmp_path):
    from fmu_support import fit_result

    from clutchlab.physics.fit import FitResult

    doc = json.loads(fit_result(("sensor_lag",)).to_json())
    doc["values"]["nope"] = 1.0
    doc["values"]["vfs_K_m"] = float("nan")
    doc["values"]["reg_F_c"] = 1e9
    doc["units"]["reg_F_c"] = "kN"
    doc["free"].append("zzz")
    del doc["status"]
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(doc, allow_nan=True))
    with pytest.raises(ModelFileError) as info:
        FitResult.from_json(path)
    err = info.value
    assert isinstance(err, FitError)  # callers that catch FitError still do
    assert str(path) in str(err)
    assert err.problems == [
        "status: missing key",
        "values.vfs_K_m: vfs_K_m = nan is not finite",
        "values.reg_F_c: reg_F_c = 1000000000.0 N outside bounds [0.01, 5.0] N",
        "values.nope: unknown parameter",
        "units.reg_F_c: 'kN', but the model's unit is 'N'",
        "free: unknown parameter(s) ['zzz']",
    ]
    res = _cli("export-fmu", str(path), "--out", str(tmp_path / "p.fmu"))
    assert res.returncode == 2 and "values.nope: unknown parameter" in res.stderr
    assert not (tmp_path / "p.fmu").exists()


def test_gp_spec_refuses_values_an_fmu_cannot_start_with():
    from clutchlab.physics.fmu import GPSpec

    good = {
        "kernel": "rbf",
        "x_mean": np.zeros(2),
        "x_scale": np.ones(2),
        "length_scales": np.ones(2),
        "alpha": 1.0,
        "points": np.zeros((3, 2)),
        "weights": np.ones(3),
        "y_mean": 0.0,
    }
    GPSpec(**good)
    bad = {**good, "x_scale": np.array([1.0, 0.0]), "weights": np.array([1.0, np.nan, 1.0])}
    with pytest.raises(ModelError, match=r"weights must be finite.*x_scale must be finite and > 0"):
        GPSpec(**bad)


def test_fit_result_without_a_value_for_a_fitted_parameter_is_refused(tmp_path):
    """Without the check the datasheet value stood in silently (export-fmu), or evaluate
    crashed with a KeyError after scoring."""
    from fmu_support import fit_result

    from clutchlab.physics.fit import FitResult

    doc = json.loads(fit_result(("sensor_lag",)).to_json())
    name = doc["free"][0]
    del doc["values"][name]
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ModelFileError) as info:
        FitResult.from_json(path)
    assert info.value.problems == [f"values: no value for the fitted parameter(s) [{name!r}]"]
