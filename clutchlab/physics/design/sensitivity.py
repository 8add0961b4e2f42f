"""Sensitivity of each metric to each design variable: linear effects over the variable ranges."""

from __future__ import annotations

import numpy as np
import pandas as pd

from .evaluate import STATUS_OK
from .spec import SweepSpec

__all__ = ["sensitivity_table"]


def _unit_coordinates(spec: SweepSpec, table: pd.DataFrame) -> np.ndarray:
    """Design variables mapped to [0, 1] over their ranges (log spacing for log variables).

    A variable with one level (``low == high``, e.g. ``values = [12.0]``) has no range: its
    column is NaN (nothing to divide by) and :func:`sensitivity_table` leaves it out.
    """
    cols = []
    for v in spec.variables:
        x = table[v.name].to_numpy(dtype=float)
        if not v.high > v.low:
            cols.append(np.full(len(x), np.nan))
        elif v.scale == "log":
            with np.errstate(divide="ignore", invalid="ignore"):  # x ≤ 0 gives NaN, dropped
                cols.append((np.log(x) - np.log(v.low)) / (np.log(v.high) - np.log(v.low)))
        else:
            cols.append((x - v.low) / (v.high - v.low))
    return np.column_stack(cols) if cols else np.zeros((len(table), 0))


#: ``note`` of a variable with one level: its effect is undefined, not zero.
ONE_LEVEL_NOTE = "one level ({value:g}): no range, effect undefined"


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
        (points used), ``note`` (why an effect is NaN, else empty). Effects are NaN when there
        are fewer points than fitted variables + 2, and for a variable with one level
        (``values = [x]``): it has no range, so it is left out of the fit and its effect is
        undefined; the other variables are fitted without it.
    """
    ok = table[table["status"] == STATUS_OK]
    u_all = _unit_coordinates(spec, ok)
    ranged = np.array([v.high > v.low for v in spec.variables], dtype=bool)
    rows = []
    for name in metrics:
        y_all = ok[name].to_numpy(dtype=float)
        sel = np.isfinite(y_all) & np.all(np.isfinite(u_all[:, ranged]), axis=1)
        y, u = y_all[sel], u_all[sel][:, ranged]
        n, k = len(y), u.shape[1]
        effect = np.full(len(spec.variables), np.nan)
        std = np.full(len(spec.variables), np.nan)
        r2 = np.nan
        if n >= k + 2 and np.ptp(y) > 0:
            a = np.column_stack([np.ones(n), u])
            coef, *_ = np.linalg.lstsq(a, y, rcond=None)
            effect[ranged] = coef[1:]
            std[ranged] = coef[1:] * u.std(axis=0) / y.std()
            resid = y - a @ coef
            r2 = 1.0 - float(resid @ resid) / float(((y - y.mean()) ** 2).sum())
        elif n >= k + 2:
            effect[ranged] = 0.0
            std[ranged] = 0.0
        too_few = f"{n} finite points, {k + 2} needed"
        for j, v in enumerate(spec.variables):
            if not ranged[j]:
                note = ONE_LEVEL_NOTE.format(value=v.low)
            else:
                note = "" if np.isfinite(effect[j]) else too_few
            rows.append(
                {
                    "metric": name,
                    "variable": v.name,
                    "effect": float(effect[j]),
                    "std_coef": float(std[j]),
                    "r2": float(r2),
                    "n": int(n),
                    "note": note,
                }
            )
    return pd.DataFrame(
        rows, columns=["metric", "variable", "effect", "std_coef", "r2", "n", "note"]
    )


def tornado_labels(sens: pd.DataFrame) -> tuple[list[str], str]:
    """Bar labels of one metric's rows of :func:`sensitivity_table`, and the panel's message.

    A one-level variable is labelled ``name (one level)``; the message (empty when some
    effect is finite) says why a panel has no bars.
    """
    one = sens["note"].str.startswith("one level")
    labels = [
        f"{v} (one level)" if o else str(v) for v, o in zip(sens["variable"], one, strict=True)
    ]
    if sens["effect"].notna().any():
        return labels, ""
    if len(sens) and one.all():
        return labels, "one level per variable: no range, no effect"
    return labels, "too few finite points"
