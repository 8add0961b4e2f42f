"""Compile the sensitivity code once, in this process, before worker processes fork.

The fit problem evaluates experiments in forked workers; each compiles the model's
sensitivity code on first use, so a new model (a candidate effect switched on) would
be compiled by every worker at once. Compiling it here first leaves one cached
library on disk that the workers only load.
"""

from __future__ import annotations

from ...data import Trace
from ...physics import CircuitModel
from ...physics.fit import (
    SENSITIVITY_CHUNK,
    FitSettings,
    compile_sensitivities_in_background,
    sensitivity_chunk,
)
from ...physics.inputs import choose_drive
from ...physics.settings import SimulationSettings

__all__ = ["warm_sensitivities"]


def warm_sensitivities(
    model: CircuitModel,
    traces: list[Trace],
    fit: FitSettings,
    nd: int,
    background: bool = False,
) -> None:
    """Compile (or load from the cache) ``model``'s sensitivity code for ``nd`` directions.

    Parameters
    ----------
    model : CircuitModel
        Model structure.
    traces : list of Trace
        Experiments (their drive mode decides which code is needed).
    fit : FitSettings
        Substeps and drive of the fit.
    nd : int
        Number of sensitivity directions (free parameters, single shooting).
    background : bool
        Only start compiling what is not cached (on another core, while this process
        works on) and return at once; the later foreground call waits for it.
    """
    sim = SimulationSettings(substeps=fit.substeps, drive=fit.drive)
    for drive in sorted({choose_drive(t, sim) for t in traces}):
        if background:
            compile_sensitivities_in_background(model, drive, fit.substeps, nd, SENSITIVITY_CHUNK)
        else:
            sensitivity_chunk(model, drive, fit.substeps, nd, SENSITIVITY_CHUNK)
