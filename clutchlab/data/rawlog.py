"""What a format decoder hands over: source channels as logged, before any mapping.

A decoder (CSV, Parquet, MF4) only turns bytes into named float64 columns with their units
and time bases; mapping to canonical signals, unit conversion, validation and alignment are
done once, for every format, by :mod:`clutchlab.data.assemble`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["RawChannel", "RawLog", "TimeBase"]


def _row(i: int) -> str:
    return f"row {i + 1}"


@dataclass
class TimeBase:
    """Sample times shared by some channels (an MF4 channel group).

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample times, s (float64, as logged: not yet checked).
    label : str
        How messages name the time base, e.g. ``"group 2"``.
    row_label : callable
        Maps a 0-based sample index to the text naming it (``"row 6"``).
    """

    time_s: np.ndarray
    label: str
    row_label: Callable[[int], str] = _row


@dataclass
class RawChannel:
    """One source channel (column) of a log.

    Parameters
    ----------
    name : str
        Source name as logged.
    values : numpy.ndarray or None
        float64 values (missing cells as NaN) in ``unit``; None if the channel is not numeric
        or was not loaded.
    unit : str or None
        Unit stored in the file (MF4 channel unit, Parquet field metadata, CSV ``name [unit]``
        or ``name (unit)`` header), or None.
    base : int or None
        Index into :attr:`RawLog.bases` (MF4); None for tabular formats, whose time is a column.
    where : str
        How messages name the channel, e.g. ``"column 'P_CL'"`` or ``"channel 'P_CL' (group 1)"``.
    problem : str or None
        Why ``values`` is None when the channel is unusable (``"not numeric (type string)"``).
    reported : numpy.ndarray or None
        Boolean mask of samples whose problem the decoder already reported (unparseable
        cells, read as NaN); they are not reported again as missing values.
    sources : tuple of str
        Names of where the channel came from, as the measurement tool wrote them (MF4: the
        channel group's acquisition name, its source's name and path, the channel's source
        name and path); a channel map's ``source`` picks among them.
    converted : str or None
        Source type the decoder already turned into ``unit`` (a Parquet ``timestamp[ns]``
        column, read as seconds since its first sample); a channel map may then not declare
        another unit for it.
    """

    name: str
    values: np.ndarray | None
    unit: str | None = None
    base: int | None = None
    where: str = ""
    problem: str | None = None
    reported: np.ndarray | None = None
    sources: tuple[str, ...] = ()
    converted: str | None = None


@dataclass
class RawLog:
    """Decoded content of one log file.

    Parameters
    ----------
    path : pathlib.Path
        The file.
    format : str
        ``"csv"``, ``"parquet"`` or ``"mf4"``.
    channels : list of RawChannel
        Every source channel, in file order.
    bases : list of TimeBase
        Time bases (MF4 groups); empty for tabular formats, whose time is a column.
    row_label : callable
        Row naming of tabular formats (``"line 7 (data row 6)"`` for CSV).
    meta : dict or None
        Metadata embedded by :mod:`clutchlab` writers (``{"name": ..., "meta": {...}}``).
    problems : list of str
        Problems found while decoding (unparseable cells), each naming column and row.
    notes : list of str
        Facts worth reporting that are not problems.
    tabular : bool
        True if time is a column (CSV, Parquet); False if channels carry time bases (MF4).
    """

    path: Path
    format: str
    channels: list[RawChannel]
    bases: list[TimeBase] = field(default_factory=list)
    row_label: Callable[[int], str] = _row
    meta: dict[str, Any] | None = None
    problems: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    tabular: bool = True

    def find(
        self, name: str, group: int | None = None, source: str | None = None
    ) -> list[RawChannel]:
        """Channels called ``name`` (in MF4 group ``group``, from ``source``, if given)."""
        return [
            c
            for c in self.channels
            if c.name == name
            and (group is None or c.base == group)
            and (source is None or source in c.sources)
        ]
