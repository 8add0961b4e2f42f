"""Exceptions of FMU export and import."""

from __future__ import annotations

from ...errors import ClutchlabError, SimulationError

__all__ = ["FmuError", "FmuTimeoutError"]


class FmuError(ClutchlabError, ValueError):
    """An FMU that cannot be used or built: not an FMU, wrong FMI version or type, an
    interface that does not fit the data, a failed compilation.

    Parameters
    ----------
    message : str
        Summary line naming the FMU.
    problems : list of str, optional
        Every problem found, one per line.
    """

    def __init__(self, message: str, problems: list[str] | None = None) -> None:
        self.problems = list(problems or [])
        text = message
        if self.problems:
            text += "\n" + "\n".join(f"  - {p}" for p in self.problems)
        super().__init__(text)


class FmuTimeoutError(SimulationError, TimeoutError):
    """An FMU simulation exceeded its wall-time limit."""
