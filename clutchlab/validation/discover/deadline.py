"""The wall-time budget of a whole discovery (``DiscoverySettings.time_limit_s``).

A discovery is a baseline fit followed by candidate and flexible-law refits, each with the
fit's own time limit. The discovery's budget bounds their sum: every refit starts only
while budget is left, its fit's time limit is what is left at most, and a refit that the
budget (not its own limit) stopped is **not judged** — a refit cut short would be compared
with complete ones, and a candidate could then "beat" a flexible law merely because the
law's refit ran out of time. The discovery ends with the model it had (the effects it added
in earlier iterations stay: each was confirmed in full) and says it stopped at its budget.

The baseline fit is capped the same way but is never discarded: stopped at a limit, its best
iterate is the model, as in ``fit-physics``.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
import time
from collections.abc import Iterator
from dataclasses import replace

from ...physics.fit import FitResult, FitSettings
from ...physics.fit.fitter import SOLVER_TIME_FRACTION
from ...physics.fit.nlp import WALL_TIME_LIMIT

__all__ = [
    "DiscoveryTimeLimit",
    "budget_spent",
    "capped_fit",
    "check_budget",
    "cut_by_budget",
    "discovery_budget",
]


class DiscoveryTimeLimit(Exception):
    """The discovery's wall-time budget is spent (raised inside it, caught by its loop).

    Not a :class:`~clutchlab.errors.ClutchlabError`: the refits record those as a failed
    candidate, which this is not.

    Parameters
    ----------
    before : str
        The step that did not run (or was cut short), e.g. ``"the refit with sensor_lag"``.
    limit_s : float
        The budget (s).
    """

    def __init__(self, before: str, limit_s: float) -> None:
        super().__init__(f"the discovery's time budget ({limit_s:.3g} s) was spent before {before}")
        self.before = before
        self.limit_s = limit_s


#: (deadline on ``time.perf_counter``, budget in s) of the running discovery; None: no budget.
_BUDGET: contextvars.ContextVar[tuple[float, float] | None] = contextvars.ContextVar(
    "clutchlab_discovery_budget", default=None
)


@contextlib.contextmanager
def discovery_budget(limit_s: float | None, t_start: float) -> Iterator[None]:
    """Within this block, refits respect a budget of ``limit_s`` seconds from ``t_start``.

    Parameters
    ----------
    limit_s : float or None
        Wall-time budget of the discovery (s); None: none.
    t_start : float
        Its start on ``time.perf_counter`` (s).
    """
    token = _BUDGET.set(None if limit_s is None else (t_start + limit_s, limit_s))
    try:
        yield
    finally:
        _BUDGET.reset(token)


def _left() -> tuple[float, float] | None:
    """(seconds left, budget) of the running discovery, or None without a budget."""
    budget = _BUDGET.get()
    if budget is None:
        return None
    deadline, limit_s = budget
    return deadline - time.perf_counter(), limit_s


def check_budget(before: str) -> None:
    """Raise :class:`DiscoveryTimeLimit` when the budget is spent.

    Parameters
    ----------
    before : str
        The step about to run (in the message).
    """
    left = _left()
    if left is not None and left[0] <= 0:
        raise budget_spent(before)


def budget_spent(before: str) -> DiscoveryTimeLimit:
    """The :class:`DiscoveryTimeLimit` of the running discovery's budget, before ``before``.

    Parameters
    ----------
    before : str
        The step that did not run, or was cut short.

    Returns
    -------
    DiscoveryTimeLimit
        Naming the running budget (s); raised by the caller.
    """
    budget = _BUDGET.get()
    return DiscoveryTimeLimit(before, math.nan if budget is None else budget[1])


def capped_fit(fit: FitSettings) -> tuple[FitSettings, bool]:
    """``fit`` with its time limit at most the budget left; whether the budget binds.

    Parameters
    ----------
    fit : FitSettings
        A refit's settings.

    Returns
    -------
    FitSettings
        The same settings, ``time_limit_s`` lowered to the seconds left when fewer.
    bool
        Whether the budget, not the fit's own limit, bounds the fit.
    """
    left = _left()
    if left is None or not left[0] < fit.time_limit_s:
        return fit, False
    return replace(fit, time_limit_s=max(left[0], 1e-3)), True


def cut_by_budget(fit: FitSettings, capped: bool, result: FitResult | None, wall_s: float) -> bool:
    """Whether a fit run with ``fit`` (from :func:`capped_fit`) was stopped by the budget.

    Parameters
    ----------
    fit : FitSettings
        The settings it ran with.
    capped : bool
        Whether the budget bound its time limit.
    result : FitResult or None
        Its result (None: it raised without one).
    wall_s : float
        Its wall time (s).

    Returns
    -------
    bool
        Capped, not converged, and either stopped at its wall-time limit or out of time
        before its first stage ended (the fitter's solver stops at
        ``SOLVER_TIME_FRACTION`` of the limit).
    """
    if not capped or (result is not None and result.success):
        return False
    at_limit = result is not None and WALL_TIME_LIMIT in result.status
    return at_limit or wall_s >= SOLVER_TIME_FRACTION * fit.time_limit_s
