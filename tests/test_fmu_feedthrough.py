"""What a master reads from ``ModelStructure``: the FMU's outputs have no direct feedthrough.

The outputs are those at the end of the last ``fmi2DoStep`` (or of initialization) and do
not change when an input is set. Without a ``dependencies`` attribute FMI 2.0 says an
output depends on every input, so a master closing a loop through the FMU (a pressure
controller reading ``clutch_pressure_bar`` and setting ``current_cmd_mA``) saw an
algebraic loop that does not exist, and a master that iterates such loops waited for
outputs that never moved. Also what such a master may send: input derivatives of any order.
"""

from __future__ import annotations

import shutil
from contextlib import contextmanager

import fmpy
from fmpy.fmi2 import FMU2Slave
from fmu_support import exported


@contextmanager
def _initialized(path, vr: dict, current_mA: float):
    """An instance of the FMU ``path`` out of initialization at ``current_mA`` (mA)."""
    md = fmpy.read_model_description(str(path))
    unzip = fmpy.extract(str(path))
    fmu = FMU2Slave(
        guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier
    )
    try:
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.setReal([vr["current_cmd_mA"]], [current_mA])
        fmu.exitInitializationMode()
        yield fmu
        fmu.terminate()
    finally:
        fmu.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)


def test_outputs_declare_no_dependency_on_the_inputs():
    md = fmpy.read_model_description(str(exported("command")))
    outputs = [v for v in md.modelVariables if v.causality == "output"]
    assert [u.variable for u in md.outputs] == outputs
    assert all(u.dependencies == [] for u in md.outputs)


def test_an_input_set_after_a_step_does_not_change_the_outputs_until_the_next_step():
    """The declaration above is what the FMU does."""
    path = exported("command")
    md = fmpy.read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
    with _initialized(path, vr, 500.0) as fmu:
        for k in range(20):
            fmu.doStep(k * 1e-3, 1e-3)
        before = fmu.getReal(outs)
        fmu.setReal([vr["current_cmd_mA"], vr["line_pressure_bar"]], [900.0, 12.0])
        assert fmu.getReal(outs) == before
        fmu.doStep(20e-3, 1e-3)
        assert fmu.getReal(outs) != before


def test_higher_input_derivative_orders_are_accepted_and_unused():
    """FMI 2.0 declares no highest order of input derivatives, so a master that
    extrapolates its inputs quadratically may set order 2 with ``canInterpolateInputs``;
    the FMU returned fmi2Error ("only order 1 is supported") and the co-simulation
    stopped. Order 2 is now accepted and unused (the inputs are linear over a step)."""
    path = exported("command")
    md = fmpy.read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    cur, p = vr["current_cmd_mA"], vr["clutch_pressure_bar"]
    out = []
    for orders in ([1], [1, 2]):
        with _initialized(path, vr, 400.0) as fmu:
            for k in range(50):
                fmu.setReal([cur], [400.0 + 4000.0 * k * 1e-3])
                fmu.setRealInputDerivatives(
                    [cur] * len(orders), orders, [4000.0, 1e5][: len(orders)]
                )
                fmu.doStep(k * 1e-3, 1e-3)
            out.append(fmu.getReal([p])[0])
    assert out[0] == out[1]
