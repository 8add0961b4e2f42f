"""What a fit or a prediction was given: experiments (traces) or something else.

:func:`as_traces` turns a :class:`~clutchlab.data.Trace`, a :class:`~clutchlab.data.Dataset`
or a sequence of traces into a list of traces, and refuses the inputs a user easily passes
by mistake (a path, an empty list, a list mixing traces and other objects) with the way to
load them. The physics fit and the ML estimators read their experiments through it.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

from ..errors import DataError
from .dataset import Dataset
from .trace import Trace

__all__ = ["as_traces"]

_WHAT = "experiments (a Trace, a Dataset or a list of Traces)"


def as_traces(X, role: str = "", *, arrays: bool = True) -> list[Trace] | None:
    """The traces in ``X`` (Trace, Dataset or sequence of Traces).

    Parameters
    ----------
    X : Trace, Dataset, sequence of Trace, or array_like
        The input.
    role : str
        What the experiments are for, in the error message (``"training"``: "no training
        experiments").
    arrays : bool
        Whether a feature matrix is a valid input too (the ML estimators' ``fit(X, y)``):
        then anything that is not experiments gives None; otherwise it is refused.

    Returns
    -------
    list of Trace, or None
        None for array input when ``arrays``.

    Raises
    ------
    DataError
        If ``X`` is an empty dataset, an empty list or tuple, a sequence mixing traces
        and other objects, or a path (a str or os.PathLike); without ``arrays`` also if it
        is not experiments at all.
    """
    what = f"{_WHAT} or a feature matrix" if arrays else _WHAT
    if isinstance(X, Trace):
        return [X]
    if isinstance(X, str | os.PathLike):
        raise DataError(
            f"expected {what}, not a path ({str(X)!r}): load it first, "
            "clutchlab.data.load_dataset(path)"
        )
    if isinstance(X, Dataset):
        traces = list(X)
    elif isinstance(X, list | tuple) and not X:
        traces = []  # no experiments (an empty feature matrix is an array, not a list)
    elif (
        isinstance(X, Sequence)
        and not isinstance(X, str)
        and (not arrays or any(isinstance(t, Trace) for t in X))
    ):
        traces = list(X)
        bad = [type(t).__name__ for t in traces if not isinstance(t, Trace)]
        if bad:
            raise DataError(f"expected only Traces, got also {', '.join(sorted(set(bad)))}")
    elif arrays:
        return None
    else:
        raise DataError(f"expected {what}, not {type(X).__name__}")
    if not traces:
        none = f"{role} experiments" if role else "experiments"
        raise DataError(f"no {none} (an empty dataset or list was given)")
    return traces
