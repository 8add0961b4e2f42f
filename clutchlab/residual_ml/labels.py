"""Latch labels derived from measured data by a documented rule.

When the latch valve latches it exhausts the regulator's feedback and clutch pressure goes to
line pressure; while unlatched the regulator holds clutch pressure well below line (about
15 bar at most against 17.7 bar on the stand). The rule, on the dither-period means ``p̄`` of
clutch pressure and ``p̄_line`` of line pressure (bar), with the gap ``g = p̄_line − p̄``:

1. **Latched / unlatched** by a Schmitt trigger: a sample becomes *latched* when
   ``g ≤ margin_bar`` and stays latched until ``g > margin_bar + hysteresis_bar``. The
   hysteresis keeps noise on a latched plateau from flickering the label.
2. **Latch events** — the paper separates "points associated with the latch event" from the
   points before and after it. Here they are the snap transient around every switch of
   step 1: the contiguous samples around the switch whose gap lies strictly inside
   ``event_band_bar = (lo, hi)`` (pressure already off the regulated plateau, not yet at line
   pressure), at most ``max_event_s`` on each side. They get the label :data:`EVENT`.

How the estimators treat them: the latch classifiers are trained on latched / unlatched
points only (the transient is ambiguous by construction, so the boundary is placed in it),
and every sample, event or not, is predicted by one of the two local GPs. Event points train
no GP by default (``SVCPartitionedGP(event_points="exclude")``); with ``"assign"`` each
trains the GP of its Schmitt-trigger state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data import Trace, dither_period_mean, dither_period_samples
from ..errors import DataError

__all__ = ["EVENT", "LATCHED", "UNLATCHED", "LatchLabelRule", "latch_labels", "schmitt"]

#: Label of unlatched samples (regulated clutch pressure).
UNLATCHED = 0
#: Label of latched samples (clutch pressure at line pressure).
LATCHED = 1
#: Label of samples of the latch snap transient.
EVENT = -1


def schmitt(gap: np.ndarray, on_below: float, off_above: float) -> np.ndarray:
    """Two-level trigger: 1 from ``gap ≤ on_below`` until ``gap > off_above``, else 0.

    Parameters
    ----------
    gap : numpy.ndarray
        Signal (e.g. line minus clutch pressure, bar).
    on_below, off_above : float
        Switching levels (same unit), ``on_below ≤ off_above``.

    Returns
    -------
    numpy.ndarray
        int8 state per sample; before the first crossing the state is 1 only if the first
        sample is at or below ``on_below``.
    """
    gap = np.asarray(gap, dtype=float)
    event = np.zeros(gap.size, dtype=np.int8)  # +1 set, -1 reset, 0 hold
    event[gap <= on_below] = 1
    event[gap > off_above] = -1
    idx = np.where(event != 0, np.arange(gap.size), -1)
    last = np.maximum.accumulate(idx)
    state = np.where(last >= 0, event[np.maximum(last, 0)], 0)
    return (state == 1).astype(np.int8)


@dataclass(frozen=True)
class LatchLabelRule:
    """Parameters of the latch-label rule (see the module docstring).

    Parameters
    ----------
    margin_bar : float
        Latched when line minus clutch pressure is at most this, bar (default 1.0).
    hysteresis_bar : float
        Extra gap needed to leave the latched state, bar (default 0.3).
    event_band_bar : (float, float)
        Gap range of the snap transient around a switch, bar (default (0.3, 2.0)); ``lo``
        below ``margin_bar`` below ``hi``. ``(margin_bar, margin_bar)`` disables events.
    max_event_s : float
        Longest event extent on each side of a switch, s (default 0.25).
    """

    margin_bar: float = 1.0
    hysteresis_bar: float = 0.3
    event_band_bar: tuple[float, float] = (0.3, 2.0)
    max_event_s: float = 0.25

    def __post_init__(self) -> None:
        lo, hi = self.event_band_bar
        problems = []
        if not self.margin_bar > 0:
            problems.append(f"margin_bar must be > 0, got {self.margin_bar!r}")
        if not self.hysteresis_bar >= 0:
            problems.append(f"hysteresis_bar must be >= 0, got {self.hysteresis_bar!r}")
        if not (0 <= lo <= self.margin_bar <= hi):
            problems.append(
                f"event_band_bar {self.event_band_bar!r} must satisfy 0 <= lo <= margin_bar "
                f"({self.margin_bar!r}) <= hi"
            )
        if not self.max_event_s >= 0:
            problems.append(f"max_event_s must be >= 0, got {self.max_event_s!r}")
        if problems:
            raise DataError("invalid latch-label rule", problems)

    def to_dict(self) -> dict:
        """JSON-ready parameters."""
        return {
            "margin_bar": self.margin_bar,
            "hysteresis_bar": self.hysteresis_bar,
            "event_band_bar": list(self.event_band_bar),
            "max_event_s": self.max_event_s,
        }

    @classmethod
    def from_dict(cls, d: dict) -> LatchLabelRule:
        """Inverse of :meth:`to_dict`."""
        return cls(
            float(d["margin_bar"]),
            float(d["hysteresis_bar"]),
            tuple(float(v) for v in d["event_band_bar"]),
            float(d["max_event_s"]),
        )

    def labels_from_gap(self, gap: np.ndarray, sample_rate_Hz: float) -> np.ndarray:
        """Labels from the gap ``line − clutch`` (bar) sampled at ``sample_rate_Hz`` (Hz)."""
        gap = np.asarray(gap, dtype=float)
        state = schmitt(gap, self.margin_bar, self.margin_bar + self.hysteresis_bar)
        labels = state.astype(np.int8)
        lo, hi = self.event_band_bar
        if gap.size < 2 or hi <= lo:
            return labels
        inside = (gap > lo) & (gap < hi)
        max_n = round(self.max_event_s * sample_rate_Hz)
        switches = np.flatnonzero(np.diff(state) != 0) + 1  # first sample of the new state
        # run boundaries of `inside`
        edges = np.flatnonzero(np.diff(inside.astype(np.int8)) != 0) + 1
        starts = np.concatenate([[0], edges])
        ends = np.concatenate([edges, [gap.size]])
        run_of = np.repeat(np.arange(starts.size), ends - starts)
        for k in switches:
            for j in (k - 1, k):
                if inside[j]:
                    r = run_of[j]
                    a = max(starts[r], k - max_n)
                    b = min(ends[r], k + max_n)
                    labels[a:b] = EVENT
        return labels


def latch_labels(
    trace: Trace, rule: LatchLabelRule | None = None, return_state: bool = False
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Latch label of every sample of ``trace``.

    Parameters
    ----------
    trace : Trace
        Experiment with ``clutch_pressure_bar`` (and ``line_pressure_bar``; 17.7 bar when
        absent).
    rule : LatchLabelRule, optional
        The rule's parameters (defaults when omitted).
    return_state : bool
        Also return the Schmitt-trigger state (1 latched, 0 unlatched) of every sample,
        event samples included.

    Returns
    -------
    labels : numpy.ndarray
        int8 per sample: :data:`LATCHED` (1), :data:`UNLATCHED` (0) or :data:`EVENT` (−1).
    state : numpy.ndarray
        int8 per sample, 0 or 1; only if ``return_state``.
    """
    rule = rule or LatchLabelRule()
    if not isinstance(trace, Trace):
        raise DataError(f"expected a Trace, got {type(trace).__name__}")
    n = dither_period_samples(trace)
    p = dither_period_mean(trace.get("clutch_pressure_bar"), n)
    line = dither_period_mean(trace.get("line_pressure_bar"), n)
    gap = line - p
    labels = rule.labels_from_gap(gap, trace.sample_rate_Hz if len(trace) > 1 else 1.0)
    if return_state:
        return labels, schmitt(gap, rule.margin_bar, rule.margin_bar + rule.hysteresis_bar)
    return labels
