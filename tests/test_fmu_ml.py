"""FMUs of learned models: GP mean/std, latch partition, causal dI/dt, hybrid on physics."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from fmpy.validation import validate_fmu
from fmu_support import TMP, fit_result, medium_trace

from clutchlab.data import causal_window
from clutchlab.errors import ModelError
from clutchlab.physics import SimulationSettings, simulate
from clutchlab.physics.fmu import FmuError, FmuPhysics, build_fmu, physics_program
from clutchlab.physics.fmu.adapters import ml_program_from
from clutchlab.physics.fmu.ml import DecisionSpec, DidtSpec, GPSpec, ml_program
from clutchlab.residual_ml import GPBaseline, SVCPartitionedGP


def _profile(spec: GPSpec, X: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
    z = (X - spec.x_mean) / spec.x_scale
    points = spec.points if points is None else points
    d2 = (((z[:, None, :] - points[None]) / spec.length_scales) ** 2).sum(-1)
    if spec.kernel == "rbf":
        return np.exp(-0.5 * d2)
    return (1.0 + d2 / (2.0 * spec.alpha)) ** (-spec.alpha)


def gp_mean(spec: GPSpec, X: np.ndarray) -> np.ndarray:
    """Reference: the GPSpec formula in NumPy."""
    return spec.y_mean + _profile(spec, X) @ spec.weights


def gp_std(spec: GPSpec, X: np.ndarray) -> np.ndarray:
    """Reference: ``y_scale · sqrt(s² − kᵀ K⁻¹ k)`` with ``K⁻¹ = L⁻ᵀ L⁻¹`` (dense)."""
    ks = spec.signal_var * _profile(spec, X, spec.std_points)
    l_inv = np.tril(spec.l_inv)
    var = spec.signal_var - np.einsum("ij,jk,ik->i", ks, l_inv.T @ l_inv, ks)
    return spec.y_scale * np.sqrt(np.maximum(var, 0.0))


def synthetic_gp(
    seed: int, d: int, kernel: str = "rq", n: int = 120, n_std: int | None = None
) -> GPSpec:
    """A GP on random standardized points with the inverse Cholesky factor of its kernel
    matrix (known answer); with ``n_std`` the std is conditioned on other random points."""
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(n, d))
    ell = rng.uniform(0.5, 2.0, d)
    spec = GPSpec(
        kernel,
        x_mean=np.array([500.0, 100.0, 50.0, 0.0, 8.0][:d]),
        x_scale=np.array([400.0, 60.0, 15.0, 300.0, 6.0][:d]),
        length_scales=ell,
        alpha=1.7,
        points=pts,
        weights=rng.normal(size=n),
        y_mean=5.0,
        signal_var=0.8,
        y_scale=3.0,
    )
    std_pts = None if n_std is None else rng.normal(size=(n_std, d))
    pts = spec.points if std_pts is None else std_pts
    z = pts * spec.x_scale + spec.x_mean  # the points in feature units
    K = spec.signal_var * _profile(spec, z, pts) + 1e-2 * np.eye(pts.shape[0])
    l_inv = np.linalg.inv(np.linalg.cholesky(K))
    return GPSpec(**{**spec.__dict__, "l_inv": l_inv, "std_points": std_pts})


def causal_slope(i_nom: np.ndarray, freq: np.ndarray, spec: DidtSpec) -> np.ndarray:
    """Reference of the FMU's dI/dt: LS slope over the last N samples (buffer starts full)."""
    m, dt = spec.max_samples, spec.sample_s
    padded = np.concatenate([np.full(m - 1, i_nom[0]), i_nom])
    buffers = np.lib.stride_tricks.sliding_window_view(padded, m)[:, ::-1]  # newest first
    n = np.array([causal_window(spec.periods / (f * dt)) for f in freq])
    n = np.minimum(n, m)
    j = np.arange(m)
    t = -j * dt
    t_bar = -(n - 1) * dt / 2
    w = np.where(j[None, :] < n[:, None], t[None, :] - t_bar[:, None], 0.0)
    w /= (dt**2 * n * (n * n - 1) / 12)[:, None]
    return np.einsum("ij,ij->i", w, buffers)


@lru_cache(maxsize=1)
def partitioned_fmu():
    didt = DidtSpec(periods=5.0, max_samples=255)
    gps = {0: synthetic_gp(1, 4), 1: synthetic_gp(2, 4, "rbf", n_std=50)}
    rng = np.random.default_rng(3)
    decision = DecisionSpec(
        "rbf",
        mean=np.array([550.0, 110.0, 50.0, 0.0]),
        scale=np.array([300.0, 50.0, 10.0, 100.0]),
        intercept=-0.2,
        support=rng.normal(size=(40, 4)),
        coef=rng.normal(size=40),
        gamma=0.7,
    )
    features = ("current_mA", "dither_amp_mA", "dither_freq_Hz", "didt_causal_mA_s")
    prog = ml_program(gps, features, decision=decision, didt=didt, name="clutch_svc_gp")
    return build_fmu(prog, TMP / "svc_gp.fmu"), gps, decision, didt


@lru_cache(maxsize=1)
def hybrid_fmu():
    fit = fit_result()
    physics = physics_program(fit.model(), fit.params(), "command")
    residual = synthetic_gp(4, 4, n=80)
    features = ("current_mA", "dither_amp_mA", "dither_freq_Hz", "physics_bar")
    prog = ml_program(residual, features, physics=physics, name="clutch_hybrid")
    return build_fmu(prog, TMP / "hybrid.fmu"), residual


def _features(trace, *extra) -> np.ndarray:
    base = [trace.get(n) for n in ("current_cmd_mA", "dither_amp_mA", "dither_freq_Hz")]
    return np.column_stack([*base, *extra])


