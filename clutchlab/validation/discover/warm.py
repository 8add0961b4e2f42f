"""Compile the sensitivity code once, in this process, before worker processes fork.

The fit problem evaluates experiments in forked workers; each compiles the model's
sensitivity code on first use, so a new model (a candidate effect switched on) would
be compiled by every worker at once. Compiling it here first leaves one cached
library on disk that the workers only load.
"""

from __future__ import annotations

from ...data import Trace
from ...physics import CircuitModel
from ...physics.fit import FitSettings, compile_sensitivities_for

__all__ = ["warm_sensitivities"]


def warm_sensitivities(
    model: CircuitModel,
    traces: list[Trace],
    fit: FitSettings,
    nd: int,
    background: bool = False,
) -> None:
    """:func:`clutchlab.physics.fit.compile_sensitivities_for` with the substeps and drive
    of the fit settings ``fit`` (same parameters otherwise)."""
    compile_sensitivities_for(model, traces, fit.substeps, fit.drive, nd, background)
