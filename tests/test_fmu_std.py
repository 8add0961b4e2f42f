"""The exported predictive standard deviation: the fast path keeps its guaranteed bound."""

from __future__ import annotations

import numpy as np
import pytest
from fmu_support import TMP, medium_trace
from test_fmu_ml import gp_std

from clutchlab.errors import ModelError
from clutchlab.physics.fmu import FmuPhysics, build_fmu
from clutchlab.physics.fmu.adapters import STD_TOL_BAR, ml_program_from
from clutchlab.physics.fmu.ml import GPSpec, ml_program
from clutchlab.residual_ml import GPBaseline

BASE = ("current_mA", "dither_amp_mA", "dither_freq_Hz")


def _local_gp(n: int = 400) -> GPSpec:
    """A GP with short length scales on points spread along the ramp's inputs (its kernel
    row is nearly sparse), with its true K⁻¹ (known answer)."""
    rng = np.random.default_rng(11)
    x = np.column_stack(
        [rng.uniform(0, 1100, n), rng.uniform(0, 120, n), rng.choice([30.0, 50.0, 70.0], n)]
    )
    x_mean, x_scale = x.mean(0), x.std(0)
    spec = GPSpec(
        "rbf",
        x_mean=x_mean,
        x_scale=x_scale,
        length_scales=np.array([0.08, 0.3, 0.5]),
        alpha=1.0,
        points=(x - x_mean) / x_scale,
        weights=rng.normal(size=n),
        y_mean=5.0,
        signal_var=0.9,
        y_scale=2.0,
    )
    z = spec.points
    d2 = (((z[:, None] - z[None]) / spec.length_scales) ** 2).sum(-1)
    K = spec.signal_var * np.exp(-0.5 * d2) + 1e-3 * np.eye(n)
    return GPSpec(**{**spec.__dict__, "k_inv": np.linalg.inv(K)})


def test_fast_std_stays_within_its_bound_and_skips_rows():
    spec = _local_gp().with_fast_std(STD_TOL_BAR)
    assert spec.std_level > 0 and spec.std_tol == STD_TOL_BAR
    fmu = build_fmu(ml_program(spec, BASE, name="gp_local"), TMP / "gp_local.fmu")
    trace = medium_trace()
    X = np.column_stack(
        [trace.get(n) for n in ("current_cmd_mA", "dither_amp_mA", "dither_freq_Hz")]
    )
    std = FmuPhysics(fmu).simulate(trace).outputs["clutch_pressure_std_bar"]
    exact = gp_std(spec, X)
    assert np.abs(std - exact).max() <= STD_TOL_BAR
    # where the certified bound holds (the FMU takes the fast path), how much is skipped
    z = (X - spec.x_mean) / spec.x_scale
    prof = np.exp(-0.5 * (((z[:, None] - spec.points[None]) / spec.length_scales) ** 2).sum(-1))
    ks = spec.signal_var * prof
    bound = ks.max(1) * ((ks * (prof <= spec.std_level)) @ np.abs(spec.k_inv).sum(1))
    fast = bound <= (STD_TOL_BAR / spec.y_scale) ** 2
    kept = (prof > spec.std_level).sum(1)
    assert fast.mean() > 0.5 and np.median(kept[fast]) < 0.5 * spec.points.shape[0]


def test_estimator_std_matches_in_process_within_the_bound():
    est = GPBaseline(max_points=300, n_hyper=300).fit([medium_trace("triangle")])
    fmu = build_fmu(ml_program_from(est, name="gp_std"), TMP / "gp_std.fmu")
    trace = medium_trace()
    sim = FmuPhysics(fmu).simulate(trace)
    est.set_params(knot_tol=0.0)
    mean, std = est.predict(trace, return_std=True)
    assert np.abs(sim.pressure_bar - mean).max() < 1e-6
    assert np.abs(sim.outputs["clutch_pressure_std_bar"] - std).max() <= STD_TOL_BAR


def test_fast_std_settings_are_checked():
    spec = _local_gp(50)
    with pytest.raises(ModelError, match=r"std_level > 0 needs a std_tol > 0"):
        GPSpec(**{**spec.__dict__, "std_level": 1e-3})
    with pytest.raises(ModelError, match=r"std_tol must be > 0 bar"):
        spec.with_fast_std(0.0)
