"""Multi-experiment fitting of the physics model (CasADi sensitivities + IPOPT)."""

from .fitter import PhysicsFitter, resolve_free
from .problem import FitProblem
from .result import FitResult, identifiability
from .sensitivity import SensitivityRun, sensitivity_chunk, simulate_sensitivities
from .settings import DEFAULT_FREE, FitSettings

__all__ = [
    "DEFAULT_FREE",
    "FitProblem",
    "FitResult",
    "FitSettings",
    "PhysicsFitter",
    "SensitivityRun",
    "identifiability",
    "resolve_free",
    "sensitivity_chunk",
    "simulate_sensitivities",
]
