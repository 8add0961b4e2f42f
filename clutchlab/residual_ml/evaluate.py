"""Scores of a fitted model on traces (DESIGN §5 metric names), and leave-one-experiment-out."""

from __future__ import annotations

import time
from collections.abc import Iterable

import numpy as np
from sklearn.base import clone
from tqdm.auto import tqdm

from ..data import Trace, dither_period_mean, dither_period_samples, pressure_metrics
from .estimators import mean_only

__all__ = ["leave_one_experiment_out", "score_traces"]


def score_traces(model, traces: Iterable[Trace]) -> dict:
    """Metrics of ``model`` on ``traces``: dither-period mean (primary) and raw (secondary).

    Parameters
    ----------
    model : TraceEstimator
        Fitted estimator.
    traces : iterable of Trace
        Experiments to score.

    Returns
    -------
    dict
        ``{"overall": {metric: value}, "overall_raw": {...}, "per_experiment": {name:
        {metric: value}}, "predict_s": float}`` with metrics ``rmse_bar``, ``mae_bar``,
        ``max_abs_bar``, ``fit_pct`` (all in bar except fit %), computed on the
        dither-period means of measured and predicted pressure (``_raw``: on raw samples).
    """
    ys, ps, yr, pr = [], [], [], []
    per: dict[str, dict] = {}
    t0 = time.perf_counter()
    for t in traces:
        pred = np.asarray(model.predict(t), dtype=float)
        n = dither_period_samples(t)
        y = dither_period_mean(t.get("clutch_pressure_bar"), n)
        p = dither_period_mean(pred, n)
        per[t.name] = pressure_metrics(y, p)
        ys.append(y)
        ps.append(p)
        yr.append(np.asarray(t.get("clutch_pressure_bar")))
        pr.append(pred)
    wall = time.perf_counter() - t0
    if not ys:
        return {"overall": {}, "overall_raw": {}, "per_experiment": {}, "predict_s": wall}
    return {
        "overall": pressure_metrics(np.concatenate(ys), np.concatenate(ps)),
        "overall_raw": pressure_metrics(np.concatenate(yr), np.concatenate(pr)),
        "per_experiment": per,
        "predict_s": wall,
    }


def leave_one_experiment_out(
    model, traces: list[Trace], progress: bool = False
) -> dict[str, dict[str, float]]:
    """Leave-one-experiment-out scores of an (unfitted) estimator on training traces.

    Each experiment is predicted by a clone of ``model`` fitted on all the others; use it for
    model choices inside the training set (never on the test ramp).

    Returns
    -------
    dict
        Experiment name → metrics of its dither-period-mean pressure (bar).
    """
    out = {}
    for k in tqdm(range(len(traces)), desc="LOEO", disable=not progress):
        m = mean_only(clone(model)).fit([t for i, t in enumerate(traces) if i != k])
        out[traces[k].name] = score_traces(m, [traces[k]])["overall"]
    return out
