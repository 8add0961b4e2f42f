"""What reading a log did: sources, unit conversions, timing, filled gaps and problems."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from .timebase import Timing

__all__ = ["LoadReport"]


@dataclass(frozen=True)
class LoadReport:
    """Account of reading one log file into a trace.

    Parameters
    ----------
    file : pathlib.Path
        The log file.
    format : str
        ``"csv"``, ``"parquet"`` or ``"mf4"``.
    name : str
        Experiment name.
    channel_map : str or None
        The channel map used (its file), or None.
    sources : mapping of str to str
        Canonical signal → where it came from (source channel, unit conversion).
    defaults : mapping of str to float
        Canonical signals filled with a constant from the channel map, in canonical units.
    timing : tuple of Timing
        Sample rate, jitter and gaps of every time base used.
    resampled : str or None
        Why the signals were resampled onto a uniform grid, or None if the log's own time
        base was kept.
    rate_Hz : float or None
        Sample rate of the trace, Hz (None if it could not be built).
    filled : tuple of str
        Every gap filled by interpolation, with column and rows.
    notes : tuple of str
        Other facts (ignored channels, converted time columns).
    problems : tuple of str
        Every problem found; empty when the trace was built.
    samples : int or None
        Samples of the trace (or of the log's time column when the trace failed).
    duration_s : float or None
        Last minus first sample time, s.
    ranges : mapping of str to (float, float)
        Smallest and largest finite value of each canonical signal, in its canonical unit.
    """

    file: Path
    format: str
    name: str
    channel_map: str | None = None
    sources: Mapping[str, str] = field(default_factory=dict)
    defaults: Mapping[str, float] = field(default_factory=dict)
    timing: tuple[Timing, ...] = ()
    resampled: str | None = None
    rate_Hz: float | None = None
    filled: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    problems: tuple[str, ...] = ()
    samples: int | None = None
    duration_s: float | None = None
    ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for key in ("sources", "defaults", "ranges"):
            object.__setattr__(self, key, MappingProxyType(dict(getattr(self, key))))

    @property
    def ok(self) -> bool:
        """True if no problem was found."""
        return not self.problems

    @property
    def jitter_max_s(self) -> float:
        """Largest time-stamp jitter over all time bases, s (0 if none was analysed)."""
        return max((tm.jitter_max_s for tm in self.timing), default=0.0)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of the report."""
        return {
            "file": str(self.file),
            "format": self.format,
            "name": self.name,
            "channel_map": self.channel_map,
            "samples": self.samples,
            "duration_s": self.duration_s,
            "rate_Hz": self.rate_Hz,
            "ranges": {k: list(v) for k, v in self.ranges.items()},
            "sources": dict(self.sources),
            "defaults": dict(self.defaults),
            "timing": [tm.to_dict() for tm in self.timing],
            "resampled": self.resampled,
            "filled": list(self.filled),
            "notes": list(self.notes),
            "problems": list(self.problems),
        }
