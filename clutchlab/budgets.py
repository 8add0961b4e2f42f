"""Performance budgets of DESIGN §7 that the code takes as defaults.

A constants-only module (no imports), so the command-line parser can read them without
loading the numerical stack.
"""

from __future__ import annotations

__all__ = ["DEMO_BUDGET_S", "FIT_BUDGET_S"]

#: The physics fit's budget (s, wall, 2 cores): the time limit of ``fit-physics``, of
#: ``evaluate``'s physics fit and of the demo's. A fit stopped by it keeps its best iterate.
FIT_BUDGET_S = 120.0

#: The demo's budget (s, wall, 2 cores; DESIGN §7: 10 minutes from a fresh install): the
#: default of ``clutchlab demo --budget`` (see :data:`clutchlab.validation.DEMO_BUDGET_S`).
DEMO_BUDGET_S = 600.0
