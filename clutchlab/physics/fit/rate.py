"""The fit's sample rate: training experiments logged much faster are resampled first.

A fit simulates every sample of its experiments, and its sample budgets (the pre-fit subset,
the residual decimation) count samples. A stand that logs at 5 kHz costs five times as much
per iteration as one at 1 kHz for the same seconds of data, and a fit within its wall limit
gets a fifth of the iterations; with ``FitSettings.fit_rate_Hz`` set, such experiments are
fitted resampled to that rate (opt-in: ``fit-physics --fit-rate``). The integration accuracy
is set by ``FitSettings.substeps``, not by the logger's rate.
"""

from __future__ import annotations

from ...data import Trace

__all__ = ["FIT_RATE_MARGIN", "SUGGESTED_FIT_RATE_HZ", "at_fit_rate", "faster_than_fit"]

#: Experiments are resampled only when logged faster than this many times the fit's rate
#: (1 kHz data stay as they are, to the last digit, at a fit rate of 1 kHz).
FIT_RATE_MARGIN = 1.5

#: The rate the fit's budgets were set on (the stand's 1 kHz): what ``fit-physics`` suggests
#: for data logged faster.
SUGGESTED_FIT_RATE_HZ = 1000.0


def at_fit_rate(traces: list[Trace], rate_Hz: float | None) -> list[Trace]:
    """``traces``, those sampled faster than ``FIT_RATE_MARGIN × rate_Hz`` resampled onto a
    uniform grid at ``rate_Hz`` (every signal linearly interpolated, as
    ``clutchlab data convert --rate``).

    Parameters
    ----------
    traces : list of Trace
        Training experiments.
    rate_Hz : float or None
        The fit's sample rate, Hz; None keeps every experiment at its own rate.

    Returns
    -------
    list of Trace
        Same order; unchanged experiments are the same objects.
    """
    return [t.resample(rate_Hz) if faster_than_fit(t, rate_Hz) else t for t in traces]


def faster_than_fit(trace: Trace, rate_Hz: float | None) -> bool:
    """Whether :func:`at_fit_rate` resamples ``trace`` (logged faster than
    ``FIT_RATE_MARGIN × rate_Hz``; never when ``rate_Hz`` is None)."""
    return rate_Hz is not None and trace.sample_rate_Hz > FIT_RATE_MARGIN * rate_Hz
