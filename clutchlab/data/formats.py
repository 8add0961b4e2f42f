"""Registry of experiment file formats: file suffix → decoder and writer."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

from ..errors import DataError
from .io_csv import decode_csv, write_csv
from .io_mat import decode_mat, write_mat
from .io_mf4 import decode_mf4, write_mf4
from .io_parquet import decode_parquet, write_parquet
from .rawlog import RawLog
from .trace import Trace

__all__ = ["FORMATS", "FileFormat", "format_of", "suffix_of"]


class FileFormat(NamedTuple):
    """One experiment file format.

    Parameters
    ----------
    name : str
        Format name used by ``save_dataset(..., format=name)`` and the CLI.
    decode : callable
        ``decode(path, wanted) -> RawLog``; ``wanted(channel_name) -> bool`` may limit which
        channels' values are loaded (or be None).
    write : callable
        ``write(trace, path)`` writes one trace in canonical names and units.
    """

    name: str
    decode: Callable[[Path, Callable[[str], bool] | None], RawLog]
    write: Callable[[Trace, Path], Any]


#: File suffix (lower case, with dot) → format. New formats register here.
FORMATS: dict[str, FileFormat] = {
    ".csv": FileFormat("csv", decode_csv, write_csv),
    ".parquet": FileFormat("parquet", decode_parquet, write_parquet),
    ".mf4": FileFormat("mf4", decode_mf4, write_mf4),
    ".mat": FileFormat("mat", decode_mat, write_mat),
}


def _supported() -> str:
    return ", ".join(f"{f.name} ({s})" for s, f in FORMATS.items())


def suffix_of(format: str) -> str:
    """File suffix of a format given by name (``"mf4"``) or suffix (``".mf4"``).

    Raises
    ------
    DataError
        If the format is not registered.
    """
    key = str(format).lower()
    for suffix, fmt in FORMATS.items():
        if key in (fmt.name, suffix, suffix.lstrip(".")):
            return suffix
    raise DataError(f"unsupported dataset format {format!r}; supported: {_supported()}")


def format_of(path: str | Path, format: str | None = None) -> FileFormat:
    """The format of ``path``: ``format`` if given, else by file suffix.

    Raises
    ------
    DataError
        If the format is unknown.
    """
    path = Path(path)
    if format is not None:
        return FORMATS[suffix_of(format)]
    fmt = FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise DataError(
            f"{path}: unsupported file format {path.suffix!r}; supported: {_supported()}"
        )
    return fmt
