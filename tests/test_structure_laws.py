"""Flexible component laws: identity = today's model, monotone / bounded where claimed, units."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from synthetic import make_trace

from clutchlab.errors import ModelError
from clutchlab.physics import CircuitModel, latch_thresholds
from clutchlab.physics.assembly import MODEL_INPUTS, Assembly
from clutchlab.physics.effects import EFFECTS, FLEXIBLE_LAWS, make_effect
from clutchlab.physics.effects.flexible import FORCE_KNOTS_MA, PLAY_WIDTHS_MA
from clutchlab.physics.simulate import simulate
from clutchlab.physics.units import SI_FACTOR


@pytest.fixture(scope="module")
def up_down_trace():
    """Up to 900 mA and back (command drive, 50 Hz dither of 60 mA): latch on and off."""
    return make_trace([0.0, 0.3, 2.3, 4.3], [0.0, 0.0, 900.0, 0.0], dither_mA=60.0)


@pytest.fixture(scope="module")
def plain_pressure(up_down_trace):
    model = CircuitModel()
    return simulate(model, model.default_params(), up_down_trace).pressure_bar


@pytest.mark.parametrize("law", FLEXIBLE_LAWS)
def test_law_at_its_defaults_is_todays_model(law, up_down_trace, plain_pressure):
    model = CircuitModel().with_effects(law)
    got = simulate(model, model.default_params(), up_down_trace).pressure_bar
    assert np.ptp(plain_pressure) > 5.0  # the trace latches: the comparison means something
    np.testing.assert_allclose(got, plain_pressure, rtol=0, atol=1e-8)


@pytest.mark.parametrize("law", FLEXIBLE_LAWS)
def test_law_parameters_have_units_bounds_and_a_fit_set(law):
    cls = EFFECTS[law]
    names = {p.name for p in cls.PARAMETERS}
    for p in cls.PARAMETERS:
        assert p.unit in SI_FACTOR and p.lower <= p.default <= p.upper, p
        assert p.component == cls.PARAMETERS[0].component
    for n in cls.STRENGTH:
        spec = next(p for p in cls.PARAMETERS if p.name == n)
        assert spec.default == 0.0 and spec.lower == 0.0 and spec.transform == "linear", n
    # a law fits parameters of its own, or is a switch a fit holds on (its weight at 1)
    assert set(cls.fit_parameters()) <= names
    assert cls.fit_parameters() or cls.STRENGTH
    model = CircuitModel().with_effects(law)
    known = {p.name for p in model.parameters}
    assert names <= known
    assert not set(cls.REPLACES) & known  # retired parameters leave the model


def _force_curve(model, params, current_mA):
    """Magnetic force (N) vs measured coil current (mA) at zero play states."""
    fn = model.functions("measured")
    k_cur = [s.name for s in MODEL_INPUTS].index("current_meas_mA")
    k_out = [o.name for o in fn.outputs].index("magnetic_force_N")
    x0 = np.array([s.initial for s in fn.states])
    out = []
    for i in current_mA:
        u = np.zeros(len(MODEL_INPUTS))
        u[k_cur] = i
        out.append(float(fn.out(x0, u, params.vector())[k_out]))
    return np.array(out)


def test_force_correction_is_monotone_for_any_admissible_weights():
    model = CircuitModel().with_effects("vfs_force_monotone")
    cur = np.linspace(0.0, 1100.0, 221)
    rng = np.random.default_rng(3)
    specs = {p.name: p for p in model.parameters}
    base = _force_curve(model, model.default_params(), cur)
    for _ in range(5):
        values = {
            n: rng.uniform(specs[n].lower, specs[n].upper)
            for n in ("mspl_d1", "mspl_d2", "mspl_d3", "mspl_d4", "mspl_w")
        }
        # the base curve at its weakest admissible gain and knee, too
        values.update(vfs_K_m=specs["vfs_K_m"].lower, vfs_i_knee=specs["vfs_i_knee"].upper)
        f = _force_curve(model, model.params(**values), cur)
        assert np.all(np.diff(f) >= -1e-12)
    # a step at a knot is a logistic of its height: half of it at the knot, d·σ(−c/w) at 0
    f = _force_curve(model, model.params(mspl_d2=4.0), cur)
    gain = f - base
    c, w = FORCE_KNOTS_MA[1], specs["mspl_w"].default
    assert gain[0] == pytest.approx(4.0 / (1.0 + np.exp(c / w)), rel=1e-9)
    assert np.interp(c, cur, gain) == pytest.approx(2.0, rel=1e-9)
    assert gain[-1] == pytest.approx(4.0, abs=0.01)


def test_play_hysteresis_loop_opposes_the_direction_and_is_bounded():
    model = CircuitModel().with_effects("vfs_play_hysteresis")
    trace = make_trace([0.0, 0.2, 2.2, 4.2], [0.0, 0.0, 800.0, 0.0], dither_mA=0.0)
    params = model.params(play_H1=0.5, play_H2=0.3, play_H3=0.2)
    res = simulate(model, params, trace, None)
    f = res.outputs["magnetic_force_N"]
    f0 = simulate(model, model.default_params(), trace).outputs["magnetic_force_N"]
    t = res.time_s
    rising, falling = (t > 1.0) & (t < 2.0), (t > 2.4) & (t < 3.4)
    # rising: the force lags (less), falling: more; saturated loop half-width = ΣH = 1 N
    assert np.all((f - f0)[rising] < 0) and np.all((f - f0)[falling] > 0)
    # after a travel of 3 widths of the widest operator (450 mA) the loop is saturated
    assert (f - f0)[rising][-1] == pytest.approx(-1.0, abs=0.03)
    assert (f - f0)[falling][-1] == pytest.approx(1.0, abs=0.03)
    hs = [
        res.states[:, res.state_names.index(f"h_play{j + 1}")] for j in range(len(PLAY_WIDTHS_MA))
    ]
    assert max(np.max(np.abs(h)) for h in hs) <= 1.0 + 1e-6


def test_free_latch_thresholds_reach_a_gap_the_area_ratio_forbids():
    model = CircuitModel().with_effects("latch_free_thresholds")
    defaults = model.default_params()
    d1, d2 = defaults["latch_d1"], defaults["latch_d2"]
    p_on, p_off = 9.0, 4.0
    assert p_off < (d1 / d2) ** 2 * p_on  # below what F0 / k could give
    assert latch_thresholds(model.params(lthr_p_on=p_on, lthr_p_off=p_off).values) == (p_on, p_off)
    plain = CircuitModel()
    assert latch_thresholds(defaults.values) == pytest.approx(
        latch_thresholds(plain.default_params().values), abs=1e-12
    )


@pytest.mark.parametrize("law", FLEXIBLE_LAWS)
def test_law_is_smooth(law):
    """No branch or kink reaches IPOPT: the expressions hold no if_else, fabs, fmin/fmax, sign."""
    fn = CircuitModel().with_effects(law).functions("command")
    text = str(fn.dx_expr) + str(fn.y_expr)
    for bad in ("if_else", "fabs", "fmax", "fmin", "sign(", "floor", "ceil"):
        assert bad not in text, (law, bad)
    # and the Jacobian of the right-hand side exists symbolically (twice differentiable)
    assert ca.jacobian(fn.dx_expr, fn.p_sym).shape == (fn.nx, fn.p_sym.numel())


def test_retire_and_redefine_fail_loudly_on_unknown_names():
    asm = Assembly("measured")
    with pytest.raises(ModelError, match="nothing to retire"):
        asm.retire_parameter("latch_F0")
    with pytest.raises(ModelError, match="nothing to redefine"):
        asm.redefine("latch_F_net", lambda a: 0.0)


def test_laws_are_found_by_name_but_stay_out_of_the_effect_library():
    """Discovery draws candidates from the library; a flexible law is no physical effect."""
    for law, cls in FLEXIBLE_LAWS.items():
        assert law not in EFFECTS and law not in list(EFFECTS)
        assert EFFECTS[law] is cls and make_effect(law).name == law
    with pytest.raises(ModelError, match="flexible laws: vfs_force_monotone"):
        make_effect("vfs_force_spline9")
