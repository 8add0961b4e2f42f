"""FMU export (FMI 2.0 co-simulation, CasADi-generated C) and import (a vendor FMU as physics).

Export: :func:`export_physics_fmu` turns a fitted physics model into an FMU whose step is
the simulator's compiled sample step; :class:`FmuProgram` + :func:`build_fmu` do the same for
any model written as CasADi functions: :func:`ml_program` (GPs, latch classifier, causal
dI/dt, hybrid on a physics program) and :func:`ml_program_from` (fitted ``residual_ml``
estimators). Import: :class:`FmuPhysics` runs an FMU
with FMPy on a trace's inputs and predicts the clutch pressure like a physics model.
"""

from .adapters import ml_program_from
from .build import build_fmu
from .errors import FmuError, FmuTimeoutError
from .export import export_physics_fmu, physics_source
from .importer import FmuPhysics, FmuSimulation
from .inspect import FmuInterface, FmuPort, inspect_fmu
from .ml import ML_FEATURES, DecisionSpec, DidtSpec, GPSpec, LagSpec, ml_program
from .physics import DRIVES, physics_program
from .program import FmuProgram, FmuVariable

__all__ = [
    "DRIVES",
    "ML_FEATURES",
    "DecisionSpec",
    "DidtSpec",
    "FmuError",
    "FmuInterface",
    "FmuPhysics",
    "FmuPort",
    "FmuProgram",
    "FmuSimulation",
    "FmuTimeoutError",
    "FmuVariable",
    "GPSpec",
    "LagSpec",
    "build_fmu",
    "export_physics_fmu",
    "inspect_fmu",
    "ml_program",
    "ml_program_from",
    "physics_program",
    "physics_source",
]
