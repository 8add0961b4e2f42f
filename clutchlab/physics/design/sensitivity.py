"""Sensitivity of each metric to each design variable: linear effects over the variable ranges."""

from __future__ import annotations

import numpy as np
import pandas as pd

from .evaluate import STATUS_OK
from .spec import SweepSpec

__all__ = ["sensitivity_table"]


def _unit_coordinates(spec: SweepSpec, table: pd.DataFrame) -> np.ndarray:
    """Design variables mapped to [0, 1] over their ranges (log spacing for log variables)."""
    cols = []
    for v in spec.variables:
        x = table[v.name].to_numpy(dtype=float)
        if v.scale == "log":
            cols.append((np.log(x) - np.log(v.low)) / (np.log(v.high) - np.log(v.low)))
        else:
            cols.append((x - v.low) / (v.high - v.low))
    return np.column_stack(cols) if cols else np.zeros((len(table), 0))


def sensitivity_table(
    table: pd.DataFrame, spec: SweepSpec, metrics: tuple[str, ...]
) -> pd.DataFrame:
    """Linear sensitivity of each metric to each design variable.

    Per metric, an ordinary least-squares fit ``metric ≈ b0 + Σ b_k u_k`` over the finished
    points with a finite metric, where ``u_k`` in [0, 1] is variable ``k`` over its range (log
    spaced for log variables). ``b_k`` is the change of the metric when variable ``k`` goes
    from ``low`` to ``high`` with the others fixed — the bar length of a tornado chart.

    Parameters
    ----------
    table : pandas.DataFrame
        Sweep results (:func:`read_results`).
    spec : SweepSpec
        The sweep's spec (variable ranges).
    metrics : tuple of str
        Metric columns to analyse.

    Returns
    -------
    pandas.DataFrame
        Columns ``metric``, ``variable``, ``effect`` (metric unit, low → high), ``std_coef``
        (standardized regression coefficient, -), ``r2`` (of the metric's fit, -), ``n``
        (points used); NaN effects when there are fewer points than variables + 2.
    """
    ok = table[table["status"] == STATUS_OK]
    u_all = _unit_coordinates(spec, ok)
    rows = []
    for name in metrics:
        y_all = ok[name].to_numpy(dtype=float)
        sel = np.isfinite(y_all) & np.all(np.isfinite(u_all), axis=1)
        y, u = y_all[sel], u_all[sel]
        n, k = len(y), u.shape[1]
        effect = np.full(k, np.nan)
        std = np.full(k, np.nan)
        r2 = np.nan
        if n >= k + 2 and np.ptp(y) > 0:
            a = np.column_stack([np.ones(n), u])
            coef, *_ = np.linalg.lstsq(a, y, rcond=None)
            effect = coef[1:]
            std = effect * u.std(axis=0) / y.std()
            resid = y - a @ coef
            r2 = 1.0 - float(resid @ resid) / float(((y - y.mean()) ** 2).sum())
        elif n >= k + 2:
            effect = np.zeros(k)
            std = np.zeros(k)
        for j, v in enumerate(spec.variables):
            rows.append(
                {
                    "metric": name,
                    "variable": v.name,
                    "effect": float(effect[j]),
                    "std_coef": float(std[j]),
                    "r2": float(r2),
                    "n": int(n),
                }
            )
    return pd.DataFrame(rows, columns=["metric", "variable", "effect", "std_coef", "r2", "n"])
