"""How logs are read: gap interpolation, resampling and jitter tolerance."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import DataError

__all__ = ["ReadOptions"]


@dataclass(frozen=True)
class ReadOptions:
    """Settings of reading a log into a :class:`~clutchlab.data.trace.Trace`.

    Parameters
    ----------
    interpolate_gaps : int
        Longest run of missing samples (NaN / inf values, or time stamps missing from a
        regular time base) that is filled by linear interpolation, in samples. Runs at the
        start or end of a channel are filled with the nearest value. Every filled run is
        reported. 0 (default): any missing sample is an error.
    rate_Hz : float or None
        Resample every log onto a uniform grid at this rate, Hz. None (default): keep a
        single regular time base as logged; align multi-rate or irregular logs on a uniform
        grid at the rate of the fastest time base.
    max_jitter : float
        Largest deviation of a time stamp from the best uniform grid through its time base,
        as a fraction of the sample interval, that still counts as regular (default 0.01).
        A log beyond it is resampled onto a uniform grid (and the jitter reported).
    """

    interpolate_gaps: int = 0
    rate_Hz: float | None = None
    max_jitter: float = 0.01

    def __post_init__(self) -> None:
        problems = []
        gaps = self.interpolate_gaps
        if isinstance(gaps, bool) or not isinstance(gaps, int) or gaps < 0:
            problems.append(f"interpolate_gaps must be an integer >= 0, got {gaps!r}")
        rate = self.rate_Hz
        if rate is not None and (
            isinstance(rate, bool)
            or not isinstance(rate, int | float)
            or not math.isfinite(rate)
            or rate <= 0
        ):
            problems.append(f"rate_Hz must be a positive number of Hz or None, got {rate!r}")
        jitter = self.max_jitter
        if isinstance(jitter, bool) or not isinstance(jitter, int | float) or not 0 <= jitter < 0.5:
            problems.append(f"max_jitter must be a fraction in [0, 0.5), got {jitter!r}")
        if problems:
            raise DataError("invalid read options", problems)
