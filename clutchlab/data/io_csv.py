"""CSV reader and writer.

File layout: one header line of column names, then one line per sample, comma-separated.
Files written here carry canonical signal names (see
:data:`~clutchlab.data.signals.CANONICAL_ORDER`) in canonical units. Files read here may carry
any names (mapped by a :class:`~clutchlab.data.channel_map.ChannelMap`), optionally with a
unit in brackets (``P_clutch [kPa]``). Line numbers in messages are the file's line numbers
(the header is line 1, the first data row is line 2).
"""

from __future__ import annotations

import csv
import os
import re
import warnings
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import DataError
from .output import atomic_file_writer
from .paths import check_input_file
from .rawlog import RawChannel, RawLog
from .signals import CANONICAL_ORDER
from .trace import _MAX_ROWS_LISTED, Trace

if TYPE_CHECKING:
    from .channel_map import ChannelMap
    from .options import ReadOptions

__all__ = ["decode_csv", "read_csv", "write_csv"]

_FLOAT_FORMAT = "%.9g"
#: Used for ``time_s`` when ``float_format`` would merge neighbouring sample times.
_EXACT_FORMAT = "%.17g"
#: Cell texts read as NaN (a missing value), not as unparseable.
_NA_VALUES = ("", "nan", "NaN", "NAN")
#: ``name [unit]`` column header.
_UNIT_HEADER = re.compile(r"^(?P<name>.*?)\s*\[(?P<unit>[^\[\]]*)\]$")


def _line_label(i: int) -> str:
    """Name the 0-based data row ``i`` by its line in the file (header = line 1)."""
    return f"line {i + 2} (data row {i + 1})"


@atomic_file_writer
def write_csv(trace: Trace, path: str | Path, *, float_format: str = _FLOAT_FORMAT) -> Path:
    """Write a trace to CSV.

    Parameters
    ----------
    trace : Trace
        Trace to write; every signal present is written, in canonical order and units
        (s, mA, Hz, bar, °C).
    path : path-like
        Destination file. An existing file is replaced atomically: the new one is
        written to a temporary sibling and renamed into place, so a failure leaves
        the earlier file as it was.
    float_format : str, optional
        printf-style format of the values. The default ``"%.9g"`` keeps 9 significant digits
        (relative rounding error at most 5e-9). If it would make ``time_s`` not strictly
        increasing (very long, finely sampled logs), ``time_s`` is written with ``"%.17g"``.

    Returns
    -------
    pathlib.Path
        The file written.
    """
    if not isinstance(trace, Trace):
        raise TypeError(f"write_csv expects a Trace, got {type(trace)!r}")
    path = Path(path)
    names = [n for n in CANONICAL_ORDER if trace.has(n)]
    columns: list[list[str]] = []
    for name in names:
        values = trace.signals[name]
        text = [float_format % v for v in values.tolist()]
        if name == "time_s" and text:
            back = np.array([float(s) for s in text])
            if np.any(np.diff(back) <= 0):
                text = [_EXACT_FORMAT % v for v in values.tolist()]
        columns.append(text)
    with path.open("w", encoding="utf-8", newline="") as fh:
        fh.write(",".join(names) + "\n")
        fh.writelines(",".join(row) + "\n" for row in zip(*columns, strict=True))
    return path


@dataclass(frozen=True)
class CsvLimits:
    """Resource limits of the CSV reader (a hostile or broken file fails fast and small).

    Attributes
    ----------
    max_columns : int
        Most columns a header may have (``CLUTCHLAB_CSV_MAX_COLUMNS``; default 10 000).
    max_header_bytes : int
        Longest header line, bytes (``CLUTCHLAB_CSV_MAX_HEADER_BYTES``; default 1 MiB).
    """

    max_columns: int = 10_000
    max_header_bytes: int = 1 << 20

    @classmethod
    def from_env(cls) -> CsvLimits:
        """The limits, each raised by its environment variable when set."""
        kw = {}
        for field_, env in (
            ("max_columns", "CLUTCHLAB_CSV_MAX_COLUMNS"),
            ("max_header_bytes", "CLUTCHLAB_CSV_MAX_HEADER_BYTES"),
        ):
            if os.environ.get(env, "").strip().isdigit():
                kw[field_] = int(os.environ[env])
        return cls(**kw)


def _nul_offset(path: Path) -> int | None:
    """Byte offset of the first NUL byte in ``path`` (a binary file), or None."""
    with path.open("rb") as fh:
        offset = 0
        while chunk := fh.read(1 << 20):
            at = chunk.find(b"\0")
            if at >= 0:
                return offset + at
            offset += len(chunk)
    return None