def test_partitioned_gp_with_causal_didt_matches_its_reference():
    fmu, gps, decision, didt = partitioned_fmu()
    assert validate_fmu(str(fmu)) == []
    trace = medium_trace()
    sim = FmuPhysics(fmu).simulate(trace)
    X = _features(
        trace, causal_slope(trace.get("current_cmd_mA"), trace.get("dither_freq_Hz"), didt)
    )
    z = (X - decision.mean) / decision.scale
    d2 = ((z[:, None, :] - decision.support[None]) ** 2).sum(-1)
    latched = np.exp(-decision.gamma * d2) @ decision.coef + decision.intercept > 0
    assert 0.05 < latched.mean() < 0.95  # both GPs are exercised
    mean = np.where(latched, gp_mean(gps[1], X), gp_mean(gps[0], X))
    std = np.where(latched, gp_std(gps[1], X), gp_std(gps[0], X))
    np.testing.assert_array_equal(sim.outputs["latch_state"], latched.astype(float))
    assert np.abs(sim.pressure_bar - mean).max() < 1e-9
    assert np.abs(sim.outputs["clutch_pressure_std_bar"] - std).max() < 1e-7


def test_hybrid_fmu_is_the_physics_plus_the_residual_gp():
    fmu, residual = hybrid_fmu()
    assert validate_fmu(str(fmu)) == []
    trace = medium_trace()
    fit = fit_result()
    phys = simulate(fit.model(), fit.params(), trace, SimulationSettings(drive="command"))
    sim = FmuPhysics(fmu).simulate(trace)
    res = gp_mean(residual, _features(trace, phys.pressure_bar))
    assert np.abs(sim.outputs["physics_pressure_bar"] - phys.pressure_bar).max() <= 0.01
    assert np.abs(sim.pressure_bar - (phys.pressure_bar + res)).max() <= 0.01
    assert np.abs(sim.outputs["latch_state"] - phys.outputs["latch_state"]).max() <= 1e-3
    std = gp_std(residual, _features(trace, phys.pressure_bar))
    assert np.abs(sim.outputs["clutch_pressure_std_bar"] - std).max() < 1e-6


def test_gp_baseline_of_residual_ml_exports_and_matches_its_predictions():
    """A real ``gp_base`` estimator: the FMU evaluates the GP exactly per sample; the
    estimator's trace prediction interpolates between knots (≤ knot_tol)."""
    trace = medium_trace()
    est = GPBaseline(max_points=200, n_hyper=400).fit([medium_trace("triangle")])
    fmu = build_fmu(ml_program_from(est, name="gp_base"), TMP / "gp.fmu")
    assert validate_fmu(str(fmu)) == []
    sim = FmuPhysics(fmu).simulate(trace)
    mean, std = est.gp_.predict(_features(trace), return_std=True)
    std = np.sqrt(std**2 + est.gp_.noise_var_)  # the estimator's std: latent + noise
    assert np.abs(sim.pressure_bar - mean).max() < 1e-9
    assert np.abs(sim.outputs["clutch_pressure_std_bar"] - std).max() < 1e-8
    assert np.abs(sim.pressure_bar - est.predict(trace)).max() <= 0.01


def test_svc_partitioned_gp_on_centred_didt_is_refused_or_exported_approximately():
    """``paper_svc_gp`` trained on the centred dI/dt and direction (no ``--causal``): refused
    with the way out named; with ``approximate_didt`` the FMU substitutes the causal ones and
    is identical except around the ramp reversal, where they lag the centred ones."""
    small = {"max_points": 200, "n_hyper": 400, "svc_max_points": 500}
    est = SVCPartitionedGP(**small).fit([medium_trace("triangle")])
    with pytest.raises(FmuError) as exc:
        ml_program_from(est)
    text = str(exc.value)
    assert "didt_mA_s, direction: centred filters" in text
    assert "clutchlab train ... --causal" in text and "--approximate-didt" in text
    prog = ml_program_from(est, approximate_didt=True, with_std=False)
    fmu = build_fmu(prog, TMP / "svc.fmu")
    trace = medium_trace()
    sim = FmuPhysics(fmu).simulate(trace)
    err = np.abs(sim.pressure_bar - est.predict(trace))
    assert np.median(err) < 1e-3 < err.max(), (np.median(err), err.max())


def test_ml_program_names_what_is_missing():
    gp = synthetic_gp(5, 4)
    with pytest.raises(ModelError) as exc:
        ml_program({0: gp, 1: gp}, ("current_mA", "dither_amp_mA", "foo", "didt_causal_mA_s"))
    text = str(exc.value)
    assert "unknown feature(s) ['foo']" in text
    assert "two GPs need a decision function" in text
    assert "feature(s) didt_causal_mA_s need a DidtSpec" in text


def test_an_fmu_that_does_not_validate_replaces_nothing(tmp_path, monkeypatch):
    """The archive is validated under its temporary name: on a problem the earlier file at
    the path is kept as it was and no temporary file is left behind."""
    import fmpy.validation

    out = tmp_path / "gp.fmu"
    out.write_bytes(b"an earlier export")
    monkeypatch.setattr(fmpy.validation, "validate_fmu", lambda f: ["an injected problem"])
    features = ("current_mA", "dither_amp_mA", "dither_freq_Hz")
    program = ml_program(synthetic_gp(5, 3, n=10), features, name="gp_invalid")
    with pytest.raises(FmuError, match="does not validate"):
        build_fmu(program, out)
    assert out.read_bytes() == b"an earlier export"
    assert [p.name for p in tmp_path.iterdir()] == ["gp.fmu"]
