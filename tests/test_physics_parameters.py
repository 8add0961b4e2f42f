"""Parameters carry units, bounds, defaults; parameter sets validate; smooth functions are sane."""

from __future__ import annotations

import json
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


def test_parameter_values_are_read_only_and_still_save_and_pickle(tmp_path):
    """``values`` of the immutable, bounds-checked set cannot be changed in place (a
    written ``q.values["reg_F_c"] = -50.0`` reached the simulation unchecked); saving,
    pickling, copying and ``replace`` still work."""
    import copy
    import pickle

    q = CircuitModel().default_params()
    with pytest.raises(TypeError):
        q.values["reg_F_c"] = -50.0
    with pytest.raises(TypeError):
        del q.values["reg_F_c"]
    assert q["reg_F_c"] == q.spec("reg_F_c").default
    assert pickle.loads(pickle.dumps(q)) == q
    assert copy.deepcopy(q) == q
    new = q.replace(reg_F_c=0.8)
    assert new["reg_F_c"] == 0.8 and dict(new.values) != dict(q.values)
    back = ParameterSet.from_json(q.parameters, new.to_json(tmp_path / "p.json"))
    assert back == new


def test_parameter_json_problems_are_all_listed():
    """A misspelt top-level key gave the defaults silently; malformed entries a KeyError
    or AttributeError; a JSON list was taken for a file name."""
    params = CircuitModel().parameters
    unit = {p.name: p.unit for p in params}
    with pytest.raises(ModelError) as err:
        ParameterSet.from_json(params, '{"parameter": {"reg_k": {"value": 20, "unit": "N/mm"}}}')
    text = str(err.value)
    assert "unknown top-level key 'parameter' (did you mean 'parameters'?)" in text
    assert "'parameters' is missing" in text
    doc = {
        "parameters": {
            "reg_k": {"unit": unit["reg_k"]},
            "reg_F0": [1.0],
            "reg_F_c": {"value": "1.0", "unit": unit["reg_F_c"]},
            "vfs_K_m": {"value": 1.0, "unit": "furlong"},
            "latch_k": {"value": 1e9, "unit": unit["latch_k"]},
            "reg_kk": {"value": 1.0, "unit": unit["reg_k"]},
        }
    }
    with pytest.raises(ModelError) as err:
        ParameterSet.from_json(params, json.dumps(doc))
    text = str(err.value)
    for part in (
        "reg_k: 'value' is missing",
        'reg_F0: must be {"value": ..., "unit": ...}, not a list',
        "reg_F_c: value '1.0' is not a number",
        "vfs_K_m: unit 'furlong'",
        "latch_k = 1000000000.0",
        "reg_kk: unknown parameter (did you mean 'reg_k'?)",
    ):
        assert part in text
    for source in ("[1]", " [1, 2]"):
        with pytest.raises(ModelError, match="top level must be an object"):
            ParameterSet.from_json(params, source)
    with pytest.raises(ModelError, match="'parameters' must be an object, not a list"):
        ParameterSet.from_json(params, '{"parameters": []}')
    with pytest.raises(ModelError, match="not JSON"):
        ParameterSet.from_json(params, '{"parameters": ')
    with pytest.raises(ModelError, match="cannot read parameter file"):
        ParameterSet.from_json(params, "no/such/file.json")


def test_a_parameter_set_of_another_model_is_refused_by_name():
    """A set is read by position; one of another model with as many parameters was
    simulated silently with shifted values."""
    m = CircuitModel()
    lag, delay = m.with_effects("sensor_lag"), m.with_effects("transport_delay")
    with pytest.raises(ModelError) as err:
        lag.default_params().for_model(delay.parameters)
    assert "missing (the model has them): delay_d, delay_d0" in str(err.value)
    assert "extra (the model does not have them): slag_kappa, slag_tau" in str(err.value)
    ps = m.default_params()
    assert ps.for_model(m.parameters) is ps
    # same names in another order: rebuilt in the model's order
    reordered = ParameterSet(tuple(reversed(m.parameters)), {"reg_k": 20.0})
    again = reordered.for_model(m.parameters)
    assert again.parameters == m.parameters and again["reg_k"] == 20.0


def test_a_value_that_is_not_a_number_is_named_not_converted():
    """``replace(reg_k=True)`` ran the model with a 1 N/mm spring without a word, and
    ``replace(reg_k="15 N/mm")`` / ``replace(reg_k=None)`` raised float()'s own error naming
    no parameter. All are now listed in the ModelError, each with the parameter's unit."""
    base = CircuitModel().default_params()
    with pytest.raises(ModelError) as err:
        base.replace(reg_k=True, vfs_d_orf="0.6 mm", cacc_V=None, fb_V=[0.5])
    text = str(err.value)
    assert "reg_k = True is not a number (give the value in N/mm" in text
    assert "vfs_d_orf = '0.6 mm' is not a number (give the value in mm" in text
    assert "cacc_V = None is not a number" in text and "fb_V = [0.5] is not a number" in text
    assert base.replace(reg_k=np.float64(20.0), vfs_d_orf=1)["reg_k"] == 20.0


def test_a_parameter_of_an_effect_the_model_lacks_names_the_effect():
    """``replace(slag_tau=3)`` on a model without sensor lag said 'unknown parameter' only."""
    with pytest.raises(ModelError) as err:
        CircuitModel().default_params().replace(slag_tau=3.0, nope=1.0)
    text = str(err.value)
    assert "unknown parameter 'slag_tau': it belongs to the effect 'sensor_lag'" in text
    assert "CircuitModel().with_effects('sensor_lag')" in text
    assert "unknown parameter 'nope'\n" in text + "\n"


def test_a_misspelt_parameter_names_the_close_ones():
    """``replace(reg_Fc=1.2)`` said "unknown parameter 'reg_Fc'" without the name meant."""
    with pytest.raises(ModelError, match=r"unknown parameter 'reg_Fc' \(did you mean 'reg_F_c'"):
        CircuitModel().default_params().replace(reg_Fc=1.2)
