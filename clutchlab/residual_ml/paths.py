"""Fast prediction along a trace: evaluate at knots, interpolate between them.

The features of a 1 kHz ramp trace move along a smooth path; a GP's prediction along it is
smooth on the scale of its length scales. So instead of evaluating every sample, the model is
evaluated at *knots* — a sample whenever the path has moved ``tol`` length scales since the
previous knot (at most ``max_gap`` samples apart) — and linearly interpolated in between.
Regime switches (latch) are handled exactly: the classifier is evaluated at the knots, every
sample between two knots of different class is classified, and each regime run gets knots at
both of its ends, so interpolation never crosses a switch. A regime flip shorter than the
knot spacing (at most ``max_gap`` samples) between two knots of the same class is not seen.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["knot_indices", "piecewise_classes", "predict_on_path"]


def knot_indices(x: np.ndarray, resolution: np.ndarray, tol: float, max_gap: int) -> np.ndarray:
    """Knot samples of a path.

    Parameters
    ----------
    x : numpy.ndarray
        n × d features along the path (feature units), in time order.
    resolution : numpy.ndarray
        d feature scales (feature units; e.g. GP length scales); a step of one resolution
        counts as path length 1.
    tol : float
        Path length between knots (dimensionless); 0 makes every sample a knot.
    max_gap : int
        Largest number of samples between knots (≥ 1).

    Returns
    -------
    numpy.ndarray
        Sorted sample indices, including the first and the last.
    """
    n = x.shape[0]
    if n <= 2 or tol <= 0 or max_gap <= 1:
        return np.arange(n)
    step = np.sqrt((((np.diff(x, axis=0)) / resolution) ** 2).sum(axis=1))
    s = np.concatenate([[0.0], np.cumsum(step)])
    cell = np.floor(s / tol)
    by_length = np.flatnonzero(np.diff(cell) != 0) + 1
    idx = np.union1d(by_length, np.arange(0, n, int(max_gap)))
    return np.union1d(idx, [0, n - 1])


def piecewise_classes(
    x: np.ndarray, knots: np.ndarray, decide: Callable[[np.ndarray], np.ndarray]
) -> np.ndarray:
    """Class (0/1) of every sample from a decision function evaluated at few samples.

    Parameters
    ----------
    x : numpy.ndarray
        n × d features along the path.
    knots : numpy.ndarray
        Knot indices (sorted, first and last included).
    decide : callable
        Maps m × d features to m decision values; class 1 where > 0.

    Returns
    -------
    numpy.ndarray
        int8 class per sample.
    """
    n = x.shape[0]
    ck = (decide(x[knots]) > 0).astype(np.int8)
    # class of each sample: that of the knot at or before it ...
    seg = np.searchsorted(knots, np.arange(n), side="right") - 1
    cls = ck[seg]
    # ... except between two knots of different class: evaluate every sample there
    change = np.flatnonzero(ck[1:] != ck[:-1])
    if change.size:
        inner = np.concatenate([np.arange(knots[c] + 1, knots[c + 1]) for c in change])
        if inner.size:
            cls[inner] = (decide(x[inner]) > 0).astype(np.int8)
    return cls


def predict_on_path(
    x: np.ndarray,
    classes: np.ndarray,
    knots: np.ndarray,
    predictors: dict[int, Callable[[np.ndarray], np.ndarray | tuple]],
    return_std: bool = False,
):
    """Per-sample prediction of a regime-switching model from knot values.

    Parameters
    ----------
    x : numpy.ndarray
        n × d features along the path.
    classes : numpy.ndarray
        Regime per sample (keys of ``predictors``).
    knots : numpy.ndarray
        Knot indices.
    predictors : dict of int to callable
        Regime → function mapping m × d features to m means (or ``(mean, std)`` when
        ``return_std``).
    return_std : bool
        Also interpolate the predictive standard deviation.

    Returns
    -------
    mean : numpy.ndarray
        n predictions.
    std : numpy.ndarray
        n standard deviations; only if ``return_std``.
    """
    n = x.shape[0]
    mean = np.empty(n)
    std = np.empty(n) if return_std else None
    bounds = np.flatnonzero(classes[1:] != classes[:-1])
    pts = np.union1d(knots, np.concatenate([bounds, bounds + 1]))
    pos = np.arange(n)
    for g, fn in predictors.items():
        mine = classes == g
        if not mine.any():
            continue
        kg = pts[classes[pts] == g]
        out = fn(x[kg])
        m, s = out if return_std else (out, None)
        mean[mine] = np.interp(pos[mine], kg, m)
        if return_std:
            std[mine] = np.interp(pos[mine], kg, s)
    return (mean, std) if return_std else mean
