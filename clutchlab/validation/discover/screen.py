"""Screening on the pre-fit subset: candidate refits that are cheap, confirmed on all data.

On long training data (the default stand: 18 experiments, 819 k samples) every refit on
all experiments costs about as much as the baseline fit. Discovery therefore screens: the
candidates are scored and refitted on the ramp-balanced subset the fit's own pre-fit uses
(:func:`clutchlab.physics.fit.prefit_subset`, at most ``DiscoverySettings.screen_samples``
samples, every ramp rate represented), each against the current fit continued there with
the same budget and stop (or, in the first iteration of a discovery that fitted its own
baseline, that fit's pre-fit optimum on the same subset); a candidate that lowers both the
information criterion and the leave-one-experiment-out error on the subset is refined on
every training experiment (the fit's refinement stage, from its subset optimum) and judged
again there, against the current fit — the decision is always taken on all training
experiments. When the training data fit in the budget the subset is all of them and there
is no screening stage.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

from ...data import Trace
from ...errors import ClutchlabError
from ...physics.fit import (
    FitResult,
    FitSettings,
    PrefitPoint,
    prefit_settings,
    prefit_subset,
    refine_settings,
)
from .refit import candidate_free, judge, refit_start, residual_at, run_fit
from .residuals import ResidualSet, loeo_evidence
from .result import ModelState
from .scoring import CandidateScore
from .settings import DiscoverySettings

__all__ = [
    "Screening",
    "confirm_settings",
    "screen_refit",
    "screen_settings",
    "screening",
]

#: What a failing screening refit may raise (reported in its evidence row, never raised).
_FAILURES = (ClutchlabError, ArithmeticError, ValueError)


@dataclass
class Screening:
    """The screening subset of one iteration.

    Attributes
    ----------
    traces : list of Trace
        The subset of the training experiments.
    residual : ResidualSet
        The current model's residual on it, with the free parameters' sensitivities
        (what the candidates are scored against).
    n_train : int
        Number of training experiments.
    reference : ResidualSet or None
        The residual the screening refits are compared with (set by :meth:`reference_for`).
    info : dict
        How the reference was obtained, its sums of squares, wall time.
    prefit : PrefitPoint or None
        The current fit's own pre-fit optimum on this subset, when the discovery made that
        fit (its baseline): the reference without a continuation.
    """

    traces: list[Trace]
    residual: ResidualSet
    n_train: int
    reference: ResidualSet | None = None
    info: dict = field(default_factory=dict)
    prefit: PrefitPoint | None = None

    def describe(self) -> str:
        """``"N of M experiments, S samples"``."""
        n = sum(len(t) for t in self.traces)
        return f"{len(self.traces)} of {self.n_train} experiments, {n} samples"

    def reference_for(self, current: ModelState, settings: DiscoverySettings) -> ResidualSet:
        """The current fit continued on the subset with a screening refit's budget (so that
        an added parameter does not look useful merely because its refit moved the other
        parameters to the subset); the better of the two by kept residual sum of squares.
        Where the current fit's own pre-fit ran on this subset (:attr:`prefit`), its
        optimum there takes the continuation's place."""
        if self.reference is not None:
            return self.reference
        t0 = time.perf_counter()
        res = self.residual
        info = {"rss_before_bar2": res.kept_rss}
        free = tuple(current.fit.free)
        if self._own_prefit(current):
            pre = self.prefit
            what = (
                "its pre-fit's optimum",
                "the current fit's own pre-fit on the subset",
                "its pre-fit's optimum is not lower",
            )

            def candidate() -> tuple[ResidualSet, dict]:
                again = residual_at(current.model, pre.params, free, self.traces, settings)
                return again, {"status": pre.status}

        else:
            what = (
                "its continuation",
                "current fit continued on the subset",
                "its continuation did not improve it",
            )

            def candidate() -> tuple[ResidualSet, dict]:
                fit = run_fit(
                    current.model,
                    self.traces,
                    settings,
                    free,
                    current.params,
                    fit=screen_settings(settings),
                    what="the current fit's continuation on the screening subset",
                )
                again = residual_at(fit.model(), fit.params(), fit.free, self.traces, settings)
                return again, {"status": fit.status, "iterations": fit.iterations}

        try:
            again, extra = candidate()
        except _FAILURES as exc:
            info["kind"] = f"current fit on the subset ({what[0]} failed: {exc})"
        else:
            info |= extra
            if again.kept_rss < res.kept_rss:
                res = again
                info["kind"] = what[1]
            else:
                info["kind"] = f"current fit on the subset ({what[2]})"
        self.reference = res
        self.info = info | {
            "subset": self.describe(),
            "experiments": [t.name for t in self.traces],
            "rss_bar2": res.kept_rss,
            **loeo_evidence(res),
            "wall_s": time.perf_counter() - t0,
        }
        return res

    def _own_prefit(self, current: ModelState) -> bool:
        """Whether :attr:`prefit` is the current model's fit on exactly this subset."""
        pre = self.prefit
        return (
            pre is not None
            and pre.model.key == current.model.key
            and pre.experiments == tuple(t.name for t in self.traces)
        )


