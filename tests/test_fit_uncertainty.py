"""Standard errors from a fit's sensitivities, and what is said when those diverged.

Two zoo fits of session 45 (saturating_lugre seeds 1 and 2, stopped with
``Error_In_Step_Computation``) reported relative standard errors of 1e-90 … 1e-31 and
flagged every parameter "not identifiable": the covariance had been computed from
sensitivities of ~1e35 bar per scaled unit (a locally unstable parameter set).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from fit_support import synthetic_fit

from clutchlab.errors import FitResultError
from clutchlab.physics import CircuitModel
from clutchlab.physics.fit import (
    FitResult,
    diverged_sensitivities,
    parameter_uncertainty,
    residual_correlation_time,
)
from clutchlab.physics.fit.result import SENSITIVITY_LIMIT
from clutchlab.validation.report import _fit_status

NAMES = ["vfs_K_m", "latch_F0", "vfs_d_orf"]


def _sound_problem(seed: int = 0):
    """Sensitivities of a sound fit's size (≲ 1 bar per scaled unit), residuals of 0.02 bar."""
    rng = np.random.default_rng(seed)
    jz = rng.normal(0.0, 0.3, (2000, len(NAMES)))
    r = rng.normal(0.0, 0.02, 2000)
    specs = {p.name: p for p in CircuitModel().parameters}
    values = CircuitModel().default_params()
    return jz, r, specs, values


def test_sound_sensitivities_give_finite_standard_errors():
    jz, r, specs, values = _sound_problem()
    assert diverged_sensitivities(jz) == ""
    unc = parameter_uncertainty(jz, r, NAMES, specs, values)
    assert unc.note == ""
    for n in NAMES:
        assert math.isfinite(unc.std_errors[n]) and unc.std_errors[n] > 0
    assert np.allclose(np.diag(unc.correlation), 1.0)
    assert len(unc.singular_values) == len(NAMES) and unc.unidentifiable == []


def test_standard_errors_scale_with_the_residual_and_not_with_a_sound_jacobian_scale():
    jz, r, specs, values = _sound_problem(1)
    base = parameter_uncertainty(jz, r, NAMES, specs, values).std_errors
    noisier = parameter_uncertainty(jz, 3.0 * r, NAMES, specs, values).std_errors
    stiffer = parameter_uncertainty(10.0 * jz, r, NAMES, specs, values).std_errors
    for n in NAMES:
        assert noisier[n] == pytest.approx(3.0 * base[n])
        assert stiffer[n] == pytest.approx(base[n] / 10.0)


@pytest.mark.parametrize(
    ("blow", "says"),
    [
        (1e35, "up to 1e+35 bar per scaled parameter unit"),
        (1e20, "up to 1e+20 bar per scaled parameter unit"),
        (math.inf, "not finite"),
        (math.nan, "not finite"),
    ],
)
def test_diverged_sensitivities_give_no_standard_errors_and_say_why(blow, says):
    jz, r, specs, values = _sound_problem(2)
    jz[700:705, 1] = blow  # a few samples where the sensitivity equations ran away
    unc = parameter_uncertainty(jz, r, NAMES, specs, values)
    assert says in unc.note and "--substeps" in unc.note
    assert all(math.isnan(unc.std_errors[n]) for n in NAMES)
    # nothing is claimed either way: not "identifiable", not "unidentifiable"
    assert unc.unidentifiable == [] and unc.correlation == [] and unc.singular_values == []


def test_the_limit_sits_between_sound_and_diverged_sensitivities():
    jz = np.full((10, 2), SENSITIVITY_LIMIT)
    assert diverged_sensitivities(jz) == ""
    jz[3, 1] = -2.0 * SENSITIVITY_LIMIT  # the sign does not matter
    assert f"up to {2.0 * SENSITIVITY_LIMIT:.3g}" in diverged_sensitivities(jz)
    # a latch snap on a short fast ramp gives sound sensitivities of ~6e6 (measured)
    assert diverged_sensitivities(np.array([[6.2e6, 1.0]])) == ""


def test_the_note_is_saved_read_back_and_shown(tmp_path):
    res = synthetic_fit({"vfs_K_m": 14.2}, status="Error_In_Step_Computation (pre-fit)")
    assert '"uncertainty_note"' not in res.to_json()  # files without one stay as they were
    res.std_errors = {"vfs_K_m": math.nan}
    res.uncertainty_note = diverged_sensitivities(np.array([[1e40]]))
    back = FitResult.from_json(res.to_json(tmp_path / "fit.json"))
    assert back.uncertainty_note == res.uncertainty_note
    assert math.isnan(back.std_errors["vfs_K_m"])
    table = back.table()
    assert "nan" in table and res.uncertainty_note in table
    assert "not identifiable" not in table
    # the report's status line of the fitted physics says it too
    status = _fit_status(
        {
            "status": back.status,
            "converged": False,
            "iterations": 8,
            "wall_s": 42.6,
            "effects": [],
            "uncertainty_note": back.uncertainty_note,
        }
    )
    assert "Standard errors, correlations and identifiability are not reported" in status


def test_a_note_of_the_wrong_type_is_a_damaged_file(tmp_path):
    doc = synthetic_fit({"vfs_K_m": 14.2}).to_json()
    bad = doc.replace('"settings": {}', '"settings": {},\n  "uncertainty_note": 3')
    with pytest.raises(FitResultError, match="uncertainty_note: must be a string"):
        FitResult.from_json(bad)


