"""Causal features: models trained with them (``clutchlab train --causal``) export exactly.

Must-show 1 for ``gp_didt``, ``paper_svc_gp`` and ``hybrid``: the FMU's output on the medium
ramp matches the in-process model within 0.01 bar (max). The in-process reference is the
model evaluated at every sample (``knot_tol=0``): its default trace prediction interpolates
between knots, an approximation of the model itself that the FMU does not make.
"""

from __future__ import annotations

import json
import subprocess
import sys
from functools import lru_cache

import numpy as np
import pytest
from fmpy.validation import validate_fmu
from fmu_support import FITTED, TMP

from clutchlab.data import causal_didt, causal_window, didt, save_dataset
from clutchlab.errors import DataError
from clutchlab.physics.fmu import FmuError, FmuPhysics, build_fmu
from clutchlab.physics.fmu.adapters import ml_program_from
from clutchlab.residual_ml import (
    GPWithDerivative,
    HybridModel,
    PhysicsPredictor,
    SVCPartitionedGP,
    load_model,
    save_model,
)
from clutchlab.residual_ml.features import (
    CAUSAL_DIDT_FEATURES,
    DIDT_FEATURES,
    FeatureBuilder,
    causal_features,
)
from clutchlab.residual_ml.hybrid import HYBRID_FEATURES

#: Must-show 1: max |FMU − in-process| on the medium ramp.
SAME_BAR = 0.01
#: Small GPs and SVC: the export is exact at any size; these keep the test short.
SMALL = {"max_points": 400, "n_hyper": 400}


def _causal(names) -> tuple[str, ...]:
    return causal_features(tuple(names))


@lru_cache(maxsize=1)
def _stand():
    from clutchlab.physics.stand import DEFAULT_SETTINGS, StandConfig, run_stand

    data = run_stand(StandConfig(settings=DEFAULT_SETTINGS[::4]), progress=False).dataset
    return list(data.select(ramps=["fast", "slow"])), list(data.select(ramps=["medium"]))


def _command_only(trace):
    """The trace without the measured current: the in-process physics then runs on the
    commanded current, as the FMU's command-drive physics does."""
    signals = {k: v for k, v in trace.signals.items() if k != "current_mA"}
    return type(trace)(trace.name, signals, trace.meta)


@lru_cache(maxsize=3)
def _model(variant: str):
    train, _ = _stand()
    if variant == "gp_didt":
        features = _causal(GPWithDerivative()._builder().names)
        return GPWithDerivative(features=features, **SMALL).fit(train)
    if variant == "paper_svc_gp":
        features = _causal(SVCPartitionedGP()._builder().names)
        return SVCPartitionedGP(features=features, svc_max_points=1000, **SMALL).fit(train)
    own = _causal(f for f in HYBRID_FEATURES if not f.startswith("physics_"))
    residual = SVCPartitionedGP(features=own, svc_max_points=1000, **SMALL)
    # The residual form is what is exported here (the form choice has its own tests).
    physics = PhysicsPredictor(params=FITTED)
    return HybridModel(physics=physics, residual=residual, form="residual").fit(train)


def test_causal_didt_looks_at_past_samples_only_and_follows_a_ramp():
    rng = np.random.default_rng(0)
    fs, n = 1000.0, 5 * 1000.0 / 70.0
    x = np.concatenate([np.zeros(200), 2.5 * np.arange(800)])  # 2500 mA/s from sample 200
    x = x + rng.normal(0.0, 0.1, x.size)
    slope = causal_didt(x, fs, n)
    later = x.copy()
    later[500:] += 50.0 * np.sin(np.arange(later.size - 500))
    np.testing.assert_array_equal(causal_didt(later, fs, n)[:500], slope[:500])
    assert not np.array_equal(didt(later, fs, n)[:500], didt(x, fs, n)[:500])  # centred: not
    window = causal_window(n)
    assert window % 2 == 1 and window >= n
    settled = slope[200 + window :]
    noise = 0.1 * fs * np.sqrt(12.0 / (window * (window**2 - 1)))  # LS slope of white noise
    assert np.abs(settled - 2500.0).max() < 6 * noise
    assert np.all(slope[: 200 - window] == pytest.approx(0.0, abs=6 * noise))


