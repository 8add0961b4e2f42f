"""Components of the clutch control circuit (solenoid → accumulator → regulator → latch)."""

from .base import Component, param
from .clutch_node import ClutchNode
from .current_driver import CurrentDriver, dither_waveform
from .fluid import Fluid, flow
from .latch import LatchValve, latch_snap_problem, latch_thresholds
from .pilot_node import PilotNode
from .regulator import FeedbackChamber, RegulatorSpool
from .sensor import PressureSensor
from .vfs import VariableForceSolenoid

__all__ = [
    "ClutchNode",
    "Component",
    "CurrentDriver",
    "FeedbackChamber",
    "Fluid",
    "LatchValve",
    "PilotNode",
    "PressureSensor",
    "RegulatorSpool",
    "VariableForceSolenoid",
    "default_components",
    "dither_waveform",
    "flow",
    "latch_snap_problem",
    "latch_thresholds",
    "param",
]


def default_components() -> tuple[Component, ...]:
    """The base circuit, in signal-flow order."""
    return (
        Fluid(),
        CurrentDriver(),
        VariableForceSolenoid(),
        PilotNode(),
        RegulatorSpool(),
        FeedbackChamber(),
        LatchValve(),
        ClutchNode(),
        PressureSensor(),
    )
