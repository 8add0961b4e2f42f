"""Latch decision from latch-event currents that move with the ramp rate.

The latch valve snaps when its pilot pressure, which trails the current, passes a
threshold; on a ramp of rate ``İ`` the snap then happens at ``I = θ + τ İ``: later on a
faster rise (latch-on), earlier on a faster fall (latch-off). The thresholds depend on the
dither (it changes the spool's friction and the mean force). :class:`EventDecision` is
that law, fitted by least squares to the latch events of the training experiments (the
switches of the Schmitt-trigger latch state of :mod:`~clutchlab.residual_ml.labels`):

``d(x) = I − τ_on İ − θ_on(A, f)`` on a rising or held branch (direction ≥ 0) and
``d(x) = I − τ_off İ − θ_off(A, f)`` on a falling one, ``θ(A, f) = c₀ + c₁A + c₂f + c₃Af``
(mA), latched where ``d > 0``. ``I`` is the estimator's current feature (lagged or not),
``İ`` its dI/dt feature, ``A`` / ``f`` the dither amplitude (mA) and frequency (Hz).

A classifier on the same features has to learn the boundary's dependence on ``İ`` from
the two ramp rates of the training set and may bend it anywhere between them; the law
above is linear in the rate by construction, so a ramp rate between the trained ones is an
interpolation. On held-back training-side ramps of the stand and four zoo plants
(``studies/latch_event.py``) it was chosen as the default (see there).

The decision is memoryless given the held direction of travel, so it runs per sample in
the step predictor and the FMU; on a falling branch it assumes the rise latched (true of
every ramp that passes the latch-on current, as the protocol's do).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..errors import ModelError

__all__ = [
    "EventDecision",
    "decision_current_columns",
    "event_features",
    "fit_event_decision",
    "latch_events",
]

#: Current features (first found is used), their dI/dt and direction features.
_CURRENT = ("current_lag_mA", "current_mA")
_DIDT = ("didt_mA_s", "didt_causal_mA_s")
_DIRECTION = ("direction", "direction_causal")
#: Huber-like scale of the latch-event fit (mA): a mis-detected event does not pull it.
_EVENT_SCALE_MA = 3.0


@dataclass(frozen=True)
class EventDecision:
    """``d(x)`` of the module docstring; > 0 means latched.

    Attributes
    ----------
    columns : numpy.ndarray
        Indices (int) of current, dI/dt, direction, dither amplitude and dither frequency
        in the decision's input rows (−1: not an input, its coefficients are 0).
    on, off : numpy.ndarray
        ``(c₀, c₁, c₂, c₃, τ)`` of latch-on and latch-off: mA, mA/mA, mA/Hz, mA/(mA·Hz), s.
    """

    columns: np.ndarray
    on: np.ndarray
    off: np.ndarray

    kind = "event"

    def _parts(self, X: np.ndarray):
        c = [int(v) for v in self.columns]

        def col(k):
            return X[:, c[k]] if c[k] >= 0 else np.zeros(X.shape[0])

        return col(0), col(1), col(2), col(3), col(4)

    def __call__(self, X: np.ndarray) -> np.ndarray:
        """Decision value per row of ``X`` (mA); > 0 means latched."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        i, di, direction, a, f = self._parts(X)

        def branch(c):
            return i - c[4] * di - (c[0] + c[1] * a + c[2] * f + c[3] * a * f)

        return np.where(direction >= 0, branch(self.on), branch(self.off))

    def thresholds(self, amp_mA: float, freq_Hz: float) -> tuple[float, float]:
        """Latch-on and latch-off current (mA) at zero rate for one dither setting."""
        x = np.array([1.0, amp_mA, freq_Hz, amp_mA * freq_Hz])
        return float(x @ self.on[:4]), float(x @ self.off[:4])

    def arrays(self) -> dict[str, np.ndarray]:
        """Arrays for an NPZ file."""
        return {"columns": np.asarray(self.columns, dtype=float), "on": self.on, "off": self.off}

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> EventDecision:
        """Inverse of :meth:`arrays`."""
        return cls(
            np.asarray(a["columns"], dtype=float).astype(int),
            np.asarray(a["on"], dtype=float),
            np.asarray(a["off"], dtype=float),
        )


def event_features(names: list[str]) -> bool:
    """Whether ``names`` hold what the law needs: a current, a dI/dt and a direction."""
    return all(_first(list(names), w) >= 0 for w in (_CURRENT, _DIDT, _DIRECTION))


def decision_current_columns(names: list[str]) -> tuple[int, int]:
    """Index in ``names`` of the current feature and of the dI/dt feature (−1: absent)."""
    return _first(list(names), _CURRENT), _first(list(names), _DIDT)