def _read_header(path: Path, limits: CsvLimits) -> list[str]:
    """First line of ``path`` as column names (BOM and surrounding whitespace stripped)."""
    nul = _nul_offset(path)
    if nul is not None:
        with path.open("rb") as fh:
            line = fh.read(nul).count(b"\n") + 1
        raise DataError(
            f"{path}: NUL byte at byte {nul} (line {line}): not a text CSV file (binary or damaged)"
        )
    with path.open("rb") as fh:
        raw = fh.readline(limits.max_header_bytes + 1)
    if len(raw) > limits.max_header_bytes and not raw.endswith(b"\n"):
        raise DataError(
            f"{path}: header line longer than {limits.max_header_bytes} bytes (raise the "
            "limit with CLUTCHLAB_CSV_MAX_HEADER_BYTES if the file is right)"
        )
    try:
        text = raw.decode("utf-8-sig")
        row = next(csv.reader([text]), None) if text.strip() else None
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not a UTF-8 text CSV file ({exc})") from None
    except csv.Error as exc:
        raise DataError(f"{path}: malformed CSV header ({exc})") from None
    if row is None:
        raise DataError(f"{path}: empty file (no header, no data rows)")
    if len(row) > limits.max_columns:
        raise DataError(
            f"{path}: {len(row)} columns in the header, more than the limit of "
            f"{limits.max_columns} (raise it with CLUTCHLAB_CSV_MAX_COLUMNS if the file is right)"
        )
    return [c.strip() for c in row]


def _split_unit(header: str) -> tuple[str, str | None]:
    match = _UNIT_HEADER.match(header)
    if match and match["name"]:
        return match["name"], match["unit"].strip() or None
    return header, None


def _last_line(path: Path) -> str:
    """Text of the last non-blank line of ``path`` (read from the end of the file)."""
    with path.open("rb") as fh:
        fh.seek(0, 2)
        size = fh.tell()
        chunk = 1 << 16
        while True:
            fh.seek(max(size - chunk, 0))
            lines = [ln for ln in fh.read().splitlines() if ln.strip()]
            if len(lines) >= 2 or chunk >= size:
                break
            chunk *= 4
    return lines[-1].decode("utf-8", errors="replace") if lines else ""


def decode_csv(path: str | Path, wanted: Callable[[str], bool] | None = None) -> RawLog:
    """Decode a CSV log into named float64 columns (no mapping, no validation of values).

    Parameters
    ----------
    path : path-like
        Comma-separated text file with a header line. Empty cells and ``NaN`` are NaN.
    wanted : callable, optional
        Ignored (every column is parsed); accepted for a uniform decoder signature.

    Returns
    -------
    RawLog
        One :class:`~clutchlab.data.rawlog.RawChannel` per column; rows named by file line.

    Raises
    ------
    DataError
        Missing, empty, non-UTF-8 or malformed file, duplicate or empty column names,
        a truncated last line; unparseable cells are listed in ``RawLog.problems``.
    """
    path = check_input_file(path)

    header = _read_header(path, CsvLimits.from_env())
    problems: list[str] = []
    names_units = [_split_unit(h) for h in header]
    names = [n for n, _ in names_units]
    dupes = sorted(c for c, k in Counter(names).items() if k > 1)
    if dupes:
        problems.append(f"{path}: duplicate column(s) {', '.join(map(repr, dupes))}")
    empty = [i + 1 for i, c in enumerate(names) if not c]
    if empty:
        problems.append(f"{path}: empty column name at position(s) {', '.join(map(str, empty))}")
    if len(header) == 1 and any(sep in header[0] for sep in ";\t"):
        problems.append(f"{path}: one column {header[0]!r}; the file must be comma-separated")
    if problems:
        raise DataError(f"{path}: bad CSV header", problems)

    try:
        columns, problems, unparseable = _parse_values(path, header)
        n = next(iter(columns.values())).size
        fields = len(next(csv.reader([_last_line(path)]), []))
    except csv.Error as exc:  # e.g. a field longer than the csv module's field size limit
        raise DataError(f"{path}: malformed CSV ({exc})") from None
    if fields < len(header):
        problems.append(
            f"{path}: file truncated: {_line_label(n - 1)} has {fields} of {len(header)} fields"
        )
    channels = [
        RawChannel(name, columns[h], unit, where=f"column {name!r}", reported=unparseable.get(h))
        for h, (name, unit) in zip(header, names_units, strict=True)
    ]
    return RawLog(path, "csv", channels, row_label=_line_label, problems=problems)


