"""The two stages of a fit on long data: a pre-fit on a ramp-balanced subset, then a short
refinement on every experiment.

The pre-fit subset is also what effect discovery screens its candidate refits on
(:mod:`clutchlab.validation.discover`), so both use :func:`prefit_subset` and the same stage
settings.
"""

from __future__ import annotations

from dataclasses import replace

from ...data import Trace
from .settings import FitSettings

__all__ = ["prefit_settings", "prefit_subset", "refine_settings"]


def prefit_subset(traces: list[Trace], budget: int) -> list[Trace]:
    """Experiments of the pre-fit: round-robin over the ramp labels, shortest first.

    Every ramp rate is represented (its shortest experiment at least); the others are added
    while the sample budget lasts. All of ``traces`` when they fit in the budget (or when
    ``budget`` is 0).

    Parameters
    ----------
    traces : list of Trace
        Training experiments.
    budget : int
        Largest number of samples of the subset (each ramp's first experiment is taken even
        when it alone exceeds it).

    Returns
    -------
    list of Trace
        In pick order.
    """
    total = sum(len(t) for t in traces)
    if not budget or total <= budget:
        return list(traces)
    by_ramp: dict = {}
    for t in sorted(traces, key=len):
        by_ramp.setdefault(t.ramp, []).append(t)
    subset, used = [], 0
    while any(by_ramp.values()):
        for queue in by_ramp.values():
            if queue and (
                used + len(queue[0]) <= budget
                or not subset
                or all(x.ramp != queue[0].ramp for x in subset)
            ):
                t = queue.pop(0)
                subset.append(t)
                used += len(t)
            elif queue:
                queue.pop(0)
    return subset


def prefit_settings(settings: FitSettings) -> FitSettings:
    """Settings of the pre-fit stage: IPOPT stops at an acceptable level once the cost
    changes by less than ``prefit_obj_change_tol`` (the user's IPOPT options win), and on a
    cost plateau (``prefit_plateau_iter`` iterations that moved the cost by less than that)."""
    return replace(
        settings,
        plateau_iter=settings.prefit_plateau_iter,
        ipopt_options={
            "acceptable_obj_change_tol": settings.prefit_obj_change_tol,
            "acceptable_tol": 0.1,
            "acceptable_iter": 2,
            **settings.ipopt_options,
        },
    )


def refine_settings(settings: FitSettings) -> FitSettings:
    """Settings of the refinement: at most ``refine_max_iter`` iterations from the pre-fit's
    optimum, kept where it is (possibly on a bound: no push into the interior) and started
    with a small barrier parameter."""
    return replace(
        settings,
        max_iter=settings.refine_max_iter,
        multistart=0,
        ipopt_options={
            "bound_push": 1e-8,
            "bound_frac": 1e-8,
            "mu_init": 1e-6,
            **settings.ipopt_options,
        },
    )
