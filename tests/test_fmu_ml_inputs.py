"""ML and hybrid FMUs check their inputs and their physics' pressures as a physics FMU does
(``test_fmu_user_inputs.py``): a standalone ML FMU declared no input range at all and
returned the GP's mean far from its data (a current in A, 1.1 instead of 1100 mA) with
status OK."""

from __future__ import annotations

import fmpy
import numpy as np
from fmu_support import input_table, simulate_logged
from test_fmu_ml import hybrid_fmu, partitioned_fmu

from clutchlab.data import SIGNALS


def test_ml_fmu_inputs_declare_and_enforce_the_plausible_ranges():
    fmu = partitioned_fmu()[0]
    md = fmpy.read_model_description(str(fmu))
    for v in md.modelVariables:
        if v.causality == "input":
            spec = SIGNALS[v.name]
            assert (float(v.min), float(v.max)) == (spec.plausible_min, spec.plausible_max)
    sig = input_table()
    sig["current_cmd_mA"][5:] = 5000.0
    res, text = simulate_logged(fmu, sig)
    assert isinstance(res, Exception) and "fmi2DoStep" in str(res), res
    assert "input current_cmd_mA = " in text and "outside its range [-300, 2000] mA" in text


def test_ml_fmu_runs_inside_the_ranges():
    res, text = simulate_logged(partitioned_fmu()[0], input_table())
    assert not isinstance(res, Exception), text
    assert np.all(np.isfinite(res))


def test_hybrid_fmu_stops_on_an_unreachable_physics_pressure():
    """``vfs_c`` at its lower bound: the hybrid's physics part leaves the range the circuit
    can reach (as its physics FMU does); the error names the physics output."""
    fmu = hybrid_fmu()[0]
    res, text = simulate_logged(fmu, input_table(stop_s=1.0), start_values={"vfs_c": 1.0})
    assert isinstance(res, Exception) and "fmi2DoStep" in str(res), res
    assert "pilot_pressure_bar = " in text and "outside the range the circuit can reach" in text
    ok, text = simulate_logged(fmu, input_table(stop_s=1.0))
    assert not isinstance(ok, Exception), text