def test_causal_feature_names():
    assert FeatureBuilder(CAUSAL_DIDT_FEATURES).causal
    assert not FeatureBuilder(DIDT_FEATURES).causal
    assert causal_features(DIDT_FEATURES) == CAUSAL_DIDT_FEATURES
    with pytest.raises(DataError, match=r"physics_bar, physics_pilot_bar have no causal"):
        causal_features(("current_mA", "didt_mA_s", "physics_bar", "physics_pilot_bar"))


@pytest.mark.parametrize("variant", ["gp_didt", "paper_svc_gp", "hybrid"])
def test_causal_model_exports_exactly(variant):
    model = _model(variant)
    est = model.residual_ if variant == "hybrid" else model
    assert FeatureBuilder(tuple(est.feature_names_)).causal
    fmu = build_fmu(ml_program_from(model, with_std=False, name=variant), TMP / f"{variant}.fmu")
    assert validate_fmu(str(fmu)) == []
    est.set_params(knot_tol=0.0)  # the model at every sample
    worst = 0.0
    for trace in _stand()[1]:
        trace = _command_only(trace) if variant == "hybrid" else trace
        sim = FmuPhysics(fmu).simulate(trace)
        err = np.abs(sim.pressure_bar - model.predict(trace)).max()
        worst = max(worst, err)
        if variant == "paper_svc_gp":
            latch = est.predict_latch(trace)
            assert np.array_equal(sim.outputs["latch_state"], latch.astype(float))
    print(f"{variant}: max |FMU - in-process| = {worst:.2e} bar")
    assert worst <= SAME_BAR


def test_models_on_centred_or_physics_features_are_refused():
    train, _ = _stand()
    gp = GPWithDerivative(features=DIDT_FEATURES, **SMALL).fit(train[:1])
    with pytest.raises(FmuError, match=r"retrain with `clutchlab train \.\.\. --causal`"):
        ml_program_from(gp)
    hybrid = HybridModel(
        physics=PhysicsPredictor(params=FITTED),
        residual=SVCPartitionedGP(features=HYBRID_FEATURES, **SMALL),
    )
    hybrid.fit(train[:2])
    with pytest.raises(FmuError) as exc:
        ml_program_from(hybrid, approximate_didt=True)
    assert "physics_bar" in str(exc.value) and "not computable in real time" in str(exc.value)


def test_saved_causal_model_keeps_its_features_and_predictions(tmp_path):
    model = _model("paper_svc_gp")
    save_model(model, tmp_path / "m.json")
    back = load_model(tmp_path / "m.json")
    assert back.feature_names_ == model.feature_names_
    trace = _stand()[1][0]
    np.testing.assert_array_equal(back.predict(trace), model.predict(trace))
    assert FeatureBuilder(tuple(back.feature_names_)).causal


