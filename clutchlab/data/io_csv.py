"""CSV reader and writer.

File layout: one header line of column names, then one line per sample, comma-separated.
Files read here may also be separated by semicolons or tabs, with a decimal point or a
decimal comma (the export of a spreadsheet or a data logger in a German or French locale:
``Zeit;I_soll;P_K`` / ``0,001;250,0;3,52``): the separator is the header's most frequent of
the three, the decimal comma is recognized in the first data lines. Files written here carry
canonical signal names (see :data:`~clutchlab.data.signals.CANONICAL_ORDER`) in canonical
units. Files read here may carry any names (mapped by a
:class:`~clutchlab.data.channel_map.ChannelMap`), optionally with a unit in brackets
(``P_clutch [kPa]``) or in parentheses (``P_clutch (kPa)``, only a known unit: ``P(clutch)``
is a name). Line numbers in messages are the file's line numbers
(the header is line 1, the first data row is line 2).
"""

from __future__ import annotations

import csv
import os
import re
import warnings
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import DataError
from .output import atomic_file_writer
from .paths import check_input_file
from .rawlog import RawChannel, RawLog
from .signals import CANONICAL_ORDER
from .trace import _MAX_ROWS_LISTED, Trace
from .units import split_header_unit

if TYPE_CHECKING:
    from .channel_map import ChannelMap
    from .options import ReadOptions

__all__ = ["decode_csv", "read_csv", "write_csv"]

_FLOAT_FORMAT = "%.9g"
#: Used for ``time_s`` when ``float_format`` would merge neighbouring sample times.
_EXACT_FORMAT = "%.17g"
#: Cell texts read as NaN (a missing value), not as unparseable.
_NA_VALUES = ("", "nan", "NaN", "NAN")


#: A clock time as loggers export it: ``12:34:56.789``, optionally after an ISO date.
_CLOCK = re.compile(
    r"^(?P<date>\d{4}-\d{2}-\d{2}[ T])?(?P<h>\d{1,2}):(?P<m>\d{2}):(?P<s>\d{2}(?:[.,]\d+)?)$"
)


#: A step back (s) of an undated clock time that is read as passing midnight: more than half a
#: day (a test-stand log is sampled far faster; a clock set back is not a midnight).
_MIDNIGHT_STEP_S = 43200.0


def _clock_seconds(
    path: Path, header: list[str], column: str, n: int, dialect: CsvDialect
) -> np.ndarray | None:
    """Seconds since the first sample of a column of clock times (``12:34:56.789``, or
    ``2026-11-30 12:34:56.789``), or None when a non-empty cell of its first ``n`` rows is
    not one. Empty cells are NaN (reported as missing values). Without a date, a clock that
    goes back by more than half a day has passed midnight (``23:59:59.999`` →
    ``00:00:00.000`` is 1 ms)."""
    import pandas as pd

    cells = pd.read_csv(
        path,
        dtype=str,
        header=0,
        names=header,
        usecols=[column],
        sep=dialect.sep,
        encoding=dialect.encoding,
        keep_default_na=False,
        skip_blank_lines=False,
        index_col=False,
    )[column].iloc[:n]
    cells = cells.fillna("").str.strip()
    present = cells != ""
    if not present.any():
        return None
    parts = cells[present].str.extract(_CLOCK)
    if parts["h"].isna().any():
        return None
    secs = (
        parts["h"].astype(float) * 3600.0
        + parts["m"].astype(float) * 60.0
        + parts["s"].str.replace(",", ".", regex=False).astype(float)
    )
    dated = parts["date"].notna()
    if dated.any():
        if not dated.all():
            return None
        days = pd.to_datetime(parts["date"].str.strip(), format="%Y-%m-%d").to_numpy()
        days = (days - days[0]) / np.timedelta64(1, "D")
        secs = secs + 86400.0 * days
    else:  # no date: a clock that goes back by more than half a day passed midnight
        steps = np.diff(secs.to_numpy(dtype=float), prepend=float(secs.iloc[0]))
        secs = secs + 86400.0 * np.cumsum(steps < -_MIDNIGHT_STEP_S)
    out = np.full(n, np.nan)
    out[present.to_numpy()] = secs.to_numpy(dtype=float)
    first = out[np.isfinite(out)][0]
    return out - first


def _unnamed(i: int) -> str:
    """Placeholder name of the 0-based column ``i`` when its header is empty."""
    return f"(unnamed column {i + 1})"


def _line_label(i: int) -> str:
    """Name the 0-based data row ``i`` by its line in the file (header = line 1)."""
    return f"line {i + 2} (data row {i + 1})"


