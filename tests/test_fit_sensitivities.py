"""The integrator's parameter and initial-state sensitivities against finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic import make_trace

from clutchlab.physics import CircuitModel, SimulationSettings, simulate_inputs
from clutchlab.physics.fit import simulate_sensitivities
from clutchlab.physics.inputs import input_matrix

MODEL = CircuitModel().with_effects("sensor_lag", "flow_force")
PARAMS = MODEL.default_params()
FREE = ["vfs_K_m", "reg_F_c", "latch_F0", "vfs_d_orf", "slag_tau", "jet_kappa"]
SUBSTEPS = 2


@pytest.fixture(scope="module")
def run():
    """Sensitivities along a fast dithered ramp through the latch snap and release."""
    trace = make_trace([0, 0.3, 2.3, 2.6, 4.6, 5.0], [0, 0, 1100, 1100, 0, 0])
    settings = SimulationSettings(substeps=SUBSTEPS)
    u = input_matrix(trace, "command", settings)
    t = trace.time_s
    fns = MODEL.functions("command")
    x0 = simulate_inputs(MODEL, PARAMS, t[:2], u[:2], "command", settings)[0][0]
    names = [p.name for p in fns.parameters]
    nd = len(FREE) + fns.nx
    e = np.zeros((len(names), nd))
    for j, name in enumerate(FREE):
        e[names.index(name), j] = 1.0
    s0 = np.zeros((fns.nx, nd))
    s0[:, len(FREE) :] = np.eye(fns.nx)
    sens = simulate_sensitivities(MODEL, "command", SUBSTEPS, t, u, PARAMS.vector(), x0, s0, e)
    return t, u, x0, settings, sens, fns


@pytest.mark.parametrize("name", FREE)
def test_parameter_sensitivities_match_central_differences(run, name):
    """Central differences with a relative step of 1e-8 (the latch snap is steep: larger
    steps leave the linear range there). Agreement within 1e-3 of the largest sensitivity,
    and the primal output of the sensitivity run equals the plain simulation."""
    t, u, x0, settings, sens, _ = run
    h = 1e-8 * abs(PARAMS[name])
    y = {}
    for sign in (1, -1):
        p = PARAMS.replace(**{name: PARAMS[name] + sign * h})
        y[sign] = simulate_inputs(MODEL, p, t, u, "command", settings, x0=x0)[1][:, 0]
    fd = (y[1] - y[-1]) / (2 * h)
    ad = sens.dy[:, FREE.index(name)]
    scale = np.max(np.abs(ad))
    assert scale > 0
    assert np.max(np.abs(fd - ad)) <= 1e-3 * scale + 1e-6
    y0 = simulate_inputs(MODEL, PARAMS, t, u, "command", settings, x0=x0)[1][:, 0]
    assert np.array_equal(y0, sens.y)


def test_initial_state_sensitivities_match_central_differences(run):
    t, u, x0, settings, sens, fns = run
    for state in ("p_c", "p_a", "latch"):
        k = fns.state_index(state)
        h = 1e-6
        y = {}
        for sign in (1, -1):
            x = x0.copy()
            x[k] += sign * h
            y[sign] = simulate_inputs(MODEL, PARAMS, t, u, "command", settings, x0=x)[1][:, 0]
        fd = (y[1] - y[-1]) / (2 * h)
        ad = sens.dy[:, len(FREE) + k]
        assert np.max(np.abs(fd - ad)) <= 1e-4 * max(np.max(np.abs(ad)), 1.0)
