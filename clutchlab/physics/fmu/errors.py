"""Exceptions of FMU export and import."""

from __future__ import annotations

from ...errors import ProblemListError, SimulationError

__all__ = ["FmuError", "FmuTimeoutError"]


class FmuError(ProblemListError, ValueError):
    """An FMU that cannot be used or built: not an FMU, wrong FMI version or type, an
    interface that does not fit the data, a failed compilation.

    Parameters
    ----------
    message : str
        Summary line naming the FMU.
    problems : list of str, optional
        Every problem found, one per line.
    """


class FmuTimeoutError(SimulationError, TimeoutError):
    """An FMU simulation exceeded its wall-time limit."""
