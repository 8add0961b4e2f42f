"""Experiments at a ramp rate between the trained ones, made from the training inputs.

The hybrid's form choice (:class:`~clutchlab.residual_ml.HybridModel`) scores the forms by
leave-one-experiment-out on the training ramps. A fold holds out a dither setting at one
ramp rate while that setting stays trained only at the other rate, so the standalone form
(the ML pipeline without physics) must carry the setting over the whole trained range of
rates; a test ramp's setting is trained at both rates around it. How much easier the test
is than the folds depends on the circuit. The fitted physics can say how much: on a
synthetic training set (the physics' prediction on the training inputs) the standalone form
is scored by the same folds and, trained on all of it, on synthetic experiments at a rate
between the trained ones — the training inputs of the slower ramp played faster
(:func:`between_rate_inputs`), with the physics' prediction as their pressure. The ratio of
the two is the standalone form's handicap.

Only inputs of the training experiments are used: nothing of a test ramp.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from ..data import Trace, dither_period_samples
from ..data.demodulate import nominal_didt
from .rate_bridge import RATE_GAP

__all__ = ["between_rate_inputs", "play_faster", "ramp_rate"]


def ramp_rate(trace: Trace) -> float:
    """Typical ramp rate of ``trace``, mA/s.

    The median of ``|dI/dt|`` of the nominal current
    (:func:`~clutchlab.data.demodulate.nominal_didt`) where it exceeds half its 95th
    percentile, i.e. along the ramps (holds left out); 0 for a trace that does not ramp.
    """
    rate = np.abs(nominal_didt(trace))
    rate = rate[np.isfinite(rate)]
    if rate.size == 0:
        return 0.0
    moving = rate[rate > 0.5 * np.percentile(rate, 95)]
    return float(np.median(moving)) if moving.size else 0.0


def play_faster(trace: Trace, factor: float, name: str | None = None) -> Trace:
    """``trace`` played ``factor`` times faster by dropping whole dither periods.

    Output sample ``k`` (time ``t = k / fs`` from the start) lies in dither period
    ``j = floor(t / T)`` at phase ``t − jT`` (``T`` the dither period, s); it takes every
    signal of ``trace`` at ``round(j · factor) · T + (t − jT)``, linearly interpolated. The
    slow parts of the profile (ramp, holds) then pass ``factor`` times faster while the dither
    keeps its frequency, waveform and its amplitude at each current. Without dither ``T`` is
    one sample.

    Parameters
    ----------
    trace : Trace
        Experiment (uniform time base).
    factor : float
        Speed-up, ≥ 1.
    name : str, optional
        Name of the new trace (default ``trace.name`` + ``"_x{factor}"``).

    Returns
    -------
    Trace
        Same sample rate, ``duration / factor`` long; metadata copied with ``ramp`` set to
        ``"between"``.
    """
    factor = float(factor)
    if not (math.isfinite(factor) and factor >= 1.0):
        raise ValueError(f"factor must be a finite number >= 1, not {factor!r}")
    fs = trace.sample_rate_Hz
    period = dither_period_samples(trace) / fs
    t = trace.time_s
    n = int(np.floor((t[-1] - t[0]) / factor * fs)) + 1
    new = np.arange(n) / fs
    j = np.floor(new / period + 1e-9)
    src = t[0] + np.round(j * factor) * period + (new - j * period)
    keep = src <= t[-1]
    new, src = new[keep], src[keep]
    signals = {k: np.interp(src, t, v) for k, v in trace.signals.items() if k != "time_s"}
    signals["time_s"] = t[0] + new
    meta = {**trace.meta, "ramp": "between"}
    return Trace(name or f"{trace.name}_x{factor:.3g}", signals, meta=meta)


def between_rate_inputs(traces: Sequence[Trace]) -> list[Trace]:
    """Experiments at the geometric-mean rate of each pair of neighbouring trained rates.

    The traces are grouped by their ``ramp`` label; a label's rate is the median of its
    traces' :func:`ramp_rate`. For each pair of neighbouring rates ``r_slow < r_fast`` that
    differ by more than 1.5×, every trace of the slower label is played
    ``sqrt(r_fast / r_slow)`` times faster (:func:`play_faster`).

    Parameters
    ----------
    traces : sequence of Trace
        Training experiments.

    Returns
    -------
    list of Trace
        The synthetic experiments (their pressure is still the measured one of the slow
        trace, replaced by the caller); empty when the traces hold fewer than two rates.
    """
    by_ramp: dict[str, list[Trace]] = {}
    for t in traces:
        by_ramp.setdefault(str(t.ramp), []).append(t)
    rates = {k: float(np.median([ramp_rate(t) for t in v])) for k, v in by_ramp.items()}
    order = sorted((r, k) for k, r in rates.items() if r > 0)
    out = []
    for (slow, label), (fast, _) in itertools.pairwise(order):
        if math.log(fast / slow) <= RATE_GAP:
            continue
        factor = math.sqrt(fast / slow)
        out += [play_faster(t, factor) for t in by_ramp[label]]
    return out