def test_train_causal_cli_then_export_fmu(tmp_path):
    train, test = _stand()
    data = tmp_path / "data"
    from clutchlab.data import Dataset

    save_dataset(Dataset([*train[:2], test[0]]), data)
    out, js = tmp_path / "model", tmp_path / "train.json"
    cmd = [sys.executable, "-m", "clutchlab.cli"]
    res = subprocess.run(
        [
            *cmd,
            "train",
            str(data),
            "--variant",
            "gp_didt",
            "--causal",
            "--out",
            str(out),
            "--train",
            f"{train[0].ramp},{train[1].ramp}",
            "--quiet",
            "--json",
            str(js),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 0, res.stderr
    doc = json.loads(js.read_text())
    assert doc["causal"] is True and FeatureBuilder(tuple(doc["features"])).causal
    fmu = tmp_path / "m.fmu"
    res = subprocess.run(
        [*cmd, "export-fmu", str(out / "model.json"), "--out", str(fmu), "--no-std"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 0, res.stderr
    assert "fmpy.validation: no problems" in res.stdout


def _resampled(trace, step_s: float):
    """``trace`` on a grid of ``step_s`` (every signal linear between its samples)."""
    t = np.asarray(trace.time_s, dtype=float)
    grid = t[0] + step_s * np.arange(round((t[-1] - t[0]) / step_s) + 1)
    signals = {k: np.interp(grid, t, np.asarray(v, dtype=float)) for k, v in trace.signals.items()}
    signals["time_s"] = grid
    return type(trace)(trace.name, signals, trace.meta), grid


def test_causal_model_is_exact_at_any_communication_step():
    """The causal dI/dt used to assume 1 ms between FMU steps (``DidtSpec.sample_s``): at
    0.1 ms steps it was 10× too steep over a 10× too short window (5.3 bar from the model
    on the medium ramp). The FMU now resamples the current to 1 ms by its own clock: at
    0.1 ms and at 10 ms steps (inputs linear over a step, as ``FmuPhysics`` sets them) it
    gives the in-process model's values at the 1 ms sample instants."""
    model = _model("gp_didt")
    model.set_params(knot_tol=0.0)
    fmu = build_fmu(ml_program_from(model, with_std=False, name="any_step"), TMP / "any.fmu")
    trace = _stand()[1][0]
    t = np.asarray(trace.time_s, dtype=float)
    ref = model.predict(trace)
    for step_s, every in ((1e-4, 10), (1e-2, 1)):
        fine, grid = _resampled(trace, step_s)
        y = FmuPhysics(fmu, isolate=False).predict(fine)
        on = slice(None, None, every)  # the grid points on 1 ms instants
        err = np.abs(y[on] - np.interp(grid[on], t, ref))
        print(f"{step_s * 1e3:g} ms: max |FMU - in-process| at 1 ms instants {err.max():.2e} bar")
        assert err.max() <= SAME_BAR


def test_ml_export_step_sets_the_default_experiment_and_bounds_the_internal_step(tmp_path):
    """``export-fmu --step`` was ignored for ML models (1 ms default experiment); the
    internal step of an ML FMU is at most the 1 ms of its causal features."""
    import fmpy

    program = ml_program_from(_model("gp_didt"), with_std=False, step_s=0.01, stop_time_s=5.0)
    assert (program.step_s, program.stop_time_s, program.max_step_s) == (0.01, 5.0, 1e-3)
    k = program.parameter_index("max_step_s")
    assert program.parameters[k].start == 1e-3 and program.parameters[k].max == 1e-3
    fmu = build_fmu(program, tmp_path / "m.fmu")
    assert fmpy.read_model_description(str(fmu)).defaultExperiment.stepSize == "0.01"
    with pytest.raises(Exception, match="fmi2ExitInitializationMode"):
        fmpy.simulate_fmu(str(fmu), stop_time=0.1, start_values={"max_step_s": 0.01})


def test_causal_didt_without_dither_counts_the_window_as_offline():
    """At a dither frequency input of 0 Hz the FMU's window was its largest (255 samples);
    offline, data without dither take 5 periods of 50 Hz (session 42): the two now agree."""
    import casadi as ca

    from clutchlab.data import Trace
    from clutchlab.data.demodulate import didt_period_samples
    from clutchlab.physics.fmu.ml import DidtSpec

    rng = np.random.default_rng(1)
    x = np.concatenate([np.zeros(300), 0.4 * np.arange(700)]) + rng.normal(0, 0.2, 1000)
    t = np.arange(x.size) * 1e-3
    bare = Trace("x", {"time_s": t, "current_mA": x, "clutch_pressure_bar": np.zeros(x.size)})
    n = 5.0 * didt_period_samples(bare)
    offline = causal_didt(x, 1000.0, n)
    spec = DidtSpec()
    buf, f = ca.MX.sym("b", spec.max_samples), ca.MX.sym("f")
    slope = ca.Function("s", [buf, f], [spec.slope(buf, f)])
    padded = np.concatenate([np.full(spec.max_samples, x[0]), x])
    for k in (400, 650, 999):
        newest_first = padded[k + spec.max_samples :: -1][: spec.max_samples]
        assert float(slope(newest_first, 0.0)) == pytest.approx(offline[k], rel=1e-9, abs=1e-9)
