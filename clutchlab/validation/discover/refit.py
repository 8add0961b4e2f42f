"""Refits inside discovery: the fit itself, the residual at a fit, its start, and its verdict.

Shared by the confirmatory refits on every training experiment (:mod:`.loop`) and the
screening refits on the pre-fit subset (:mod:`.screen`).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import replace

import numpy as np

from ...data import Trace
from ...errors import ClutchlabError, FitError, FitWarning
from ...physics import CircuitModel
from ...physics.effects import EFFECTS
from ...physics.fit import FitResult, FitSettings, PhysicsFitter
from ...physics.parameters import ParameterSet
from .deadline import budget_spent, capped_fit, check_budget, cut_by_budget
from .residuals import (
    ResidualSet,
    loeo_evidence,
    point_sums_of_squares,
    residual_problem,
    residual_set,
)
from .scoring import CandidateScore
from .settings import DiscoverySettings
from .warm import warm_sensitivities

__all__ = [
    "START_FRACTIONS",
    "by_criterion",
    "candidate_free",
    "judge",
    "refit_start",
    "residual_at",
    "run_fit",
]

#: Fractions of the one-step strength estimate tried as refit starts (besides the default):
#: the estimate is a linear extrapolation, far off when the strength enters nonlinearly
#: (a quadratic strength probed near zero overshoots by ``s_true / (2 s_probe)``).
START_FRACTIONS = (1.0, 0.5, 0.25, 0.1)


def run_fit(
    model: CircuitModel,
    traces: list[Trace],
    settings: DiscoverySettings,
    free: tuple[str, ...],
    start: ParameterSet | None,
    fit: FitSettings | None = None,
    *,
    what: str = "a refit",
    budget_ok: bool = False,
    prefit: list | None = None,
) -> FitResult:
    """Fit; a fit that stops short returns its best iterate (discovery's refits are short by
    design, so the FitWarning saying so is not shown; the status is in the result).

    ``fit`` replaces ``settings.fit`` (a screening or refinement stage's settings). Inside
    a discovery with a time budget (:mod:`.deadline`) the fit's time limit is at most the
    budget left, and a fit the budget stopped raises :class:`.DiscoveryTimeLimit` naming
    ``what`` — it is not judged against complete refits — unless ``budget_ok`` (the
    baseline fit, whose best iterate is the model whatever stopped it).

    ``prefit``, a list, receives the fit's :class:`~clutchlab.physics.fit.PrefitPoint`
    (its optimum on the pre-fit subset) when the fit was staged.
    """
    if not budget_ok:
        check_budget(what)
    fit = fit or settings.fit
    warm_sensitivities(model, traces, fit, len(free))
    fit, capped = capped_fit(fit)
    fitter = PhysicsFitter(model, replace(fit, free=free), start)
    t0 = time.perf_counter()
    error: FitError | None = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FitWarning)
            result = fitter.fit(traces).result_
    except FitError as exc:
        error, result = exc, getattr(exc, "result", None)
    if not budget_ok and cut_by_budget(fit, capped, result, time.perf_counter() - t0):
        raise budget_spent(f"the end of {what}") from error
    if result is None:
        raise error
    if prefit is not None and fitter.prefit_ is not None:
        prefit.append(fitter.prefit_)
    return result


def residual_at(
    model: CircuitModel,
    params: ParameterSet,
    free: tuple[str, ...],
    traces: list[Trace],
    settings: DiscoverySettings,
    jacobian: bool = True,
) -> ResidualSet:
    """The training residual of ``model`` at ``params`` on ``traces`` (with the free
    parameters' output sensitivities when ``jacobian``)."""
    problem = residual_problem(model, params, tuple(free), traces, settings.fit)
    if jacobian:
        warm_sensitivities(model, traces, settings.fit, len(free))
        problem.start_workers(traces, settings.fit.workers)
    try:
        return residual_set(problem, traces, jacobian=jacobian, snap_guard_s=settings.snap_guard_s)
    finally:
        problem.close()


def judge(res: ResidualSet, rss_ref: float, k: int) -> dict | None:
    """A refit's verdict against the reference residual sum of squares ``rss_ref`` (bar²).

    ``ΔBIC = n_eff · ln(RSS₁/RSS₀) + k · ln(n_eff)`` for ``k`` added free parameters, and
    the linearized leave-one-experiment-out error (bar²). None when either sum of squares
    is not a positive number.
    """
    rss1 = res.kept_rss
    if not (math.isfinite(rss1) and rss1 > 0 and rss_ref > 0):
        return None
    n_eff, _ = res.effective()
    return {
        **loeo_evidence(res),
        "rss_bar2": rss1,
        "rss_ref_bar2": rss_ref,
        "n_eff": n_eff,
        "k": k,
        "delta_bic": n_eff * math.log(rss1 / rss_ref) + k * math.log(max(n_eff, 1.0)),
    }


def by_criterion(verdicts: list[dict]) -> list[int]:
    """Order refits of the same experiments by information criterion, best first.

    ``BIC = n · ln(RSS) + k · ln(n)`` with one effective sample size ``n`` for all — the
    smallest of theirs (``n_eff``), so that a better fit is not outweighed by a refit's
    own estimate of its sample size — and ``k`` each one's added free parameters.

    Parameters
    ----------
    verdicts : list of dict
        Verdicts of :func:`judge` (``rss_bar2`` in bar², ``k``, ``n_eff``).

    Returns
    -------
    list of int
        Indices into ``verdicts``, lowest criterion first (ties keep their order).
    """
    if not verdicts:
        return []
    n = max(min(v["n_eff"] for v in verdicts), 1.0)
    key = [n * math.log(v["rss_bar2"]) + v["k"] * math.log(n) for v in verdicts]
    return sorted(range(len(verdicts)), key=key.__getitem__)


def refit_start(
    cand: CircuitModel,
    values: dict[str, float],
    score: CandidateScore,
    traces: list[Trace],
    settings: DiscoverySettings,
    keep: np.ndarray,
) -> ParameterSet:
    """Start of a confirmatory refit: the current fit plus the effect.

    Fitted non-strength parameters (a lag's time constant) start at the grid value where
    the score was largest. Fitted strengths start at the best — by the kept residual sum
    of squares on ``traces``, one simulation each — of :data:`START_FRACTIONS` × the
    one-step (score) estimate and the default strength.
    """
    cls = EFFECTS[score.effect]
    specs = {p.name: p for p in cand.parameters}
    base = dict(values) | dict(score.nuisance)
    fitted = [n for n in score.strength if n in cls.fit_parameters()]
    if not fitted:
        return cand.params(**base)
    trials = [{n: f * score.strength[n] for n in fitted} for f in START_FRACTIONS]
    trials.append({n: specs[n].default for n in fitted})
    clipped = [
        {n: min(max(v, specs[n].lower), specs[n].upper) for n, v in trial.items()}
        for trial in trials
    ]
    try:
        rss = point_sums_of_squares(cand, base, clipped, traces, settings.fit, keep)
    except ClutchlabError:
        rss = [math.inf] * len(clipped)
    k = int(np.argmin(rss)) if np.any(np.isfinite(rss)) else len(clipped) - 1
    return cand.params(**base, **clipped[k])


def candidate_free(current_free: tuple[str, ...], effect: str) -> tuple[str, ...]:
    """The current free parameters plus the effect's fit parameters."""
    free = tuple(current_free)
    return free + tuple(n for n in EFFECTS[effect].fit_parameters() if n not in free)
