"""Multi-experiment fitting of the physics model (CasADi sensitivities + IPOPT)."""

from .fitter import PhysicsFitter, PrefitPoint, check_savable, period_mean_pairs, resolve_free
from .problem import FitProblem
from .rate import FIT_RATE_MARGIN, SUGGESTED_FIT_RATE_HZ, at_fit_rate, faster_than_fit
from .result import (
    FitResult,
    ParameterUncertainty,
    correlation_note,
    diverged_sensitivities,
    identifiability,
    parameter_uncertainty,
    residual_correlation_time,
    training_rms,
)
from .sensitivity import (
    SENSITIVITY_CHUNK,
    SensitivityRun,
    compile_fit_code,
    compile_sensitivities_for,
    compile_sensitivities_in_background,
    sensitivity_chunk,
    simulate_sensitivities,
)
from .settings import DEFAULT_FREE, FIT_BUDGET_S, FitSettings
from .staged import latches_where_data_do_not
from .stages import prefit_settings, prefit_subset, refine_settings
from .structure import (
    STRUCTURES,
    CandidateScore,
    StructureSelection,
    StructureSelector,
    select_structure,
)

__all__ = [
    "DEFAULT_FREE",
    "FIT_BUDGET_S",
    "FIT_RATE_MARGIN",
    "SENSITIVITY_CHUNK",
    "STRUCTURES",
    "SUGGESTED_FIT_RATE_HZ",
    "CandidateScore",
    "FitProblem",
    "FitResult",
    "FitSettings",
    "ParameterUncertainty",
    "PhysicsFitter",
    "PrefitPoint",
    "SensitivityRun",
    "StructureSelection",
    "StructureSelector",
    "at_fit_rate",
    "check_savable",
    "compile_fit_code",
    "compile_sensitivities_for",
    "compile_sensitivities_in_background",
    "correlation_note",
    "diverged_sensitivities",
    "faster_than_fit",
    "identifiability",
    "latches_where_data_do_not",
    "parameter_uncertainty",
    "period_mean_pairs",
    "prefit_settings",
    "prefit_subset",
    "refine_settings",
    "residual_correlation_time",
    "resolve_free",
    "select_structure",
    "sensitivity_chunk",
    "simulate_sensitivities",
    "training_rms",
]
