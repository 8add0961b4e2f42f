"""The base model against its closed-form steady state (no dither, currents held)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from synthetic import make_trace

from clutchlab.physics import CircuitModel, SimulationSettings, latch_thresholds, simulate

MODEL = CircuitModel()
PARAMS = MODEL.default_params()
HOLD_S = 1.5
LEVELS_MA = [250, 350, 450, 550, 650, 750, 850]


def _area(d_mm):
    return math.pi / 4 * (d_mm * 1e-3) ** 2


@pytest.fixture(scope="module")
def staircase():
    """Held current steps through the regulated range, no dither (equilibria, not orbits)."""
    knots_t, knots_i = [0.0], [LEVELS_MA[0]]
    for level in LEVELS_MA:
        knots_t += [knots_t[-1] + 0.05, knots_t[-1] + 0.05 + HOLD_S]
        knots_i += [level, level]
    trace = make_trace(knots_t, knots_i, dither_mA=0.0, dither_Hz=0.0)
    res = simulate(MODEL, PARAMS, trace, SimulationSettings())
    ends = [int(np.searchsorted(trace.time_s, t)) - 1 for t in knots_t[2::2]]
    return res, ends


def test_regulated_pressure_follows_pilot_through_the_area_ratio(staircase):
    """``A_fb p_c = A_pil p_a + F0 − k x_r`` (friction vanishes at rest, no flow force).

    Tolerance 1e-3 bar: the residual velocity / flow at the end of a 1.5 s hold.
    Without the spring term (``x_r`` = 0) the closed form holds within 0.05 bar: the
    metering opening needed for the leakage flow is a few µm, ``k·x/A_fb`` < 0.05 bar.
    """
    res, ends = staircase
    a_pil, a_fb = _area(PARAMS["reg_d_pil"]), _area(PARAMS["reg_d_fb"])
    p_a = res.outputs["pilot_pressure_bar"][ends] * 1e5
    x_r = res.outputs["regulator_position_mm"][ends] * 1e-3
    p_c = res.outputs["clutch_pressure_true_bar"][ends]
    exact = (a_pil * p_a + PARAMS["reg_F0"] - PARAMS["reg_k"] * 1e3 * x_r) / a_fb / 1e5
    no_spring = (a_pil * p_a + PARAMS["reg_F0"]) / a_fb / 1e5
    assert np.max(np.abs(p_c - exact)) < 1e-3
    assert np.max(np.abs(p_c - no_spring)) < 0.05
    gain = np.polyfit(p_a / 1e5, p_c, 1)[0]
    assert gain == pytest.approx(a_pil / a_fb, rel=0.01)
    assert np.all(res.outputs["latch_state"][ends] < 1e-3)


def test_vfs_pressure_follows_magnetic_force_through_feedback_area(staircase):
    """``A_fb,v p_vo = F_mag(i) − F_pre − k_v x_v`` at rest (1e-3 bar)."""
    res, ends = staircase
    i = res.outputs["coil_current_mA"][ends] * 1e-3
    f_mag = PARAMS["vfs_K_m"] * i * np.tanh(i / (PARAMS["vfs_i_knee"] * 1e-3))
    x_v = res.states[ends, res.state_names.index("x_v")] * 1e-3
    p_vo = (f_mag - PARAMS["vfs_F_pre"] - PARAMS["vfs_k"] * 1e3 * x_v) / _area(PARAMS["vfs_d_fb"])
    assert np.max(np.abs(res.outputs["vfs_pressure_bar"][ends] - p_vo / 1e5)) < 1e-3
    # And the pilot (accumulator) node equals the VFS output once the orifice carries no flow.
    assert (
        np.max(
            np.abs(res.outputs["pilot_pressure_bar"][ends] - res.outputs["vfs_pressure_bar"][ends])
        )
        < 0.02
    )


def test_latch_snaps_on_and_off_at_the_differential_area_thresholds():
    """Slow triangle, no dither: pilot pressure at the onset of the snap, both ways.

    Ideal thresholds ``p_on = F0/A1``, ``p_off = (F0 + k s)/A2``. The smooth latch
    opens quasi-statically as ``λ = σ(F_net/F_w)``, so it reaches ``λ_th`` where
    ``F_net = F_w·logit(λ_th)``: onset at ``p_on + F_w·logit(λ_th)/A1`` rising and
    ``p_off + F_w·logit(1 − λ_th)/A2`` falling. Tolerance 0.05 bar: the differential
    area's own feedback (``dF/dλ·λ_th`` ≈ 0.05 N) and the latch lag on the ramp.
    """
    trace = make_trace([0, 0.5, 20.5, 40.5], [600, 600, 1100, 600], dither_mA=0.0, dither_Hz=0.0)
    res = simulate(MODEL, PARAMS, trace, SimulationSettings())
    lam = res.outputs["latch_state"]
    p_a = res.outputs["pilot_pressure_bar"]
    lam_th = 0.01
    logit = math.log(lam_th / (1 - lam_th))
    k_on = int(np.argmax(lam > lam_th))
    k_off = len(lam) - 1 - int(np.argmax(lam[::-1] > 1 - lam_th))
    p_on, p_off = latch_thresholds(PARAMS)
    f_w = PARAMS["latch_F_w"]
    assert p_on > p_off + 1.0
    assert p_a[k_on] == pytest.approx(
        p_on + f_w * logit / _area(PARAMS["latch_d1"]) / 1e5, abs=0.05
    )
    assert p_a[k_off] == pytest.approx(
        p_off - f_w * logit / _area(PARAMS["latch_d2"]) / 1e5, abs=0.05
    )
    # Latched: the feedback is exhausted and the clutch goes to line pressure.
    k_peak = int(np.searchsorted(trace.time_s, 20.5))
    assert lam[k_peak] > 0.99
    assert res.outputs["clutch_pressure_true_bar"][k_peak] == pytest.approx(17.7, abs=0.1)
    # Before the onset the regulator still regulates (well below line).
    assert res.outputs["clutch_pressure_true_bar"][k_on - 200] < 16.5
