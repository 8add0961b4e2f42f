"""Closing the loop (DESIGN §6): from the fit residual to a named missing effect.

``discover(dataset)`` fits the physics model on the training ramps, examines the
residual (against each signal, lagged cross-correlation, spectrum, whiteness, a
sparse regression with pysindy), scores every library effect the model lacks by how
much of the residual its output sensitivity explains (a score test at zero strength),
confirms the best by refitting, adds the winner while an information criterion
improves, and reports the error before and after on the training and the unseen test
ramp. It says "unexplained residual" rather than naming a wrong effect, and claims an
effect only when it predicts the left-out training experiments better than each
flexible component law of at most its size (``alternatives``).
"""

from .alternatives import Alternative, alternative_note, alternatives_for, fit_alternative
from .diagnostics import Diagnostics, diagnose, ramp_bound
from .loop import discover, period_mean_metrics
from .partial import regulated_partial
from .report import plot_diagnostics, plot_evidence, plot_residuals, write_report
from .residuals import ResidualSet, residual_problem, residual_set
from .result import DiscoveryResult, IterationRecord, ModelState
from .scoring import CandidateScore, score_candidates
from .settings import DiscoverySettings
from .sparse import SparseFit, sparse_regression

__all__ = [
    "Alternative",
    "CandidateScore",
    "Diagnostics",
    "DiscoveryResult",
    "DiscoverySettings",
    "IterationRecord",
    "ModelState",
    "ResidualSet",
    "SparseFit",
    "alternative_note",
    "alternatives_for",
    "diagnose",
    "discover",
    "fit_alternative",
    "period_mean_metrics",
    "plot_diagnostics",
    "plot_evidence",
    "plot_residuals",
    "ramp_bound",
    "regulated_partial",
    "residual_problem",
    "residual_set",
    "score_candidates",
    "sparse_regression",
    "write_report",
]
