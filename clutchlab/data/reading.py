"""Read one log file of any registered format into a validated trace."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from .assemble import assemble
from .channel_map import ChannelMap, ChannelMapLike, load_channel_map
from .formats import format_of
from .options import ReadOptions
from .report import LoadReport
from .signals import CANONICAL_ORDER, SIGNALS
from .trace import Trace

__all__ = ["check_log", "read_log"]


def _wanted(cmap: ChannelMap | None):
    if cmap is None:
        return lambda name: name in SIGNALS
    names = {cmap.spec(s).channel for s in CANONICAL_ORDER}
    return lambda name: name in names


def check_log(
    path: str | Path,
    *,
    name: str | None = None,
    meta: Mapping[str, Any] | None = None,
    channel_map: ChannelMapLike = None,
    options: ReadOptions | None = None,
    format: str | None = None,
) -> tuple[Trace | None, LoadReport]:
    """Read a log and report on it; problems are returned, not raised.

    Parameters
    ----------
    path : path-like
        Log file (``.csv``, ``.parquet``, ``.mf4``).
    name : str, optional
        Experiment name; default the embedded name, else the file stem.
    meta : dict, optional
        Metadata (e.g. from the manifest); default the embedded metadata.
    channel_map : ChannelMap, path-like or mapping, optional
        Source channel → canonical signal (see :mod:`clutchlab.data.channel_map`).
    options : ReadOptions, optional
        Gap interpolation, resampling, jitter tolerance.
    format : str, optional
        Format name; default from the file suffix.

    Returns
    -------
    trace : Trace or None
        None if anything is wrong.
    report : LoadReport
        Sources, timing, filled gaps, notes and every problem (file, column, row).

    Raises
    ------
    DataError
        Only for an unusable channel map or an unknown format.
    """
    path = Path(path)
    cmap = load_channel_map(channel_map) if channel_map is not None else None
    fmt = format_of(path, format)
    try:
        raw = fmt.decode(path, _wanted(cmap))
    except DataError as exc:
        report = LoadReport(
            file=path,
            format=fmt.name,
            name=name or path.stem,
            channel_map=cmap.label if cmap is not None else None,
            problems=tuple(exc.problems or [str(exc)]),
        )
        return None, report
    # User data may hold absurd values (1e308 s, inf): they are reported as problems, so
    # numpy's overflow warnings on the way would only be noise.
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        return assemble(raw, name=name, meta=meta, channel_map=cmap, options=options)


def read_log(
    path: str | Path,
    *,
    name: str | None = None,
    meta: Mapping[str, Any] | None = None,
    channel_map: ChannelMapLike = None,
    options: ReadOptions | None = None,
    format: str | None = None,
) -> tuple[Trace, LoadReport]:
    """Read one log file (CSV, Parquet, MF4) into a validated trace in canonical units.

    Parameters
    ----------
    path : path-like
        Log file; the format is taken from the suffix unless ``format`` is given.
    name : str, optional
        Experiment name; default the embedded name, else the file stem.
    meta : dict, optional
        Metadata (e.g. from the manifest); default the metadata embedded by clutchlab writers.
    channel_map : ChannelMap, path-like or mapping, optional
        Source channel → canonical signal with units and defaults. Without it, channel names
        must be canonical and units (where the file stores them) canonical.
    options : ReadOptions, optional
        ``interpolate_gaps`` (samples), ``rate_Hz`` (resampling rate, Hz), ``max_jitter``
        (fraction of the sample interval).

    Returns
    -------
    trace : Trace
        Canonical signals (s, mA, Hz, bar, °C) on one time base, uniform if the log was
        multi-rate, irregular or gappy.
    report : LoadReport
        Sources, unit conversions, timing and jitter, filled gaps, notes.

    Raises
    ------
    DataError
        Naming the file and listing every problem, each with column and row: unreadable,
        empty or truncated file, missing required column, NaN/inf runs (unless filled),
        non-monotonic or duplicate time, time gaps, implausible units, values out of the
        physical range, sample rate below 10 × the dither frequency.
    """
    trace, report = check_log(
        path, name=name, meta=meta, channel_map=channel_map, options=options, format=format
    )
    if trace is None:
        raise DataError(f"{Path(path)}: cannot read {report.format} log", list(report.problems))
    return trace, report