def test_reports_call_nothing_identifiable_or_not_when_the_sensitivities_diverged():
    from clutchlab.validation.discover.report import _parameter_rows
    from clutchlab.validation.discover.result import _parameters

    res = synthetic_fit({"vfs_K_m": 14.2, "latch_F0": 28.0})
    res.unidentifiable = ["latch_F0"]
    rows = _parameter_rows(_parameters(res))
    assert [r[0] for r in rows] == ["vfs_K_m", "latch_F0 (not identifiable)"]
    res.std_errors = {"vfs_K_m": math.nan, "latch_F0": math.nan}
    res.unidentifiable = []
    res.uncertainty_note = diverged_sensitivities(np.array([[math.inf]]))
    params = _parameters(res)
    assert [p["identifiable"] for p in params] == [None, None]
    assert [r[0] for r in _parameter_rows(params)] == ["vfs_K_m", "latch_F0"]


def _ar1(rng, n, phi):
    """A stationary AR(1) series of unit innovations."""
    e = rng.normal(size=n)
    x = np.empty(n)
    x[0] = e[0] / math.sqrt(1.0 - phi * phi)
    for k in range(1, n):
        x[k] = phi * x[k - 1] + e[k]
    return x


def test_the_correlation_time_of_known_series():
    """τ = 1 for independent residuals, (1 + φ) / (1 − φ) for an AR(1), about w for a
    moving mean over w samples (the fit's period-mean residuals)."""
    rng = np.random.default_rng(5)
    assert residual_correlation_time(rng.normal(size=20000)) == pytest.approx(1.0, abs=0.15)
    assert residual_correlation_time(_ar1(rng, 40000, 0.9)) == pytest.approx(19.0, rel=0.25)
    w = 20
    moving = np.convolve(rng.normal(size=40000), np.ones(w) / w, mode="valid")
    assert residual_correlation_time(moving) == pytest.approx(w, rel=0.25)
    assert residual_correlation_time(np.zeros(10)) == 1.0  # nothing to correlate


def test_lags_do_not_cross_from_one_experiment_into_the_next():
    """Two experiments with opposite offsets: each is one correlated error; read as one
    series, the products across the boundary would cancel part of it."""
    x = np.r_[np.full(500, 0.1), np.full(500, -0.1)]
    apart = residual_correlation_time(x, [(0, 500), (500, 500)])
    together = residual_correlation_time(x)
    assert apart == pytest.approx(500.0, rel=0.01) and together < 0.75 * apart


def test_standard_errors_cover_the_spread_of_estimates_under_correlated_residuals():
    """Linear least squares on smooth sensitivities with AR(1) residuals (φ = 0.95, the
    fit's case: misfit that drifts): the reported standard errors match the spread of the
    estimates over noise draws, where independent-residual ones are ~6 × too small."""
    rng = np.random.default_rng(11)
    n = 4000
    t = np.linspace(0.0, 1.0, n)
    jz = np.column_stack([np.sin(2 * np.pi * t), t, np.cos(3 * np.pi * t) ** 2])
    specs = {p.name: p for p in CircuitModel().parameters}
    values = CircuitModel().default_params()
    estimates, reported = [], []
    for _ in range(200):
        y = 0.02 * _ar1(rng, n, 0.95)
        beta, *_ = np.linalg.lstsq(jz, y, rcond=None)
        estimates.append(beta)
        reported.append(parameter_uncertainty(jz, y - jz @ beta, NAMES, specs, values))
    spread = np.std(estimates, axis=0)
    for k, name in enumerate(NAMES):
        spec, v = specs[name], values[name]
        scale = abs(v if spec.transform == "log" else spec.scale)
        se = np.median([u.std_errors[name] for u in reported]) / scale
        assert se == pytest.approx(spread[k], rel=0.3), name
    tau = np.median([u.correlation_time for u in reported])
    assert tau == pytest.approx((1 + 0.95) / (1 - 0.95), rel=0.35)


def test_the_correlation_time_is_saved_read_back_and_shown(tmp_path):
    res = synthetic_fit({"vfs_K_m": 14.2})
    assert "residual_correlation_time" not in res.to_json()  # not reported: not written
    assert "correlation over" not in res.table()
    res.residual_correlation_time = 48.9
    back = FitResult.from_json(res.to_json(tmp_path / "fit.json"))
    assert back.residual_correlation_time == 48.9
    assert "allow for the residuals' correlation over 48.9 consecutive residuals" in back.table()
    fit = {"status": back.status, "converged": True, "iterations": 8, "wall_s": 42.6}
    said = "Standard errors allow for the residuals' correlation over 48.9 consecutive residuals."
    assert said in _fit_status({**fit, "residual_correlation_time": 48.9})
    assert "correlation over" not in _fit_status({**fit, "residual_correlation_time": None})
    gone = {**fit, "residual_correlation_time": 48.9, "uncertainty_note": "not reported"}
    assert "correlation over" not in _fit_status(gone)  # no standard errors: nothing to allow for


def test_lagged_sums_are_the_products_at_every_lag_without_wrap_around():
    from clutchlab.data import lagged_sums

    x = np.random.default_rng(3).normal(size=37)
    direct = np.correlate(x, x, mode="full")[len(x) - 1 :]
    np.testing.assert_allclose(lagged_sums(x), direct, atol=1e-10)