#: A number written with a decimal comma (``-3,52``, ``1,5e-3``).
_DECIMAL_COMMA = re.compile(r"^\s*[-+]?\d+,\d+(?:[eE][-+]?\d+)?\s*$")
#: Data lines looked at for a decimal comma.
_SNIFF_LINES = 50


@dataclass(frozen=True)
class CsvDialect:
    """How a CSV file separates its fields and writes its decimals.

    Attributes
    ----------
    sep : {",", ";", "\\t"}
        Field separator.
    decimal : {".", ","}
        Decimal mark (a comma only with another separator than the comma).
    encoding : {"utf-8-sig", "cp1252"}
        Text encoding: UTF-8 (with or without a byte-order mark), or Windows-1252 when the
        header is not UTF-8 (a spreadsheet's "CSV" export on Windows, ``T_Öl [°C]``).
    """

    sep: str = ","
    decimal: str = "."
    encoding: str = "utf-8-sig"

    def describe(self) -> str:
        """``"semicolon-separated, decimal comma"``."""
        sep = {",": "comma", ";": "semicolon", "\t": "tab"}[self.sep]
        text = f"{sep}-separated, decimal {'comma' if self.decimal == ',' else 'point'}"
        if self.encoding != "utf-8-sig":
            text += ", Windows-1252 text (not UTF-8)"
        return text


def _sniff_dialect(header: str, path: Path) -> CsvDialect:
    """The separator most frequent in the header line (the comma on a tie or when none is
    there), and a decimal comma when another separator leaves commas inside numbers of the
    first data lines."""
    counts = {sep: header.count(sep) for sep in (",", ";", "\t")}
    sep = max(counts, key=lambda k: (counts[k], k == ","))
    if counts[sep] == 0 or sep == ",":
        return CsvDialect()
    with path.open("r", encoding="utf-8-sig", errors="replace", newline="") as fh:
        next(fh, None)
        for _, line in zip(range(_SNIFF_LINES), fh, strict=False):
            if any(_DECIMAL_COMMA.match(field) for field in line.rstrip("\r\n").split(sep)):
                return CsvDialect(sep, ",")
    return CsvDialect(sep, ".")


#: Largest error of a written sample time, as a fraction of the smallest sample interval.
TIME_TEXT_TOLERANCE = 1e-3


def _time_text_exact(values: np.ndarray, text: list[str]) -> bool:
    """Whether ``text`` holds every sample time to :data:`TIME_TEXT_TOLERANCE` of a step."""
    values = np.asarray(values, dtype=float)
    back = np.array([float(s) for s in text])
    steps = np.diff(values)
    if steps.size == 0:
        return bool(np.all(back == values))
    error = float(np.max(np.abs(back - values)))
    return bool(np.all(np.diff(back) > 0)) and error <= TIME_TEXT_TOLERANCE * float(steps.min())


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
        (relative rounding error at most 5e-9). If it would move a ``time_s`` sample by more
        than :data:`TIME_TEXT_TOLERANCE` of the smallest sample interval (a late start time, a
        fast logger), ``time_s`` is written with ``"%.17g"`` (exact).

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
        if name == "time_s" and text and not _time_text_exact(values, text):
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


