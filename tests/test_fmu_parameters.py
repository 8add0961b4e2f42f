"""Vendor-FMU habits: parameter values by ``parameters=`` / ``--fmu-param``, and every parameter
left at the FMU's start value listed."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from fmu_support import exported, medium_trace

from clutchlab.physics.fmu import FmuError, FmuPhysics


def test_parameters_set_values_like_start_values_and_are_listed_when_left():
    trace = medium_trace()
    plain = FmuPhysics(exported("command"))
    heavy = FmuPhysics(exported("command"), parameters={"reg_m": 40.0})
    alias = FmuPhysics(exported("command"), start_values={"reg_m": 40.0})
    sim_plain, sim_heavy = plain.simulate(trace), heavy.simulate(trace)
    assert not np.allclose(sim_plain.pressure_bar, sim_heavy.pressure_bar)
    np.testing.assert_array_equal(sim_heavy.pressure_bar, alias.simulate(trace).pressure_bar)
    left = [m for m in sim_heavy.messages if "left at the FMU's start value" in m]
    assert left and not any("'reg_m'" in m for m in left)
    assert any("'reg_m'" in m for m in sim_plain.messages)


def test_parameter_given_twice_with_two_values_is_refused():
    with pytest.raises(FmuError, match="reg_m"):
        FmuPhysics(exported("command"), parameters={"reg_m": 40.0}, start_values={"reg_m": 20.0})
    with pytest.raises(FmuError, match="unknown parameter"):
        FmuPhysics(exported("command"), parameters={"no_such": 1.0})


def test_cli_fmu_param_must_be_name_equals_number(tmp_path):
    res = subprocess.run(
        [
            sys.executable, "-m", "clutchlab.cli", "evaluate", str(tmp_path), "--out",
            str(tmp_path / "r"), "--physics-fmu", str(exported("command")),
            "--fmu-param", "reg_m=heavy",
        ],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert res.returncode != 0
    assert "--fmu-param 'reg_m=heavy': expected NAME=VALUE" in res.stderr
