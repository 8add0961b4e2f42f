"""A co-simulation user's inputs and parameters: what the physics FMU refuses, and how.

Found by using an exported FMU as a controls engineer would (fmpy, own input tables):
a NaN input was reported as "the integrator diverged", a current of 5000 mA (or an oil
temperature in K) gave −7·10⁶ bar with status OK, and a parameter inside its declared
bounds (``vfs_c`` = 1 N·s/m) gave −38 000 bar with status OK.
"""

from __future__ import annotations

import fmpy
import numpy as np
import pytest
from fmu_support import exported, fit_result, input_table, simulate_logged
from synthetic import make_trace

from clutchlab.data import SIGNALS
from clutchlab.errors import SimulationError, SimulationWarning
from clutchlab.physics import SimulationSettings, simulate

COMMAND = SimulationSettings(drive="command")
INPUTS = (
    "current_cmd_mA",
    "dither_amp_mA",
    "dither_freq_Hz",
    "line_pressure_bar",
    "prime_pressure_bar",
    "oil_temp_C",
)


def _run(fmu, start_values=None, **constant):
    """:func:`simulate_logged` on the default ramp with ``constant`` inputs added."""
    return simulate_logged(fmu, input_table(**constant), start_values)


def test_inputs_declare_the_data_contracts_plausible_range():
    md = fmpy.read_model_description(str(exported("command")))
    var = {v.name: v for v in md.modelVariables if v.causality == "input"}
    assert list(var) == list(INPUTS)
    for name, v in var.items():
        spec = SIGNALS[name]
        assert (float(v.min), float(v.max)) == (spec.plausible_min, spec.plausible_max), name
        assert float(v.min) <= float(v.start) <= float(v.max)


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("current_cmd_mA", 5000.0),  # -7e6 bar with status OK on a design with all effects
        ("oil_temp_C", 313.15),  # in K
        ("line_pressure_bar", 1770.0),  # in kPa
        ("dither_freq_Hz", -50.0),
    ],
)
def test_an_input_outside_its_range_is_refused_by_name(name, value):
    sig = input_table(line_pressure_bar=17.7, oil_temp_C=40.0)
    sig[name][5:] = value  # in range at initialization, out of it from t ≈ 40 ms
    res, text = simulate_logged(exported("command"), sig)
    assert isinstance(res, Exception) and "fmi2DoStep" in str(res), res
    assert f"input {name} = " in text and "outside its range" in text, text
    lo, hi = SIGNALS[name].plausible_min, SIGNALS[name].plausible_max
    assert f"[{lo:g}, {hi:g}]" in text, text


def test_an_input_at_its_bound_is_inside():
    """An importer's interpolation between two rows at the bound may land 1 ulp outside."""
    res, text = _run(exported("command"), oil_temp_C=-40.0, line_pressure_bar=60.0)
    assert not isinstance(res, Exception), text
    assert np.all(np.isfinite(res))


def test_a_nan_input_is_named_not_reported_as_a_divergence():
    sig = input_table()
    sig["current_cmd_mA"][10:] = np.nan
    res, text = simulate_logged(exported("command"), sig)
    assert isinstance(res, Exception) and "fmi2DoStep" in str(res), res
    assert "input current_cmd_mA is nan" in text and "diverged" not in text, text


def test_a_nan_parameter_is_named_at_initialization():
    res, text = _run(exported("command"), start_values={"vfs_K_m": float("nan")})
    assert isinstance(res, Exception) and "fmi2ExitInitializationMode" in str(res)
    assert "parameter vfs_K_m is nan" in text and "diverged" not in text, text


def test_a_finite_but_unphysical_pressure_is_an_error_as_in_process():
    """``vfs_c`` at its lower bound (1 N·s/m): the fixed-step solution stays finite and
    reaches −44 bar in the pilot chamber at 0.17 s (thousands of bar later). In process,
    :meth:`SimulationResult.check_pressures` says so; the FMU returned status OK."""
    sig = input_table(stop_s=1.0)
    res, text = simulate_logged(exported("command"), sig, start_values={"vfs_c": 1.0})
    assert isinstance(res, Exception) and "fmi2DoStep" in str(res), res
    assert "pilot_pressure_bar = " in text and "outside the range the circuit can reach" in text
    assert "[-1, 26.55] bar" in text, text  # 1.5 × 17.7 bar line pressure
    fit = fit_result()
    params = fit.model().params(**{**fit.values, "vfs_c": 1.0})
    with pytest.warns(SimulationWarning, match="outside the range the circuit can reach"):
        ref = simulate(fit.model(), params, make_trace([0.0, 1.0], [0.0, 800.0]), COMMAND)
    with pytest.raises(SimulationError, match="outside the range the circuit can reach"):
        ref.check_pressures()


def test_inputs_in_range_still_run_and_match_the_default():
    """The checks change nothing inside the ranges: the default run is unchanged by an
    explicit line / prime pressure at their start values."""
    res, text = _run(exported("command"), line_pressure_bar=17.7, prime_pressure_bar=0.5)
    ref, _ = _run(exported("command"))
    assert not isinstance(res, Exception), text
    np.testing.assert_array_equal(res, ref)


@pytest.mark.parametrize(
    ("start_values", "shown"),
    [
        # accepted silently (clutch pressure 0.56 bar) although the model refuses it:
        # CircuitModel().params(vfs_K_m=1000) raises "outside bounds [5, 30] N/A"
        ({"vfs_K_m": 1000.0}, "parameter vfs_K_m = 1000 N/A is outside its range [5, 30] N/A"),
        # accepted up to any length: 10⁶ s ran initialization for hours (8 ms per settled
        # second; 600 s here, 5 s on the old code)
        ({"settle_s": 600.0}, "parameter settle_s = 600 s is outside its range [0, 60] s"),
    ],
)
def test_a_parameter_outside_its_declared_range_is_refused_at_initialization(start_values, shown):
    res, text = _run(exported("command"), start_values=start_values)
    assert isinstance(res, Exception) and "fmi2ExitInitializationMode" in str(res), res
    assert shown in text, text


def test_settle_s_declares_the_simulators_range():
    md = fmpy.read_model_description(str(exported("command")))
    settle = next(v for v in md.modelVariables if v.name == "settle_s")
    assert (settle.min, settle.max) == ("0.0", "60.0")  # SimulationSettings.settle_s


def test_a_parameter_at_its_bound_is_accepted():
    res, text = _run(exported("command"), start_values={"vfs_K_m": 30.0, "settle_s": 0.0})
    assert not isinstance(res, Exception), text
