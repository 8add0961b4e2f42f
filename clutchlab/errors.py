"""Domain exceptions shared by every layer.

They subclass the built-in exceptions so callers can catch either the specific
clutchlab error or the generic Python one.
"""

from __future__ import annotations

import os
import sys
import warnings

__all__ = [
    "ClutchlabError",
    "DataError",
    "FitError",
    "FitResultError",
    "FitWarning",
    "ModelError",
    "ModelFileError",
    "OutputError",
    "ParameterWarning",
    "ProblemListError",
    "SimulationError",
    "SimulationWarning",
    "warn_at_caller",
]


class ClutchlabError(Exception):
    """Base class of every clutchlab exception."""


class ProblemListError(ClutchlabError):
    """A clutchlab error that lists every problem found, one per line after the summary.

    Parameters
    ----------
    message : str
        Summary line.
    problems : list of str, optional
        Every problem found.
    """

    def __init__(self, message: str, problems: list[str] | None = None) -> None:
        self.problems = list(problems or [])
        text = message
        if self.problems:
            text += "\n" + "\n".join(f"  - {p}" for p in self.problems)
        super().__init__(text)


class DataError(ProblemListError, ValueError):
    """Bad input data: a file, column or row that breaks the data contract.

    Parameters
    ----------
    message : str
        Summary line.
    problems : list of str, optional
        Every problem found, each naming file, column and row where known.
    """


class ModelError(ClutchlabError, ValueError):
    """Bad model specification: unknown effect or parameter, value out of bounds."""


class OutputError(ClutchlabError, OSError):
    """An output that may not or cannot be written: it exists, is in the way of a file
    clutchlab did not write, or lies in a folder that cannot be written."""


class ModelFileError(ProblemListError, ModelError):
    """A saved model or fit result whose content is not valid, with every problem found.

    Parameters
    ----------
    message : str
        Summary line naming the file.
    problems : list of str, optional
        Every problem found, each naming the key (``state.gps.0.y_scale``) or the array
        (``array 'gp0.x_scale' in m.npz``).
    """


class SimulationError(ClutchlabError, RuntimeError):
    """The integrator failed (non-finite state, diverging solution)."""


class FitError(ClutchlabError, RuntimeError):
    """A parameter fit failed; carries the best iterate when there is one."""


class FitResultError(ModelFileError, FitError):
    """A fit-result file whose content is not valid (unknown effect or parameter, a value
    not finite or outside its bounds, a missing key): every problem listed; both a
    :class:`ModelError` and a :class:`FitError`.

    Parameters
    ----------
    message : str
        Summary line naming the file.
    problems : list of str, optional
        Every problem found, each naming its key.
    """


class FitWarning(UserWarning):
    """A fit returned its best iterate without converging (stopped at a limit)."""


class SimulationWarning(UserWarning):
    """A simulation finished, but a pressure left the range the circuit can reach: the
    integration step was too long for the parameters' dynamics, or the design is unstable."""


class ParameterWarning(UserWarning):
    """Values accepted that do not do what they say: a parameter set within its bounds that
    defeats what a component is for (a latch valve whose areas and spring leave it no snap
    action, so it cannot latch), or an estimator option the fitted model does not use."""


_PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__))


def warn_at_caller(message: str, category: type[Warning]) -> None:
    """``warnings.warn`` attributed to the first frame outside clutchlab: the user's line.

    Parameters
    ----------
    message : str
        The warning's text.
    category : type of Warning
        Its class.
    """
    level, frame = 1, sys._getframe(1)
    while frame is not None and _inside(frame.f_code):
        frame, level = frame.f_back, level + 1
    warnings.warn(message, category, stacklevel=level + 1)


def _inside(code) -> bool:
    """A frame of clutchlab's, or the ``__init__`` a dataclass generates (``<string>``)."""
    name = code.co_filename
    return name.startswith(_PACKAGE_DIR) or (name == "<string>" and code.co_name == "__init__")
