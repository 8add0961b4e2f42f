"""Parquet reader and writer (pyarrow).

Written files hold one float64 column per canonical signal present, in canonical order, each
field with its unit in the field metadata (``unit``), and the trace name and metadata as
JSON in the schema metadata (key ``clutchlab``). Read files may hold any names (a unit in a
name, ``P_clutch [kPa]``, is read as in a CSV header when the field metadata has none) and
numeric types (integers, floats, decimals; a timestamp or duration time column is turned
into seconds since its first sample, exactly in integer ticks, and is then in seconds: a
channel map may not declare another unit for it); rows are named ``row N`` (1-based) in
messages.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import DataError
from .meta_json import embedded_meta_json, parse_embedded_meta
from .output import atomic_file_writer
from .paths import check_input_file
from .rawlog import RawChannel, RawLog
from .signals import CANONICAL_ORDER, SIGNALS
from .trace import Trace
from .units import split_header_unit

if TYPE_CHECKING:
    from .channel_map import ChannelMap
    from .options import ReadOptions

__all__ = ["decode_parquet", "read_parquet", "write_parquet"]

#: Schema metadata key holding ``{"name": ..., "meta": {...}}`` as JSON.
META_KEY = b"clutchlab"


@atomic_file_writer
def write_parquet(trace: Trace, path: str | Path) -> Path:
    """Write a trace to a Parquet file.

    Parameters
    ----------
    trace : Trace
        Trace to write; every signal present, float64, canonical order and units
        (s, mA, Hz, bar, °C). Units go to the field metadata, name and metadata to the
        schema metadata.
    path : path-like
        Destination file. An existing file is replaced atomically: the new one is
        written to a temporary sibling and renamed into place, so a failure leaves
        the earlier file as it was.

    Returns
    -------
    pathlib.Path
        The file written.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    if not isinstance(trace, Trace):
        raise TypeError(f"write_parquet expects a Trace, got {type(trace)!r}")
    path = Path(path)
    names = [n for n in CANONICAL_ORDER if trace.has(n)]
    fields = [
        pa.field(n, pa.float64(), nullable=True, metadata={"unit": SIGNALS[n].unit}) for n in names
    ]
    schema = pa.schema(fields, metadata={META_KEY: embedded_meta_json(trace).encode()})
    table = pa.table([pa.array(np.asarray(trace.signals[n])) for n in names], schema=schema)
    pq.write_table(table, path)
    return path


#: Name pandas gives an unnamed index it writes as a column.
_PANDAS_INDEX = re.compile(r"__index_level_\d+__")

#: Seconds per tick of an Arrow timestamp / duration unit.
_TICK_S = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}


def _is_time_type(t: Any) -> bool:
    import pyarrow as pa

    return pa.types.is_timestamp(t) or pa.types.is_duration(t)


def _seconds_since_first(column: Any) -> np.ndarray:
    """Seconds since the first valid sample of a timestamp / duration column (NaN for nulls).

    The first sample is subtracted in int64 ticks before the conversion to float64, so epoch
    nanoseconds (~1.7e18, beyond float64's 2**53) keep their exact steps.
    """
    import pyarrow as pa

    ticks = np.asarray(column.cast(pa.int64()).fill_null(0).to_numpy(zero_copy_only=False))
    ticks = ticks.astype(np.int64, copy=False)
    nulls = np.asarray(column.is_null().to_numpy(zero_copy_only=False), dtype=bool)
    valid = ticks[~nulls]
    first = int(valid[0]) if valid.size else 0
    if valid.size and max(int(valid.max()) - first, first - int(valid.min())) < 2**63:
        elapsed = (ticks - np.int64(first)).astype(np.float64)
    else:  # a span beyond int64 (absurd stamps): float is as good, and the checks will tell
        elapsed = ticks.astype(np.float64) - float(first)
    elapsed[nulls] = np.nan
    return elapsed * _TICK_S[column.type.unit]


def _to_float(column: Any, name: str) -> tuple[np.ndarray | None, str | None, str | None]:
    """float64 values of an Arrow column; or None with the reason; plus a note."""
    import pyarrow as pa
    import pyarrow.compute as pc

    t = column.type
    if _is_time_type(t):
        note = f"column {name!r}: {t} converted to seconds since its first sample"
        return _seconds_since_first(column), None, note
    if pa.types.is_integer(t) or pa.types.is_floating(t) or pa.types.is_decimal(t):
        try:
            values = pc.cast(column, pa.float64(), safe=False).to_numpy(zero_copy_only=False)
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError) as exc:
            return None, f"cannot convert type {t} to float64 ({exc})", None
        return np.asarray(values, dtype=np.float64), None, None
    return None, f"not numeric (type {t})", None