def law_columns(names: list[str], law: str) -> np.ndarray:
    """Indices in ``names`` of current, dI/dt, direction, dither amplitude and frequency
    (−1: absent) for a latch-event ``law``; ModelError naming what it lacks."""
    cols = np.array(
        [
            _first(names, _CURRENT),
            _first(names, _DIDT),
            _first(names, _DIRECTION),
            _first(names, ("dither_amp_mA",)),
            _first(names, ("dither_freq_Hz",)),
        ]
    )
    missing = [
        what
        for what, c in zip(("a current", "a dI/dt", "a direction"), cols[:3], strict=True)
        if c < 0
    ]
    if missing:
        raise ModelError(
            f"the {law} needs {', '.join(missing)} feature among the classifier features; "
            f"they are {names}"
        )
    return cols


def _first(names: list[str], wanted: tuple[str, ...]) -> int:
    return next((names.index(n) for n in wanted if n in names), -1)


def _fit_branch(rows: np.ndarray, used: list[int]) -> np.ndarray:
    """``(c₀, c₁, c₂, c₃, τ)`` of ``I = θ(A, f) + τ İ`` by a robust least-squares fit.

    ``rows``: one event per row, columns ``(I, İ, A, f)``; ``used``: which of the five
    coefficients are fitted (the rest stay 0).
    """
    i, di, a, f = rows.T
    design = np.column_stack([np.ones_like(i), a, f, a * f, di])[:, used]
    # Scaled columns: mA, mA, Hz, mA·Hz and mA/s differ by orders of magnitude.
    scale = np.maximum(np.abs(design).max(axis=0), 1e-12)
    z = design / scale
    start = np.linalg.lstsq(z, i, rcond=None)[0]
    res = least_squares(
        lambda p: z @ p - i, start, loss="soft_l1", f_scale=_EVENT_SCALE_MA, method="trf"
    )
    coef = np.zeros(5)
    coef[used] = res.x / scale
    return coef


def fit_event_decision(
    events: list[tuple[np.ndarray, int]], feature_names: list[str]
) -> EventDecision:
    """Fit the latch-event law to latch events.

    Parameters
    ----------
    events : list of (numpy.ndarray, int)
        One feature row (the decision's inputs, ``feature_names`` order) per latch event
        and its direction: +1 latch-on (the first latched sample of a rising branch), −1
        latch-off (the first unlatched sample of a falling one).
    feature_names : list of str
        Names of the row's columns; they must include a current feature (``current_lag_mA``
        or ``current_mA``), a dI/dt feature and a direction feature.

    Returns
    -------
    EventDecision

    Raises
    ------
    ModelError
        If a needed feature is missing or there are fewer than two events of each kind.
    """
    names = list(feature_names)
    cols = law_columns(names, "latch-event law")
    coefs = []
    for sign, what in ((1, "latch-on"), (-1, "latch-off")):
        x = np.array([row for row, s in events if s == sign], dtype=float)
        if len(x) < 2:
            raise ModelError(
                f"the latch-event law needs at least two {what} events in the training data, "
                f"found {len(x)}"
            )
        a = x[:, cols[3]] if cols[3] >= 0 else np.zeros(len(x))
        f = x[:, cols[4]] if cols[4] >= 0 else np.zeros(len(x))
        rows = np.column_stack([x[:, cols[0]], x[:, cols[1]], a, f])
        used = [0]
        spread = np.ptp(rows, axis=0)
        if spread[2] > 1e-6 * max(np.abs(a).max(), 1.0):
            used.append(1)
        if spread[3] > 1e-6 * max(np.abs(f).max(), 1.0):
            used.append(2)
        if 1 in used and 2 in used and len(x) >= 6:
            used.append(3)
        rates = np.abs(rows[:, 1])
        if rates.max() > 1.5 * max(rates.min(), 1e-9):  # two ramp rates or more: τ
            used.append(4)
        if len(x) <= len(used):
            used = [0, 4] if 4 in used and len(x) > 2 else [0]
        coefs.append(_fit_branch(rows, used))
    return EventDecision(cols, coefs[0], coefs[1])


def latch_events(X: np.ndarray, state: np.ndarray) -> list[tuple[np.ndarray, int]]:
    """Latch events of one experiment: ``(row of X, +1 / −1)`` at every switch of ``state``.

    ``state`` is the Schmitt-trigger latch state (1 latched) per sample; the row is that of
    the first sample after the switch.
    """
    s = np.asarray(state, dtype=np.int8)
    sw = np.flatnonzero(np.diff(s) != 0) + 1
    return [(X[k], 1 if s[k] == 1 else -1) for k in sw]