#: Iterations of a screening refit's cost-plateau test: it stops when its cost moved less
#: than the pre-fit's ``prefit_obj_change_tol`` (relative) over its last this many
#: iterations. On the default stand the refits' last iterations only creep: over the last
#: four of ten, sensor_lag's cost moved 0.03 %, transport_delay's 0.13 %, reg_pilot_lag's
#: 0.02 % (session 64).
SCREEN_PLATEAU_ITER = 2


def screen_settings(settings: DiscoverySettings) -> FitSettings:
    """A screening refit: the pre-fit stage's settings, on the subset alone, at most
    ``settings.screen_max_iter`` iterations, stopped by IPOPT or by a cost plateau over
    :data:`SCREEN_PLATEAU_ITER` iterations (the same stop for the candidates, the
    flexible alternatives and the current fit's continuation)."""
    fit = settings.fit
    return replace(
        prefit_settings(fit),
        prefit_samples=0,
        max_iter=min(fit.max_iter, settings.screen_max_iter),
        plateau_iter=SCREEN_PLATEAU_ITER,
    )


def confirm_settings(fit: FitSettings) -> FitSettings:
    """The confirmation of a screened candidate: the fit's refinement stage on all data."""
    return replace(refine_settings(fit), prefit_samples=0)


def screening(
    current: ModelState,
    train: list[Trace],
    settings: DiscoverySettings,
    prefit: PrefitPoint | None = None,
) -> Screening | None:
    """The iteration's screening subset with the current model's residual on it, or None
    when the training data fit in ``settings.screen_samples`` (no screening stage).
    ``prefit``: the current fit's own pre-fit optimum, if known (:attr:`Screening.prefit`)."""
    budget = settings.screen_samples
    if budget is None:
        budget = settings.fit.prefit_samples
    subset = prefit_subset(train, budget)
    if len(subset) == len(train):
        return None
    fit = current.fit
    res = residual_at(current.model, current.params, tuple(fit.free), subset, settings)
    return Screening(subset, res, len(train), prefit=prefit)


def screen_refit(
    score: CandidateScore,
    current: ModelState,
    screen: Screening,
    settings: DiscoverySettings,
) -> FitResult | None:
    """Refit the candidate on the subset; fill ``score.refit`` (scope ``"screening"``) with
    its verdict against the subset reference; the fit, or None when it failed."""
    t0 = time.perf_counter()
    ref = screen.reference_for(current, settings)
    try:
        cand = current.model.with_effects(score.effect)
        free = candidate_free(tuple(current.fit.free), score.effect)
        keep = screen.residual.keep
        start = refit_start(cand, current.fit.values, score, screen.traces, settings, keep)
        fit = run_fit(
            cand,
            screen.traces,
            settings,
            free,
            start,
            fit=screen_settings(settings),
            what=f"the screening refit with {score.effect}",
        )
        res = residual_at(fit.model(), fit.params(), fit.free, screen.traces, settings)
    except _FAILURES as exc:
        score.refit = {
            "scope": "screening",
            "status": f"failed: {exc}",
            "wall_s": time.perf_counter() - t0,
        }
        return None
    verdict = judge(res, ref.kept_rss, len(free) - len(current.fit.free))
    if verdict is None:
        score.refit = {
            "scope": "screening",
            "status": "failed: non-finite residual",
            "wall_s": time.perf_counter() - t0,
        }
        return None
    score.refit = {
        "scope": "screening",
        "subset": screen.describe(),
        **verdict,
        "status": fit.status,
        "converged": bool(fit.success),
        "iterations": fit.iterations,
        "wall_s": time.perf_counter() - t0,
    }
    return fit
