"""Parameters carry units, bounds, defaults; parameter sets validate; smooth functions are sane."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from clutchlab.errors import ModelError
from clutchlab.physics import EFFECTS, CircuitModel, Parameter, ParameterSet
from clutchlab.physics.smooth import orifice_flow, smooth_abs, smooth_max0
from clutchlab.physics.units import SI_FACTOR

ALL_EFFECTS = CircuitModel().with_effects(*EFFECTS)


def test_every_parameter_has_unit_bounds_default_description():
    params = ALL_EFFECTS.parameters
    assert len(params) >= 60
    names = [p.name for p in params]
    assert len(names) == len(set(names)), "parameter names must be unique"
    for p in params:
        assert p.unit in SI_FACTOR, p.name
        assert math.isfinite(p.lower) and math.isfinite(p.upper), p.name
        assert p.lower < p.upper, p.name
        assert p.lower <= p.default <= p.upper, p.name
        assert p.description, p.name
        assert p.scale > 0, p.name
        assert p.transform in ("log", "linear"), p.name
        if p.transform == "log":
            assert p.lower > 0, p.name
        assert p.component, p.name


def test_effect_strength_parameters_can_be_zero():
    for name, cls in EFFECTS.items():
        specs = {p.name: p for p in cls.PARAMETERS}
        assert cls.STRENGTH, name
        assert cls.signature and cls.description, name
        for s in cls.STRENGTH:
            assert specs[s].lower <= 0.0 <= specs[s].upper, (name, s)
            assert specs[s].default != 0.0, (name, s)


def test_parameter_rejects_default_outside_bounds_and_unknown_unit():
    with pytest.raises(ModelError, match="outside bounds"):
        Parameter("x", "mm", 5.0, 0.1, 1.0, "x")
    with pytest.raises(ModelError, match="unit"):
        Parameter("x", "furlong", 0.5, 0.1, 1.0, "x")
    with pytest.raises(ModelError, match="log transform"):
        Parameter("x", "N", 0.5, -1.0, 1.0, "x", transform="log")


def test_parameter_set_validates_and_round_trips(tmp_path):
    model = CircuitModel()
    ps = model.default_params()
    assert ps["reg_k"] == 15.0
    new = ps.replace(reg_k=20.0)
    assert new["reg_k"] == 20.0 and ps["reg_k"] == 15.0
    assert new.changed() == {"reg_k": 20.0}
    with pytest.raises(ModelError, match="outside bounds"):
        ps.replace(reg_k=1e6)
    with pytest.raises(ModelError, match="unknown parameter 'nope'"):
        ps.replace(nope=1.0)
    path = tmp_path / "p.json"
    new.to_json(path)
    back = ParameterSet.from_json(model.parameters, path)
    assert np.array_equal(back.vector(), new.vector())
    vec_back = ParameterSet.from_vector(model.parameters, new.vector())
    assert vec_back == new


@given(st.floats(-1e3, 1e3), st.floats(1e-6, 10.0))
def test_smooth_max0_and_abs_bound_the_exact_functions(x, eps):
    m = float(smooth_max0(ca.DM(x), eps))
    a = float(smooth_abs(ca.DM(x), eps))
    assert m >= max(x, 0.0) - 1e-9
    assert m - max(x, 0.0) <= eps / 2 + 1e-9
    assert abs(x) - 1e-9 <= a <= abs(x) + eps + 1e-9


@given(st.floats(-5e6, 5e6, allow_subnormal=False), st.floats(1e-8, 1e-4))
def test_orifice_flow_is_odd_and_follows_the_pressure_drop(dp, area):
    q = float(orifice_flow(0.65, area, ca.DM(dp), 850.0, 1e4))
    q_neg = float(orifice_flow(0.65, area, ca.DM(-dp), 850.0, 1e4))
    assert q == pytest.approx(-q_neg, rel=1e-12, abs=1e-18)
    if abs(dp) > 1e-200:  # below that the flow underflows to 0, which is fine
        assert np.sign(q) == np.sign(dp)
    if abs(dp) > 1e6:  # turbulent limit: Cd·A·sqrt(2|Δp|/ρ) within 0.01 %
        exact = 0.65 * area * math.sqrt(2 * abs(dp) / 850.0)
        assert abs(q) == pytest.approx(exact, rel=1e-4)
