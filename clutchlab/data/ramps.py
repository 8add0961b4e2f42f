"""Ramp labels in the order of their ramp rates, fastest first.

A dataset's ramp labels are the user's (``fast`` / ``medium`` / ``slow`` on the stand, but
``r5s`` / ``r10s`` / ``r20s`` or ``ramp_2`` elsewhere), so an alphabetical order says nothing
about the rates: summaries, legends and overviews list them by the rate measured from the
current instead.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import numpy as np

from .derived import didt, dither_period_mean, dither_period_samples
from .trace import Trace

__all__ = [
    "RAMP_RATE_PERIODS",
    "RAMP_RATE_SHARE",
    "order_ramps",
    "ramp_rate_mA_s",
    "ramps_fastest_first",
]

#: Window of the slope of a measured current's ramp rate, in dither periods (of at least
#: 10 samples each): the window ``nominal_didt`` uses for the direction of travel ...
RAMP_RATE_PERIODS = 5.0
#: ... or this share of the experiment's samples when longer: the slope noise falls with the
#: window to the power 1.5, and four corners of a ramp profile rounded by half a window
#: each leave the full slope on far more than the 5 % of samples the percentile needs.
RAMP_RATE_SHARE = 0.02


def order_ramps(labels: Iterable[str], rates: Mapping[str, float | None]) -> list[str]:
    """Ramp labels fastest first, as summaries and overviews list them.

    Parameters
    ----------
    labels : iterable of str
        Ramp labels (each listed once).
    rates : mapping of str to float or None
        Ramp rate of a label (mA/s); a label missing here, or with None or a value that is
        not a finite number > 0, has no known rate.

    Returns
    -------
    list of str
        Labels with a known rate by rate, fastest first, then the others; alphabetical
        among equal rates and among the labels without one.
    """

    def key(label: str) -> tuple[int, float, str]:
        rate = rates.get(label)
        if rate is not None and math.isfinite(rate) and rate > 0:
            return 0, -float(rate), label
        return 1, 0.0, label

    return sorted(dict.fromkeys(labels), key=key)


def ramp_rate_mA_s(trace: Trace) -> float | None:
    """Ramp rate of an experiment (mA/s): the 95th percentile of |dI/dt| of its
    dither-period-mean current.

    The current is the command ``current_cmd_mA`` when logged, else the measured
    ``current_mA`` (its dither averaged out over each period, its slope a least-squares one
    over :data:`RAMP_RATE_PERIODS` periods or :data:`RAMP_RATE_SHARE` of the experiment), so
    the rate is the data's, not a label's.

    Parameters
    ----------
    trace : Trace
        One experiment with ``current_cmd_mA`` or ``current_mA``.

    Returns
    -------
    float or None
        mA/s (0 for a current that never changes); None when the trace has fewer than two
        samples.
    """
    if len(trace) < 2:
        return None
    n = dither_period_samples(trace)
    if trace.has("current_cmd_mA"):
        cur = dither_period_mean(np.asarray(trace.get("current_cmd_mA"), float), n)
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = np.abs(np.gradient(cur, trace.time_s))
    else:
        # A measured current keeps its noise after the period mean: its two-sample slope
        # (±300 mA/s on stand data) made a 27 mA/s ramp read 181 mA/s, faster than a
        # logged 110 mA/s command. A least-squares slope over 5 dither periods, or over
        # 2 % of the experiment when that is longer, reads it within a few per cent.
        cur = dither_period_mean(np.asarray(trace.get("current_mA"), float), n)
        if not np.isfinite(cur).all() or trace.sample_rate_Hz <= 0:
            return None
        window = max(RAMP_RATE_PERIODS * max(n, 10.0), RAMP_RATE_SHARE * len(trace))
        slope = np.abs(didt(cur, trace.sample_rate_Hz, window))
    return float(np.nanpercentile(slope, 95)) if np.any(np.isfinite(slope)) else None


def ramps_fastest_first(traces: Iterable[Trace]) -> dict[str, list[Trace]]:
    """The experiments grouped by ramp label, the labels fastest first.

    A label's rate is the fastest of its experiments' (:func:`ramp_rate_mA_s`); labels
    whose rate cannot be measured (or is 0: no ramp) come last, alphabetically
    (:func:`order_ramps`).

    Parameters
    ----------
    traces : iterable of Trace
        Experiments (their order is kept within a label).

    Returns
    -------
    dict of str to list of Trace
        Ramp label → its experiments, in the order of the labels' rates.
    """
    groups: dict[str, list[Trace]] = {}
    rates: dict[str, float | None] = {}
    for trace in traces:
        label = str(trace.ramp)
        groups.setdefault(label, []).append(trace)
        rate = ramp_rate_mA_s(trace)
        rates[label] = max(filter(None, (rates.get(label), rate)), default=None)
    return {label: groups[label] for label in order_ramps(groups, rates)}