def read_csv(
    path: str | Path,
    name: str | None = None,
    meta: Mapping[str, Any] | None = None,
    *,
    channel_map: ChannelMap | str | Path | None = None,
    options: ReadOptions | None = None,
) -> Trace:
    """Read one experiment from a CSV file.

    Parameters
    ----------
    path : path-like
        CSV file: header line, comma-separated numeric values. Without ``channel_map`` the
        columns must be canonical names in canonical units (s, mA, Hz, bar, °C).
    name : str, optional
        Trace name; defaults to the file stem.
    meta : dict, optional
        Trace metadata (e.g. from the dataset manifest).
    channel_map : ChannelMap or path-like, optional
        Source column → canonical signal with units (see :mod:`clutchlab.data.channel_map`).
    options : ReadOptions, optional
        Gap interpolation, resampling and jitter tolerance.

    Returns
    -------
    Trace
        With ``source`` set to ``path``.

    Raises
    ------
    DataError
        Naming the file and listing every problem, each with column and line (see
        :func:`~clutchlab.data.reading.read_log`).
    """
    from .reading import read_log

    return read_log(
        path, name=name, meta=meta, channel_map=channel_map, options=options, format="csv"
    )[0]


def _long_rows(path: Path, n_fields: int) -> list[str]:
    """Problems naming the lines with more fields than the header (data would be lost)."""
    bad = []
    with path.open("r", encoding="utf-8-sig", errors="replace", newline="") as fh:
        for line_no, row in enumerate(csv.reader(fh), start=1):
            if line_no > 1 and len(row) > n_fields:
                bad.append(f"line {line_no} (data row {line_no - 1}) has {len(row)} fields")
    shown = ", ".join(bad[:_MAX_ROWS_LISTED]) + (f" … ({len(bad)} lines)" if len(bad) > 5 else "")
    return [f"{path}: more fields than the {n_fields} columns of the header at {shown}"]


def _parse_values(
    path: Path, header: list[str]
) -> tuple[dict[str, np.ndarray], list[str], dict[str, np.ndarray]]:
    """Parse the data rows of ``path`` into float64 columns named by ``header``.

    Unparseable cells become NaN and are listed, by column and line, in the returned problems
    (and flagged in the returned masks, by column).

    The fast path parses floats in the C engine; only if that fails are the values re-read
    as text to name every unparseable cell by column and line.
    """
    import pandas as pd

    options: dict[str, Any] = {
        "encoding": "utf-8-sig",
        "skipinitialspace": True,
        "skip_blank_lines": False,  # keep line numbers = data row + 2
        "keep_default_na": False,
        "na_values": _NA_VALUES,
        "header": 0,
        "names": header,
        "index_col": False,
    }
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", pd.errors.ParserWarning)
            try:
                df = pd.read_csv(path, dtype=np.float64, **options)
                text = None
            except ValueError as exc:
                if isinstance(exc, pd.errors.ParserError):
                    raise
                text = pd.read_csv(path, dtype=str, **{**options, "na_values": None}).fillna("")
                df = text
    except pd.errors.ParserWarning:  # a row has more fields than the header
        raise DataError(f"{path}: malformed CSV", _long_rows(path, len(header))) from None
    except (pd.errors.ParserError, csv.Error, UnicodeDecodeError, ValueError) as exc:
        reason = " ".join(str(exc).split())
        raise DataError(f"{path}: malformed CSV ({type(exc).__name__}: {reason})") from None
    # Blank lines at the end of the file are not data rows.
    filled = df.notna().any(axis=1).to_numpy() if text is None else (text != "").any(axis=1)
    filled = np.asarray(filled, dtype=bool)
    n = int(np.flatnonzero(filled)[-1]) + 1 if filled.any() else 0
    if n == 0:
        raise DataError(f"{path}: empty file (header but no data rows)")
    if text is None:
        return {col: df[col].to_numpy(dtype=np.float64)[:n] for col in header}, [], {}

    problems: list[str] = []
    signals: dict[str, np.ndarray] = {}
    masks: dict[str, np.ndarray] = {}
    for col in header:
        cells = text[col].iloc[:n].str.strip()
        missing = cells.isin(_NA_VALUES)
        values = pd.to_numeric(cells.where(~missing, "nan"), errors="coerce").to_numpy(
            dtype=np.float64
        )
        unparseable = np.isnan(values) & ~missing.to_numpy()
        bad = np.flatnonzero(unparseable)
        if bad.size:
            masks[col] = unparseable
            shown = ", ".join(
                f"{_line_label(int(i))} {cells.iloc[int(i)]!r}" for i in bad[:_MAX_ROWS_LISTED]
            )
            more = f" … ({bad.size} in total)" if bad.size > _MAX_ROWS_LISTED else ""
            label = _split_unit(col)[0]
            problems.append(f"{path}: column {label!r}: unparseable number at {shown}{more}")
        signals[col] = values
    return signals, problems, masks
