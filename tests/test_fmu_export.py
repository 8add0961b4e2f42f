"""FMU export: validation, modelDescription content, agreement with the in-process model."""

from __future__ import annotations

import ctypes

import fmpy
import numpy as np
import pytest
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu
from fmu_support import FITTED, exported, fit_result, medium_trace
from synthetic import make_trace

from clutchlab.errors import SimulationError
from clutchlab.physics import SimulationSettings, simulate
from clutchlab.physics.fmu import FmuPhysics

DRIVES = ("command", "measured")
#: Must-show 1: the FMU on the medium ramp against the in-process model.
MATCH_BAR = 0.01


@pytest.mark.parametrize("drive", DRIVES)
def test_exported_fmu_passes_fmpy_validation(drive):
    assert validate_fmu(str(exported(drive))) == []


@pytest.mark.parametrize("drive", DRIVES)
def test_model_description_has_units_descriptions_starts_and_experiment(drive):
    md = fmpy.read_model_description(str(exported(drive)))
    assert md.fmiVersion == "2.0" and md.coSimulation is not None
    assert md.coSimulation.canInterpolateInputs and md.coSimulation.canGetAndSetFMUstate
    assert md.defaultExperiment.stepSize == "0.001" or float(md.defaultExperiment.stepSize) == 1e-3
    var = {v.name: v for v in md.modelVariables}
    current = "current_cmd_mA" if drive == "command" else "current_mA"
    inputs = [v.name for v in md.modelVariables if v.causality == "input"]
    assert inputs == [
        current,
        "dither_amp_mA",
        "dither_freq_Hz",
        "line_pressure_bar",
        "prime_pressure_bar",
        "oil_temp_C",
    ]
    assert var[current].unit == "mA" and var["oil_temp_C"].unit == "degC"
    assert float(var["line_pressure_bar"].start) == 17.7
    assert (
        var["clutch_pressure_bar"].causality == "output"
        and var["clutch_pressure_bar"].unit == "bar"
    )
    assert var["latch_state"].causality == "output"
    for name, value in FITTED.items():  # the fitted values are the parameters' start values
        assert var[name].causality == "parameter"
        assert float(var[name].start) == value
    assert all(v.description for v in md.modelVariables)
    units = {u.name: u.baseUnit for u in md.unitDefinitions}
    assert units["bar"].factor == 1e5 and units["degC"].offset == 273.15


@pytest.mark.parametrize(("drive", "waveform"), [("command", "triangle"), ("measured", "sine")])
def test_fmu_matches_in_process_model_on_medium_ramp(drive, waveform):
    """Must-show 1: max |Δp| ≤ 0.01 bar over the 23 s medium ramp (1 kHz, 23 000 steps)."""
    trace = medium_trace(waveform)
    fit = fit_result()
    ref = simulate(fit.model(), fit.params(), trace, SimulationSettings(drive=drive))
    sim = FmuPhysics(exported(drive)).simulate(trace)
    err = np.abs(sim.pressure_bar - ref.pressure_bar)
    assert err.max() <= MATCH_BAR, (drive, err.max(), trace.time_s[err.argmax()])
    assert np.abs(sim.outputs["latch_state"] - ref.outputs["latch_state"]).max() <= 1e-3
    assert np.ptp(ref.pressure_bar) > 5.0  # the ramp exercises the circuit (latch included)
    if drive == "command":
        assert sim.start_values["dither_wave_triangle"] == 1.0


def test_fmpy_simulate_fmu_runs_the_fmu():
    """fmpy's own driver (inputs held over each step) simulates the FMU: a 2 s ramp."""
    trace = make_trace([0, 0.5, 1.5, 2.0], [0, 0, 700, 700], name="ramp")
    names = ("current_cmd_mA", "dither_amp_mA", "dither_freq_Hz", "line_pressure_bar")
    signals = np.zeros(len(trace), dtype=[("time", float)] + [(n, float) for n in names])
    signals["time"] = trace.time_s
    for n in names:
        signals[n] = trace.get(n)
    res = fmpy.simulate_fmu(
        str(exported("command")),
        input=signals,
        stop_time=2.0,
        output_interval=1e-3,
        start_values={"oil_temp_C": 40.0},
        timeout=120,
    )
    fit = fit_result()
    ref = simulate(fit.model(), fit.params(), trace, SimulationSettings(drive="command"))
    assert len(res) == len(trace)
    err = np.abs(res["clutch_pressure_bar"] - ref.pressure_bar)
    # Held instead of linear inputs: a half-sample lag of a slow ramp, no latch on this ramp.
    assert err.max() < 0.05, err.max()
    assert res["clutch_pressure_bar"][-1] > 3.0


def _slave(path):
    md = fmpy.read_model_description(str(path))
    unzip = fmpy.extract(str(path))
    fmu = FMU2Slave(
        guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier
    )
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.setReal([vr["current_cmd_mA"], vr["dither_amp_mA"]], [500.0, 80.0])
    fmu.exitInitializationMode()
    return fmu, vr


def test_long_communication_step_is_split_into_nominal_steps():
    """One 10 ms step with linear inputs equals ten 1 ms steps with the same inputs."""
    path = exported("command")
    out = []
    for pieces in (1, 10):
        fmu, vr = _slave(path)
        cur, p = vr["current_cmd_mA"], vr["clutch_pressure_bar"]
        t = 0.0
        for _ in range(pieces):
            fmu.setReal([cur], [500.0 + 2000.0 * t])
            fmu.setRealInputDerivatives([cur], [1], [2000.0])  # 2 mA/ms
            fmu.doStep(t, 0.01 / pieces)
            t += 0.01 / pieces
        out.append(fmu.getReal([p])[0])
        fmu.terminate()
        fmu.freeInstance()
    assert abs(out[0] - out[1]) < 1e-9, out


def test_fmu_state_get_set_and_serialize_restore_the_step():
    fmu, vr = _slave(exported("command"))
    p = vr["clutch_pressure_bar"]
    for k in range(20):
        fmu.doStep(k * 1e-3, 1e-3)
    state = fmu.getFMUstate()
    blob = fmu.serializeFMUstate(state)
    fmu.setReal([vr["current_cmd_mA"]], [900.0])
    for k in range(20, 40):
        fmu.doStep(k * 1e-3, 1e-3)
    first = fmu.getReal([p])[0]
    fmu.setFMUstate(fmu.deSerializeFMUstate(blob))
    fmu.setReal([vr["current_cmd_mA"]], [900.0])
    for k in range(20, 40):
        fmu.doStep(k * 1e-3, 1e-3)
    assert fmu.getReal([p])[0] == first
    fmu.freeFMUstate(state)
    fmu.terminate()
    fmu.freeInstance()


def test_diverging_parameters_give_an_error_from_the_fmu():
    """A dither waveform weight of 1e200 (a parameter without declared bounds):
    initialization fails and the FMU's own message is in the error. (A NaN parameter is
    refused before the FMU runs: ``test_fmu_parameter_outside_its_declared_range_is_refused``.)
    """
    physics = FmuPhysics(exported("command"), start_values={"dither_wave_sine": 1e200})
    with pytest.raises(SimulationError, match=r"settling run .* diverged"):
        physics.predict(medium_trace())


def test_fmu_refuses_a_parameter_change_after_initialization():
    fmu, vr = _slave(exported("command"))
    status = fmu._functions["fmi2SetReal"](
        fmu.component, (ctypes.c_uint32 * 1)(vr["reg_m"]), 1, (ctypes.c_double * 1)(20.0)
    )
    assert status == 3  # fmi2Error
    fmu.terminate()
    fmu.freeInstance()
