"""The latched plateau relative to line pressure (``SVCPartitionedGP(latched_reference=...)``).

The latched clutch sees line pressure less a small offset; line pressure wanders with
the supply, which the ML features (current, dither, dI/dt) cannot see. With the line
reference the latched GP learns the offset and the prediction follows the logged line
pressure.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from synthetic import tiny_stand

from clutchlab.data import Trace, dither_period_mean, dither_period_samples
from clutchlab.errors import DataError, ModelError
from clutchlab.physics.fmu import ml_program_from
from clutchlab.residual_ml import HybridModel, PhysicsPredictor, SVCPartitionedGP, load_model
from clutchlab.residual_ml.hybrid import HYBRID_FEATURES
from clutchlab.validation.metrics import compare_experiment, pool_comparisons

SMALL = {"n_hyper": 300, "max_points": 300}


@pytest.fixture(scope="module")
def data():
    return tiny_stand(3)


@pytest.fixture(scope="module")
def models(data):
    train = data.select(ramps=["fast", "slow"])
    return {
        ref: SVCPartitionedGP(latched_reference=ref, **SMALL).fit(train) for ref in ("none", "line")
    }


def _shifted(trace: Trace, dp: float) -> Trace:
    """The trace with line pressure, and the latched clutch pressure with it, moved by dp."""
    line = trace.get("line_pressure_bar")
    p = trace.get("clutch_pressure_bar")
    latched = p > line - 1.0
    return trace.with_signals(
        line_pressure_bar=line + dp, clutch_pressure_bar=np.where(latched, p + dp, p)
    )


def _plateau_rmse(model, trace) -> float:
    n = dither_period_samples(trace)
    y = dither_period_mean(trace.get("clutch_pressure_bar"), n)
    yh = dither_period_mean(model.predict(trace), n)
    line = dither_period_mean(trace.get("line_pressure_bar"), n)
    both = (y > line - 1.0) & (yh > line - 1.0)
    assert both.sum() > 100
    return float(np.sqrt(np.mean((yh - y)[both] ** 2)))


def test_the_line_reference_follows_line_pressure(models, data):
    assert models["line"].latched_reference_ == "line"
    assert models["none"].latched_reference_ == "none"
    test = _shifted(data["medium_30Hz_A"], 0.6)  # supply 0.6 bar above anything trained
    err_none, err_line = _plateau_rmse(models["none"], test), _plateau_rmse(models["line"], test)
    assert err_line < 0.1 < err_none, (err_none, err_line)
    # The unlatched branch does not depend on the reference (evaluated at every sample:
    # the path knots depend on both GPs' resolutions).
    F = models["line"]._trace_matrix(test)
    a = models["none"]._predict_matrix(F, path=False, return_std=False)
    b = models["line"]._predict_matrix(
        F, path=False, return_std=False, ref=test.get("line_pressure_bar")
    )
    low = test.get("clutch_pressure_bar") < 8.0
    np.testing.assert_allclose(a[low], b[low], atol=1e-9)


def test_prediction_needs_line_pressure_when_fitted_with_it(models, data):
    tr = data["medium_70Hz_B"]
    bare = Trace(tr.name, {k: v for k, v in tr.signals.items() if k != "line_pressure_bar"})
    with pytest.raises(DataError, match=r"medium_70Hz_B: no line_pressure_bar") as info:
        models["line"].predict(bare)
    # the remedy a command-line user has (the message named only a Python argument)
    assert "line_pressure_bar = 17.7 under [defaults] in its channel map" in str(info.value)
    logged = Trace(tr.name, bare.signals, source="logs/r10s_run2.csv")
    with pytest.raises(DataError, match=r"medium_70Hz_B \(logs/r10s_run2.csv\): no line_"):
        models["line"].predict(logged)
    models["none"].predict(bare)  # the paper's form needs none
    with pytest.raises(ModelError, match="relative to line pressure"):
        models["line"].predict(models["line"]._trace_matrix(tr))


def test_training_without_line_pressure_falls_back(data):
    train = [
        Trace(t.name, {k: v for k, v in t.signals.items() if k != "line_pressure_bar"}, t.meta)
        for t in data.select(ramps=["fast", "slow"])
    ]
    model = SVCPartitionedGP(**SMALL).fit(train)
    assert model.latched_reference_ == "none"
    with pytest.raises(ModelError, match="latched_reference"):
        SVCPartitionedGP(latched_reference="supply", **SMALL).fit(train)


def test_save_load_keeps_the_reference(models, data, tmp_path):
    tr = data["medium_30Hz_A"]
    models["line"].save(tmp_path / "m.json")
    back = load_model(tmp_path / "m.json")
    assert back.latched_reference_ == "line"
    np.testing.assert_array_equal(back.predict(tr), models["line"].predict(tr))
    # A file written before the line reference loads as the paper's form.
    doc = json.loads((tmp_path / "m.json").read_text())
    state = doc["state"] if "state" in doc else doc
    assert state.pop("latched_reference") == "line"
    (tmp_path / "old.json").write_text(json.dumps(doc))
    (tmp_path / "old.npz").write_bytes((tmp_path / "m.npz").read_bytes())
    assert load_model(tmp_path / "old.json").latched_reference_ == "none"


def test_fmu_program_takes_line_pressure_for_the_plateau(models):
    prog = ml_program_from(models["line"], with_std=False, approximate_didt=True)
    line = {v.name: v for v in prog.inputs}["line_pressure_bar"]
    assert "latched plateau" in line.description
    prog_none = ml_program_from(models["none"], with_std=False, approximate_didt=True)
    assert "not used" in {v.name: v for v in prog_none.inputs}["line_pressure_bar"].description


def test_hybrid_residual_ignores_the_reference_its_standalone_form_uses_it(data):
    train = data.select(ramps=["fast", "slow"])
    hyb = HybridModel(
        physics=PhysicsPredictor(substeps=2),
        residual=SVCPartitionedGP(features=HYBRID_FEATURES, **SMALL),
        form="residual",
    ).fit(train)
    assert hyb.residual_.latched_reference_ == "none"  # the physics follows line already
    alone = HybridModel(physics=PhysicsPredictor(substeps=2), form="standalone")._standalone()
    assert alone.latched_reference == "line"


def test_latched_plateau_metric_counts_only_where_both_are_latched():
    i = np.linspace(0, 1000, 200)
    line = np.full(200, 17.7)
    measured = np.where(i > 500, 17.6, 5.0)
    predicted = np.where(i > 600, 17.5, 5.0)  # latches later, then 0.1 bar low
    c = compare_experiment("x", i, np.ones(200), line, measured, predicted)
    pooled = pool_comparisons([c])
    assert pooled["latched_plateau_samples"] == int(np.sum(i > 600))
    assert pooled["latched_plateau_rmse_bar"] == pytest.approx(0.1)
    # With time, the samples within plateau_guard_s (50 ms) of either snap are left out.
    t = np.arange(200) * 0.01
    spike = np.where((i > 600) & (i < 620), 16.9, predicted)  # a snap transient: 0.8 bar
    c = compare_experiment("x", i, np.ones(200), line, measured, spike, time_s=t)
    pooled = pool_comparisons([c])
    first = np.flatnonzero(i > 600)[0]
    assert pooled["latched_plateau_samples"] == int(np.sum((i > 600) & (t >= t[first] + 0.045)))
    assert pooled["latched_plateau_rmse_bar"] == pytest.approx(0.1)


def test_interval_coverage_by_region():
    from clutchlab.validation.metrics import interval_coverage

    t = np.arange(1000) * 0.01  # 10 s
    line = np.full(1000, 17.7)
    measured = np.where((t > 4.0) & (t < 7.0), 17.6, 5.0)
    predicted = measured + 0.1
    predicted[(t > 3.9) & (t < 4.1)] = 5.0  # latches 0.1 s late
    std = np.full(1000, 0.06)  # covers the 0.1 bar offset at 2σ, not the late snap
    got = interval_coverage(t, line, measured, predicted, std)
    assert sum(total for _, total in got.values()) == 1000
    assert abs(got["latch_window"][1] - 2 * 31) <= 2  # ±0.15 s around both snaps
    assert got["regulated"][0] == got["regulated"][1] > 600  # all covered
    assert got["latched"][0] == got["latched"][1] > 200
    late = int(np.sum((t > 4.0) & (t < 4.1)))  # the late snap: outside ±2σ
    assert got["latch_window"][0] == got["latch_window"][1] - late
