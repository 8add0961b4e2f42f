"""CSV reader and writer for traces with canonical column names.

File layout: one header line with canonical signal names (see
:data:`~clutchlab.data.signals.CANONICAL_ORDER`), then one line per sample, comma-separated,
values in the canonical units. Line numbers in error messages are the file's line numbers
(the header is line 1, the first data row is line 2).
"""

from __future__ import annotations

import csv
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from .signals import CANONICAL_ORDER, SIGNALS
from .trace import _MAX_ROWS_LISTED, Trace, _check_signals, _unknown_names_problem

__all__ = ["read_csv", "write_csv"]

_FLOAT_FORMAT = "%.9g"
#: Used for ``time_s`` when ``float_format`` would merge neighbouring sample times.
_EXACT_FORMAT = "%.17g"
#: Cell texts read as NaN (a missing value), not as unparseable.
_NA_VALUES = ("", "nan", "NaN", "NAN")


def _line_label(i: int) -> str:
    """Name the 0-based data row ``i`` by its line in the file (header = line 1)."""
    return f"line {i + 2} (data row {i + 1})"


def write_csv(trace: Trace, path: str | Path, *, float_format: str = _FLOAT_FORMAT) -> Path:
    """Write a trace to CSV.

    Parameters
    ----------
    trace : Trace
        Trace to write; every signal present is written, in canonical order and units
        (s, mA, Hz, bar, °C).
    path : path-like
        Destination file; overwritten if it exists.
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


def _read_header(path: Path) -> list[str]:
    """First line of ``path`` as column names (BOM and surrounding whitespace stripped)."""
    try:
        with path.open("r", encoding="utf-8-sig", newline="") as fh:
            row = next(csv.reader(fh), None)
    except UnicodeDecodeError as exc:
        raise DataError(f"{path}: not a UTF-8 text CSV file ({exc})") from None
    if row is None:
        raise DataError(f"{path}: empty file (no header, no data rows)")
    return [c.strip() for c in row]


def read_csv(
    path: str | Path,
    name: str | None = None,
    meta: Mapping[str, Any] | None = None,
) -> Trace:
    """Read a trace from a CSV file with canonical column names.

    Parameters
    ----------
    path : path-like
        CSV file: header of canonical names, comma-separated numeric values in canonical
        units (s, mA, Hz, bar, °C). Empty cells and ``NaN`` are read as NaN.
    name : str, optional
        Trace name; defaults to the file stem.
    meta : dict, optional
        Trace metadata (e.g. from the dataset manifest).

    Returns
    -------
    Trace
        With ``source`` set to ``path``.

    Raises
    ------
    DataError
        Naming the file and listing every problem: missing file, empty file or no data rows,
        non-canonical / duplicate / missing columns, unparseable values (column and line),
        non-finite or non-increasing time (line).
    """
    path = Path(path)
    name = path.stem if name is None else name
    if not path.exists():
        raise DataError(f"{path}: file not found")
    if not path.is_file():
        raise DataError(f"{path}: not a file")

    header = _read_header(path)
    problems: list[str] = []
    dupes = sorted({c for c in header if header.count(c) > 1})
    if dupes:
        problems.append(f"{path}: duplicate column(s) {', '.join(map(repr, dupes))}")
    unknown = [c for c in dict.fromkeys(header) if c not in SIGNALS]
    if unknown:
        problem = _unknown_names_problem(unknown, str(path))
        if len(header) == 1 and any(sep in header[0] for sep in ";\t"):
            problem += " (the file must be comma-separated)"
        problems.append(problem)
    if problems:
        raise DataError(f"{path}: bad CSV header", problems)

    signals, problems = _parse_values(path, header)
    problems += _check_signals(signals, str(path), row_label=_line_label)[1]
    if problems:
        raise DataError(f"{path}: invalid CSV", problems)
    return Trace(name, signals, meta=meta, source=path)


def _parse_values(path: Path, header: list[str]) -> tuple[dict[str, np.ndarray], list[str]]:
    """Parse the data rows of ``path`` into float64 columns named by ``header``.

    Unparseable cells become NaN and are listed, by column and line, in the returned problems.

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
    }
    try:
        df = pd.read_csv(path, dtype=np.float64, **options)
        text = None
    except pd.errors.ParserError as exc:
        raise DataError(f"{path}: malformed CSV ({exc})") from None
    except ValueError:
        df = text = pd.read_csv(path, dtype=str, **{**options, "na_values": None}).fillna("")
    # Blank lines at the end of the file are not data rows.
    filled = df.notna().any(axis=1).to_numpy() if text is None else (text != "").any(axis=1)
    filled = np.asarray(filled, dtype=bool)
    n = int(np.flatnonzero(filled)[-1]) + 1 if filled.any() else 0
    if n == 0:
        raise DataError(f"{path}: empty file (header but no data rows)")
    if text is None:
        return {col: df[col].to_numpy(dtype=np.float64)[:n] for col in header}, []

    problems: list[str] = []
    signals: dict[str, np.ndarray] = {}
    for col in header:
        cells = text[col].iloc[:n].str.strip()
        missing = cells.isin(_NA_VALUES)
        values = pd.to_numeric(cells.where(~missing, "nan"), errors="coerce").to_numpy(
            dtype=np.float64
        )
        bad = np.flatnonzero(np.isnan(values) & ~missing.to_numpy())
        if bad.size:
            shown = ", ".join(
                f"{_line_label(int(i))} {cells.iloc[int(i)]!r}" for i in bad[:_MAX_ROWS_LISTED]
            )
            more = f" … ({bad.size} in total)" if bad.size > _MAX_ROWS_LISTED else ""
            problems.append(f"{path}: column {col!r}: unparseable number at {shown}{more}")
        signals[col] = values
    return signals, problems
