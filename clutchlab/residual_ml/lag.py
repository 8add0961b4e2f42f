"""Choosing the time constant of the lagged-current feature by leave-one-ramp-rate-out.

Why a lagged current: the circuit trails the command (accumulator filling, spool and latch
travel), so on a ramp of rate ``r`` the pressure at current ``I`` is roughly the static
pressure at ``I − τ r``. A GP on (I, dI/dt) has to learn that oblique dependence from the
ramp rates it was trained on, and between two training rates it *blends* their curves
(e.g. two half-height latch steps at the two rates' latch currents) instead of *moving* one
curve. On the lagged current ``current_lag_mA`` (:func:`clutchlab.data.first_order_lag`) the
curves of all ramp rates fall onto one, and a new rate is an interpolation in the other
features only.

τ is a property of the hardware, so it is chosen from the training data: for each candidate
τ, each ramp rate of the training set (the ``ramp`` label of its experiments) is predicted
from the *other* rates, and the τ with the smallest pooled RMSE of the dither-period-mean
pressure wins. This is leave-one-experiment-out with the experiments of one ramp rate left
out together (a held-out fast experiment would otherwise be predicted from the other fast
experiments, which says nothing about τ). The test ramp is never used.

The predictor of the held-out rate is a k-nearest-neighbour average on the standardized
features without the rate itself (dI/dt, which is never shared between ramp rates): a
model-free test of "do the curves of the ramp rates coincide on the lagged current". A GP
in its place gave the same optimum on the default stand (0.2 s) but a rugged score curve
(its hyperparameters change with τ) at ten times the cost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..data import Trace, first_order_lag
from .features import FeatureBuilder, target_pressure

__all__ = ["LAG_GRID_S", "LagSelection", "select_lag"]

#: Candidate time constants, s (then refined by a factor √2 either side of the best).
LAG_GRID_S: tuple[float, ...] = (0.0, 0.025, 0.05, 0.1, 0.2, 0.4, 0.8)


@dataclass(frozen=True)
class LagSelection:
    """Outcome of :func:`select_lag`.

    Attributes
    ----------
    lag_s : float
        Chosen time constant, s.
    scores : dict of float to float
        Candidate τ (s) → pooled leave-one-ramp-rate-out RMSE (bar).
    groups : tuple of str
        Ramp rates (labels) that were left out in turn.
    reason : str
        How the value was obtained (e.g. "fewer than two ramp rates: no lag").
    """

    lag_s: float
    scores: dict[float, float] = field(default_factory=dict)
    groups: tuple[str, ...] = ()
    reason: str = ""


def _group(trace: Trace) -> str | None:
    return trace.ramp or None


#: Features left out of the scoring predictor: the ramp rate, never shared between groups.
_RATE_FEATURES = ("didt_mA_s", "didt_causal_mA_s")


def select_lag(
    traces: list[Trace],
    builder: FeatureBuilder,
    *,
    grid: tuple[float, ...] = LAG_GRID_S,
    n_neighbors: int = 20,
    max_rows: int = 50_000,
) -> LagSelection:
    """Time constant of ``current_lag_mA`` by leave-one-ramp-rate-out on training traces.

    Parameters
    ----------
    traces : list of Trace
        Training experiments; their ``ramp`` labels define the groups left out in turn.
    builder : FeatureBuilder
        The estimator's features (must contain ``current_lag_mA``; its ``lag_s`` is ignored).
    grid : tuple of float
        Candidate τ, s (≥ 0); the best interior one is refined by √2 either side.
    n_neighbors : int
        Neighbours averaged by the scoring predictor (default 20).
    max_rows : int
        Samples are decimated evenly to at most about this many rows (the dither-period-mean
        target is smooth over a period, so 1 kHz samples are highly redundant).

    Returns
    -------
    LagSelection
        The chosen τ and every candidate's score; τ = 0 when the traces hold fewer than two
        ramp rates (τ is then not identifiable from the data).
    """
    from sklearn.neighbors import KNeighborsRegressor

    groups = sorted({g for t in traces if (g := _group(t)) is not None})
    if len(groups) < 2:
        return LagSelection(0.0, {}, tuple(groups), "fewer than two ramp rates: no lag")
    names = [f for f in builder.features if f not in _RATE_FEATURES]
    extra = () if "current_mA" in names else ("current_mA",)
    full = FeatureBuilder((*names, *extra), builder.didt_periods, builder.deadband_mA_s)
    j_lag = names.index("current_lag_mA")
    j_cur = (names + list(extra)).index("current_mA")
    stride = max(1, sum(len(t) for t in traces) // max_rows)
    mats = [full.build(t) for t in traces]
    ys = [target_pressure(t)[::stride] for t in traces]
    member = [_group(t) for t in traces]

    def score(tau: float) -> float:
        Xs = []
        for t, M in zip(traces, mats, strict=True):
            X = M[::stride, : len(names)].copy()
            X[:, j_lag] = first_order_lag(M[:, j_cur], tau, t.sample_rate_Hz)[::stride]
            Xs.append(X)
        sse, n = 0.0, 0
        for g in groups:
            tr = [k for k, m in enumerate(member) if m != g]
            Xt = np.concatenate([Xs[k] for k in tr])
            mu, sd = Xt.mean(axis=0), Xt.std(axis=0)
            sd[sd == 0] = 1.0
            knn = KNeighborsRegressor(min(n_neighbors, len(Xt))).fit(
                (Xt - mu) / sd, np.concatenate([ys[k] for k in tr])
            )
            for k in (k for k, m in enumerate(member) if m == g):
                e = knn.predict((Xs[k] - mu) / sd) - ys[k]
                sse += float(e @ e)
                n += e.size
        return math.sqrt(sse / n)

    scores = {float(tau): score(float(tau)) for tau in grid}
    best = min(scores, key=scores.get)
    if 0 < best < max(grid):
        for tau in (best / math.sqrt(2), best * math.sqrt(2)):
            scores[tau] = score(tau)
        best = min(scores, key=scores.get)
    return LagSelection(
        best,
        dict(sorted(scores.items())),
        tuple(groups),
        f"leave-one-ramp-rate-out over {', '.join(groups)}",
    )
