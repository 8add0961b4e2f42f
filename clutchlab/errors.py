"""Domain exceptions shared by every layer.

They subclass the built-in exceptions so callers can catch either the specific
clutchlab error or the generic Python one.
"""

from __future__ import annotations

__all__ = ["ClutchlabError", "DataError", "FitError", "ModelError", "SimulationError"]


class ClutchlabError(Exception):
    """Base class of every clutchlab exception."""


class DataError(ClutchlabError, ValueError):
    """Bad input data: a file, column or row that breaks the data contract.

    Parameters
    ----------
    message : str
        Summary line.
    problems : list of str, optional
        Every problem found, each naming file, column and row where known.
    """

    def __init__(self, message: str, problems: list[str] | None = None) -> None:
        self.problems = list(problems or [])
        text = message
        if self.problems:
            text += "\n" + "\n".join(f"  - {p}" for p in self.problems)
        super().__init__(text)


class ModelError(ClutchlabError, ValueError):
    """Bad model specification: unknown effect or parameter, value out of bounds."""


class SimulationError(ClutchlabError, RuntimeError):
    """The integrator failed (non-finite state, diverging solution)."""


class FitError(ClutchlabError, RuntimeError):
    """A parameter fit failed; carries the best iterate when there is one."""
