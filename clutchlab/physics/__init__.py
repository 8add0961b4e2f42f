"""Lumped-parameter physics of the clutch control circuit, in CasADi.

Define the model once (:class:`CircuitModel`, optionally ``.with_effects(...)``),
then hand the frozen model to :func:`simulate`, fitters and exporters.
"""

from .assembly import MODEL_INPUTS, Assembly, InputSpec, StateSpec
from .components import Component, default_components, latch_thresholds
from .effects import EFFECTS, Effect, effect_table, make_effect
from .model import OUTPUTS, CircuitModel, ModelFunctions, OutputSpec
from .parameters import Parameter, ParameterSet
from .profile import drive_trace, knot_profile
from .result import SimulationResult
from .settings import SimulationSettings
from .simulate import simulate, simulate_inputs

__all__ = [
    "EFFECTS",
    "MODEL_INPUTS",
    "OUTPUTS",
    "Assembly",
    "CircuitModel",
    "Component",
    "Effect",
    "InputSpec",
    "ModelFunctions",
    "OutputSpec",
    "Parameter",
    "ParameterSet",
    "SimulationResult",
    "SimulationSettings",
    "StateSpec",
    "default_components",
    "drive_trace",
    "effect_table",
    "knot_profile",
    "latch_thresholds",
    "make_effect",
    "simulate",
    "simulate_inputs",
]
