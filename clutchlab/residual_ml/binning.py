"""Grid binning: many redundant 1 kHz samples → few weighted bin means.

A ramp logged at 1 kHz moves by a fraction of a milliampere per sample, so neighbouring
samples carry almost the same information. Binning replaces all samples that fall into one
cell of a regular grid over the inputs by their weighted mean input, weighted mean target and
total weight; a GP then treats the bin mean as one observation whose noise variance is the
per-sample variance divided by the total weight (the number of independent observations in
it). With cells small against the kernel's length scales this loses no accuracy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

__all__ = ["Bins", "grid_bins"]


@dataclass(frozen=True)
class Bins:
    """Weighted bin means of a sample set.

    Attributes
    ----------
    x : numpy.ndarray
        m × d weighted mean inputs (units of the inputs).
    y : numpy.ndarray
        m weighted mean targets (unit of the target), or an empty array without targets.
    weight : numpy.ndarray
        m total weights (effective number of independent observations).
    count : numpy.ndarray
        m numbers of samples.
    label : numpy.ndarray
        m integer labels (all 0 when binned without labels).
    index : numpy.ndarray
        n bin index of every input sample (−1 for samples of zero weight).
    """

    x: np.ndarray
    y: np.ndarray
    weight: np.ndarray
    count: np.ndarray
    label: np.ndarray
    index: np.ndarray

    def __len__(self) -> int:
        return int(self.weight.size)

    def subset(self, keep: np.ndarray) -> Bins:
        """The bins selected by a boolean mask or index array (``index`` is not remapped)."""
        return Bins(
            self.x[keep],
            self.y[keep] if self.y.size else self.y,
            self.weight[keep],
            self.count[keep],
            self.label[keep],
            self.index,
        )


def _sorted_codes(values: np.ndarray) -> np.ndarray:
    """``np.unique(values, return_inverse=True)[1]`` (int64), by hashing: pandas'
    factorization with sorted codes gives the same codes without sorting all ~10⁶ values
    (only the distinct ones), several times faster on a training set's samples."""
    return pd.factorize(np.asarray(values), sort=True)[0].astype(np.int64)


def _codes(column: np.ndarray, width: float) -> np.ndarray:
    """Integer grid cell of every value (exact-value classes when ``width`` is 0)."""
    if width > 0:
        k = np.floor(column / width)
        return (k - k.min()).astype(np.int64)
    return _sorted_codes(column)


def grid_bins(
    x: np.ndarray,
    y: np.ndarray | None,
    weight: np.ndarray | None,
    width: float | np.ndarray,
    labels: np.ndarray | None = None,
) -> Bins:
    """Bin samples on a regular grid; samples with different labels never share a bin.

    Parameters
    ----------
    x : numpy.ndarray
        n × d inputs (any units; ``width`` in the same units per column).
    y : numpy.ndarray or None
        n targets (any unit), or None to bin inputs only.
    weight : numpy.ndarray or None
        n non-negative sample weights (effective observations; default 1 each). Samples of
        weight 0 are left out.
    width : float or numpy.ndarray
        Cell width per input column, in the column's units; 0 groups identical values only.
    labels : numpy.ndarray, optional
        n integer labels (e.g. latch state); default all 0.

    Returns
    -------
    Bins
        Bins ordered by grid cell.

    Raises
    ------
    ValueError
        If shapes disagree, a width is negative or not finite, or a weight is negative.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2:
        raise ValueError(f"x must be 2-D, got shape {x.shape}")
    n, d = x.shape
    w = np.ones(n) if weight is None else np.asarray(weight, dtype=np.float64)
    if w.shape != (n,):
        raise ValueError(f"weight must have shape ({n},), got {w.shape}")
    if (w < 0).any() or not np.isfinite(w).all():
        raise ValueError("sample weights must be finite and non-negative")
    width = np.broadcast_to(np.asarray(width, dtype=np.float64), (d,))
    if (width < 0).any() or not np.isfinite(width).all():
        raise ValueError(f"bin widths must be finite and >= 0, got {width}")
    lab = np.zeros(n, dtype=np.int64) if labels is None else np.asarray(labels, dtype=np.int64)
    if lab.shape != (n,):
        raise ValueError(f"labels must have shape ({n},), got {lab.shape}")
    use = w > 0
    index = np.full(n, -1, dtype=np.int64)
    if not use.any():
        empty = np.zeros((0, d))
        z = np.zeros(0)
        return Bins(empty, z, z, z.astype(np.int64), z.astype(np.int64), index)
    xs, ws, ls = x[use], w[use], lab[use]
    cols = [_codes(xs[:, j], float(width[j])) for j in range(d)]
    cols.append(_sorted_codes(ls))
    spans = [int(c.max()) + 1 for c in cols]
    if float(np.prod(np.asarray(spans, dtype=np.float64))) < 2.0**62:
        key = np.zeros(xs.shape[0], dtype=np.int64)
        for c, s in zip(cols, spans, strict=True):
            key = key * s + c
        inv = _sorted_codes(key)
    else:  # too many cells for one int64 key: the lexicographic rank of the code rows,
        # built column by column (each partial key is re-coded to its sorted rank, < n, so
        # the next product stays small): the same cells in the same order as
        # np.unique(rows, axis=0), without its lexicographic sort of n rows
        inv = cols[0]
        for c, s in zip(cols[1:], spans[1:], strict=True):
            inv = _sorted_codes(inv * s + c)
    inv = inv.ravel()
    m = int(inv.max()) + 1
    wsum = np.bincount(inv, weights=ws, minlength=m)
    xm = np.empty((m, d))
    for j in range(d):
        xm[:, j] = np.bincount(inv, weights=ws * xs[:, j], minlength=m) / wsum
    if y is not None:
        ys = np.asarray(y, dtype=np.float64)
        if ys.shape != (n,):
            raise ValueError(f"y must have shape ({n},), got {ys.shape}")
        ym = np.bincount(inv, weights=ws * ys[use], minlength=m) / wsum
    else:
        ym = np.zeros(0)
    count = np.bincount(inv, minlength=m).astype(np.int64)
    label = np.zeros(m, dtype=np.int64)
    label[inv] = ls
    index[use] = inv
    return Bins(xm, ym, wsum, count, label, index)