def _read_header(path: Path, limits: CsvLimits) -> tuple[list[str], CsvDialect]:
    """First line of ``path`` as column names (BOM and surrounding whitespace stripped), and
    the file's dialect."""
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
    encoding = "utf-8-sig"
    try:
        try:
            text = raw.decode(encoding)
        except UnicodeDecodeError as exc:
            try:  # a spreadsheet's export on Windows: "T_Öl [°C]" in Windows-1252
                text, encoding = raw.decode("cp1252"), "cp1252"
            except UnicodeDecodeError:
                raise exc from None
        dialect = replace(_sniff_dialect(text, path), encoding=encoding)
        row = next(csv.reader([text], delimiter=dialect.sep), None) if text.strip() else None
    except UnicodeDecodeError as exc:
        raise DataError(
            f"{path}: not a UTF-8 (or Windows-1252) text CSV file: line 1 ({exc})"
        ) from None
    except csv.Error as exc:
        raise DataError(f"{path}: malformed CSV header ({exc})") from None
    if row is None:
        raise DataError(f"{path}: empty file (no header, no data rows)")
    if len(row) > limits.max_columns:
        raise DataError(
            f"{path}: {len(row)} columns in the header, more than the limit of "
            f"{limits.max_columns} (raise it with CLUTCHLAB_CSV_MAX_COLUMNS if the file is right)"
        )
    return [c.strip() for c in row], dialect


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
        ``wanted(name)`` tells whether a column is needed. Every column is parsed, but
        unparseable cells are problems only in wanted columns; another column with text in it
        (a comment, a status) is returned as not numeric. None: every column is wanted.

    Returns
    -------
    RawLog
        One :class:`~clutchlab.data.rawlog.RawChannel` per column; rows named by file line.

    Raises
    ------
    DataError
        Missing, empty, non-UTF-8 or malformed file, duplicate column names, a column
        without a name that holds values (an empty one is ignored, with a note),
        a truncated last line; unparseable cells are listed in ``RawLog.problems``.
    """
    path = check_input_file(path)

    header, dialect = _read_header(path, CsvLimits.from_env())
    problems: list[str] = []
    names_units = [split_header_unit(h, wanted) for h in header]
    # A column without a name (a trailing separator on every line, a blank spreadsheet
    # column) is read under a placeholder: dropped below if it is empty, else a problem.
    unnamed = {i for i, (n, _) in enumerate(names_units) if not n}
    for i in unnamed:
        header[i] = _unnamed(i)
        names_units[i] = (header[i], None)
    names = [n for n, _ in names_units]
    dupes = sorted(c for c, k in Counter(names).items() if k > 1)
    for name in dupes:  # named by the headers that clash: they may differ only in the unit
        clash = [h for h, n in zip(header, names, strict=True) if n == name]
        shown = "" if len(set(clash)) == 1 else f" (headers {', '.join(map(repr, clash))})"
        problems.append(f"{path}: duplicate column {name!r}{shown}")
    if problems:
        raise DataError(f"{path}: bad CSV header", problems)

    try:
        columns, by_column, unparseable = _parse_values(
            path, header, dict(zip(header, names, strict=True)), dialect
        )
        n = next(iter(columns.values())).size
        fields = len(next(csv.reader([_last_line(path)], delimiter=dialect.sep), []))
        # unnamed columns at the end (a separator after the last header only) may be absent
        # from a row: nothing lands in a wrong column then
        trailing = 0
        while trailing < len(header) and len(header) - 1 - trailing in unnamed:
            trailing += 1
        needed = len(header) - trailing
        # a row with fewer fields reads as NaN in its last needed column: only a file with a
        # missing value there is scanned for short rows (the scan re-reads the whole file)
        gaps = needed > 0 and bool(np.isnan(columns[header[needed - 1]]).any())
        short = _short_rows(path, needed, n, dialect.sep) if gaps else []
    except csv.Error as exc:  # e.g. a field longer than the csv module's field size limit
        raise DataError(f"{path}: malformed CSV ({exc})") from None
    if fields < needed:
        problems.append(
            f"{path}: file truncated: {_line_label(n - 1)} has {fields} of {len(header)} fields"
        )
        short = [line for line in short if line != n - 1]
    if short:
        shown = ", ".join(_line_label(i) for i in short[:_MAX_ROWS_LISTED])
        more = f" … ({len(short)} lines)" if len(short) > _MAX_ROWS_LISTED else ""
        problems.append(
            f"{path}: fewer fields than the {len(header)} columns of the header at {shown}{more} "
            "(a value is missing, so the values after it would land in the wrong columns)"
        )
    clock_notes = []
    converted: dict[str, str] = {}
    for h in list(by_column):
        name = dict(zip(header, names, strict=True))[h]
        if wanted is not None and not wanted(name):
            continue
        seconds = _clock_seconds(path, header, h, n, dialect)
        if seconds is not None:  # a logger's clock time: seconds since its first sample
            columns[h] = seconds
            del by_column[h]
            unparseable.pop(h, None)
            converted[h] = "a clock time (hh:mm:ss.fff)"
            clock_notes.append(
                f"{path}: column {name!r}: clock times read as seconds since its first sample"
            )
    channels = []
    short_mask = np.isin(np.arange(n), short) if short else None
    dropped = []
    for i in sorted(unnamed):
        h = header[i]
        values = columns[h]
        if h not in by_column and np.isnan(values).all():
            dropped.append(i + 1)
            continue
        first = int(np.flatnonzero(~np.isnan(values))[0]) if h not in by_column else None
        at = f" (first at {_line_label(first)})" if first is not None else ""
        problems.append(
            f"{path}: column {i + 1} has no name in the header but holds values{at}; name it "
            "in the header (and in the channel map) or remove it"
        )
    for i, (h, (name, unit)) in enumerate(zip(header, names_units, strict=True)):
        if i in unnamed:
            continue
        where = f"column {name!r}"
        if h in by_column and wanted is not None and not wanted(name):
            # A column nobody asked for (a comment, a status text) does not fail the file.
            channels.append(RawChannel(name, None, unit, where=where, problem="not numeric"))
            continue
        if h in by_column:
            problems.append(by_column[h])
        reported = unparseable.get(h)
        if short_mask is not None:  # already reported: not again as missing values
            reported = short_mask if reported is None else reported | short_mask
        if h in converted:
            channels.append(
                RawChannel(
                    name, columns[h], "s", where=where, reported=reported, converted=converted[h]
                )
            )
            continue
        channels.append(RawChannel(name, columns[h], unit, where=where, reported=reported))
    notes = [] if dialect == CsvDialect() else [f"{path}: read as {dialect.describe()}"]
    notes += clock_notes
    if dropped:
        notes.append(
            f"{path}: column(s) {', '.join(map(str, dropped))} without a name and without values "
            "ignored (a trailing separator or a blank spreadsheet column)"
        )
    return RawLog(path, "csv", channels, row_label=_line_label, problems=problems, notes=notes)


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


def _short_rows(path: Path, n_fields: int, n_rows: int, sep: str = ",") -> list[int]:
    """0-based data rows (of the first ``n_rows``) with fewer fields than the header.

    Blank lines are left out (they read as rows of missing values, reported as such). Counts
    separators in bulk; a file with quotes, where a comma may be inside a field, is read
    with the ``csv`` module instead.
    """
    data = path.read_bytes()
    if b'"' in data:
        short = []
        with path.open("r", encoding="utf-8-sig", errors="replace", newline="") as fh:
            for i, row in enumerate(csv.reader(fh, delimiter=sep)):
                if 0 < i <= n_rows and 0 < len(row) < n_fields and any(c.strip() for c in row):
                    short.append(i - 1)
        return short
    raw = np.frombuffer(data, dtype=np.uint8)
    ends = np.flatnonzero(raw == ord("\n"))
    if not ends.size or ends[-1] != raw.size - 1:
        ends = np.append(ends, raw.size)
    ends = ends[1 : n_rows + 1]  # line 1 is the header
    starts = np.concatenate(([0], np.flatnonzero(raw == ord("\n"))))[1 : ends.size + 1] + 1
    commas = np.flatnonzero(raw == ord(sep))
    fields = np.searchsorted(commas, ends) - np.searchsorted(commas, starts) + 1
    short = []
    for row in np.flatnonzero(fields < n_fields):
        if data[starts[row] : ends[row]].strip():  # a blank line is not a short row
            short.append(int(row))
    return short


def _long_rows(path: Path, n_fields: int, sep: str = ",") -> list[str]:
    """Problems naming the lines with more fields than the header (data would be lost)."""
    bad = []
    with path.open("r", encoding="utf-8-sig", errors="replace", newline="") as fh:
        for line_no, row in enumerate(csv.reader(fh, delimiter=sep), start=1):
            if line_no > 1 and len(row) > n_fields:
                bad.append(f"line {line_no} (data row {line_no - 1}) has {len(row)} fields")
    shown = ", ".join(bad[:_MAX_ROWS_LISTED]) + (f" … ({len(bad)} lines)" if len(bad) > 5 else "")
    return [f"{path}: more fields than the {n_fields} columns of the header at {shown}"]


def _parse_values(
    path: Path, header: list[str], labels: Mapping[str, str], dialect: CsvDialect = CsvDialect()
) -> tuple[dict[str, np.ndarray], dict[str, str], dict[str, np.ndarray]]:
    """Parse the data rows of ``path`` into float64 columns named by ``header``.

    ``labels`` names each header's column in messages (its name without the unit).

    Unparseable cells become NaN and are listed, by line, in the returned problems (one per
    column, keyed by header) and flagged in the returned masks, by column.

    The fast path parses floats in the C engine; only if that fails are the values re-read
    as text to name every unparseable cell by column and line.
    """
    import pandas as pd

    options: dict[str, Any] = {
        "encoding": dialect.encoding,
        "skipinitialspace": True,
        "skip_blank_lines": False,  # keep line numbers = data row + 2
        "keep_default_na": False,
        "na_values": _NA_VALUES,
        "header": 0,
        "names": header,
        "index_col": False,
        "sep": dialect.sep,
        "decimal": dialect.decimal,
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
        raise DataError(
            f"{path}: malformed CSV", _long_rows(path, len(header), dialect.sep)
        ) from None
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
        return {col: df[col].to_numpy(dtype=np.float64)[:n] for col in header}, {}, {}

    problems: dict[str, str] = {}
    signals: dict[str, np.ndarray] = {}
    masks: dict[str, np.ndarray] = {}
    for col in header:
        cells = text[col].iloc[:n].str.strip()
        missing = cells.isin(_NA_VALUES)
        numbers = cells.str.replace(",", ".", regex=False) if dialect.decimal == "," else cells
        values = pd.to_numeric(numbers.where(~missing, "nan"), errors="coerce").to_numpy(
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
            label = labels[col]
            problems[col] = f"{path}: column {label!r}: unparseable number at {shown}{more}"
        signals[col] = values
    return signals, problems, masks