def decode_parquet(path: str | Path, wanted: Callable[[str], bool] | None = None) -> RawLog:
    """Decode a Parquet file into named float64 columns (no mapping, no value checks).

    Parameters
    ----------
    path : path-like
        Parquet file with one column per channel.
    wanted : callable, optional
        ``wanted(name)`` tells whether a column's values are needed; other columns are
        listed without values. Default: every column.

    Returns
    -------
    RawLog
        One channel per column (non-numeric columns with ``values=None`` and the reason);
        embedded clutchlab metadata in ``meta``.

    Raises
    ------
    DataError
        Missing file, not a readable Parquet file (wrong magic, truncated, corrupt), no
        columns or no rows, duplicate column names.
    """
    import pyarrow.parquet as pq

    path = check_input_file(path)
    if path.stat().st_size == 0:
        raise DataError(f"{path}: empty file")
    try:
        table = pq.read_table(path)
        names = [str(n) for n in table.column_names]  # decoding may fail on damaged names
        schema_meta = dict(table.schema.metadata or {})
        field_meta = [table.schema.field(i).metadata or {} for i in range(len(names))]
    except Exception as exc:  # pyarrow raises many types on corrupt input
        raise DataError(
            f"{path}: not a readable Parquet file (truncated or corrupt?): "
            f"{type(exc).__name__}: {exc}"
        ) from None
    if not names:
        raise DataError(f"{path}: empty file (no columns)")
    if table.num_rows == 0:
        raise DataError(f"{path}: empty file (no rows)")
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise DataError(f"{path}: duplicate column(s) {', '.join(map(repr, dupes))}")

    # pandas stores an unnamed index it could not keep as metadata (not a RangeIndex) as
    # ``__index_level_N__`` columns: row labels, not channels.
    index = [i for i, n in enumerate(names) if _PANDAS_INDEX.fullmatch(n)]
    if index:
        table = table.drop_columns([names[i] for i in index])
        field_meta = [m for i, m in enumerate(field_meta) if i not in index]
        dropped = ", ".join(repr(names[i]) for i in index)
        names = [n for i, n in enumerate(names) if i not in index]
    meta = None
    if META_KEY in schema_meta:
        meta = parse_embedded_meta(schema_meta[META_KEY])
    channels: list[RawChannel] = []
    notes: list[str] = [f"pandas index column(s) {dropped} ignored"] if index else []
    # A unit in the column name (``P_CL [kPa]``, a spreadsheet's or logger's export) is
    # read as in a CSV header; a unit in the field metadata comes first.
    headers = names
    split = [split_header_unit(h, wanted) for h in headers]
    names = [n for n, _ in split]
    clash = sorted({n for n in names if names.count(n) > 1})
    if clash:
        by_name = {
            n: [repr(h) for h, m in zip(headers, names, strict=True) if m == n] for n in clash
        }
        shown = [f"{n!r} (columns {', '.join(h)})" for n, h in by_name.items()]
        raise DataError(f"{path}: duplicate column(s) {', '.join(shown)}")
    for i, name in enumerate(names):
        unit = split[i][1]
        if b"unit" in field_meta[i]:
            unit = field_meta[i][b"unit"].decode("utf-8", errors="replace") or unit
        if wanted is not None and not wanted(name):
            channels.append(
                RawChannel(name, None, unit, where=f"column {headers[i]!r}", problem="not loaded")
            )
            continue
        try:
            values, problem, note = _to_float(table.column(i), name)
        except Exception as exc:  # conversion of exotic Arrow types
            values, problem, note = None, f"unreadable column ({type(exc).__name__}: {exc})", None
        if note:
            notes.append(note)
        converted = None
        if values is not None and _is_time_type(table.column(i).type):
            converted = str(table.column(i).type)
            if unit is not None and unit != "s":
                notes.append(f"column {name!r}: field unit {unit!r} ignored ({converted})")
            unit = "s"
        channels.append(
            RawChannel(
                name,
                values,
                unit,
                where=f"column {headers[i]!r}",
                problem=problem,
                converted=converted,
            )
        )
    return RawLog(path, "parquet", channels, meta=meta, notes=notes)


def read_parquet(
    path: str | Path,
    name: str | None = None,
    meta: Mapping[str, Any] | None = None,
    *,
    channel_map: ChannelMap | str | Path | None = None,
    options: ReadOptions | None = None,
) -> Trace:
    """Read one experiment from a Parquet file.

    Parameters
    ----------
    path : path-like
        Parquet file. Without ``channel_map`` the columns must be canonical names; a unit in
        the field metadata must then be the canonical one.
    name : str, optional
        Trace name; defaults to the embedded name, else the file stem.
    meta : dict, optional
        Trace metadata; defaults to the metadata embedded by :func:`write_parquet`.
    channel_map : ChannelMap or path-like, optional
        Source column → canonical signal with units.
    options : ReadOptions, optional
        Gap interpolation, resampling and jitter tolerance.

    Returns
    -------
    Trace

    Raises
    ------
    DataError
        Naming the file and listing every problem with column and row.
    """
    from .reading import read_log

    return read_log(
        path, name=name, meta=meta, channel_map=channel_map, options=options, format="parquet"
    )[0]
