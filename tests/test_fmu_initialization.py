"""Outputs read in Initialization Mode (the FMU's initial unknowns) are computed.

A master that reads the FMU's outputs before ``fmi2ExitInitializationMode`` (to propagate
initial values through connected FMUs, as FMI 2.0 allows for ``InitialUnknowns``) got
0 bar and 0 mA: the outputs were computed only on leaving Initialization Mode.
"""

from __future__ import annotations

import shutil

import fmpy
from fmpy.fmi2 import FMU2Slave
from fmu_support import exported


def _slave():
    path = exported("command")
    md = fmpy.read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = fmpy.extract(str(path))
    fmu = FMU2Slave(
        guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier
    )
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    return fmu, vr, unzip


def _outputs(vr):
    return [vr[n] for n in ("clutch_pressure_bar", "coil_current_mA", "latch_state")]


def test_outputs_in_initialization_mode_are_those_after_it():
    fmu, vr, unzip = _slave()
    try:
        fmu.setReal([vr["current_cmd_mA"]], [700.0])
        during = fmu.getReal(_outputs(vr))
        fmu.exitInitializationMode()
        after = fmu.getReal(_outputs(vr))
        assert during == after
        assert during[0] > 5.0 and abs(during[1] - 700.0) < 1.0  # not 0 bar / 0 mA
        fmu.doStep(0.0, 1e-3)
        fmu.terminate()
    finally:
        fmu.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)


def test_an_input_set_after_reading_initial_outputs_is_used():
    """Reading outputs during initialization does not freeze the initial inputs: a value
    set afterwards is what the FMU leaves Initialization Mode with."""
    fmu, vr, unzip = _slave()
    ref, ref_vr, ref_unzip = _slave()
    try:
        fmu.setReal([vr["current_cmd_mA"]], [300.0])
        low = fmu.getReal(_outputs(vr))
        fmu.setReal([vr["current_cmd_mA"]], [700.0])
        fmu.exitInitializationMode()
        ref.setReal([ref_vr["current_cmd_mA"]], [700.0])
        ref.exitInitializationMode()
        assert fmu.getReal(_outputs(vr)) == ref.getReal(_outputs(ref_vr)) != low
        fmu.terminate()
        ref.terminate()
    finally:
        fmu.freeInstance()
        ref.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)
        shutil.rmtree(ref_unzip, ignore_errors=True)
