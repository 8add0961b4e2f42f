"""Convert a dataset folder or a single log to canonical names and units in another format.

Everything is read and validated first; only then is anything written, atomically (a
temporary sibling renamed into place), so a failed conversion leaves no partial output.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from ..errors import DataError
from .channel_map import ChannelMapLike
from .formats import FORMATS, suffix_of
from .io_dataset import load_dataset, save_dataset
from .manifest import MANIFEST_NAME
from .options import ReadOptions
from .reading import read_log
from .trace import Trace

__all__ = ["convert"]


def _write_file_atomically(trace: Trace, dst: Path, suffix: str) -> None:
    dst.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{dst.name}.", suffix=".tmp", dir=dst.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        FORMATS[suffix].write(trace, tmp)
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)
        os.replace(tmp, dst)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def convert(
    src: str | Path,
    dst: str | Path,
    *,
    format: str | None = None,
    channel_map: ChannelMapLike = None,
    options: ReadOptions | None = None,
    overwrite: bool = False,
) -> Path:
    """Convert a dataset folder, or one log file, into canonical names and units.

    Parameters
    ----------
    src : path-like
        Dataset folder (or its ``manifest.json``), or a single ``.csv`` / ``.parquet`` /
        ``.mf4`` log.
    dst : path-like
        Destination folder (for a dataset) or file (for a single log).
    format : {"csv", "parquet", "mf4"}, optional
        Output format; default ``"csv"`` for a dataset, the suffix of ``dst`` for a file.
    channel_map : ChannelMap, path-like or mapping, optional
        Source channel → canonical signal with units and defaults.
    options : ReadOptions, optional
        Gap interpolation, resampling, jitter tolerance.
    overwrite : bool, optional
        Replace an existing destination (a dataset folder with a manifest, or a file).

    Returns
    -------
    pathlib.Path
        The destination.

    Raises
    ------
    DataError
        Listing every problem of the input (nothing is written then), an unsupported format,
        or a destination that exists (without ``overwrite``).
    """
    src, dst = Path(src), Path(dst)
    if src.is_file() and src.name != MANIFEST_NAME:
        suffix = suffix_of(format) if format is not None else dst.suffix.lower()
        if suffix not in FORMATS:
            raise DataError(
                f"{dst}: cannot tell the output format from the suffix {dst.suffix!r}; pass "
                f"format= one of {', '.join(f.name for f in FORMATS.values())}"
            )
        if dst.suffix.lower() != suffix:
            raise DataError(
                f"{dst}: the suffix does not match the format {FORMATS[suffix].name!r} "
                f"(expected {suffix})"
            )
        if dst.exists() and (dst.is_dir() or not overwrite):
            raise DataError(f"{dst}: exists (pass overwrite=True to replace a file)")
        if dst.resolve() == src.resolve():
            raise DataError(f"{dst}: is the source file")
        trace = read_log(src, channel_map=channel_map, options=options)[0]
        _write_file_atomically(trace, dst, suffix)
        return dst
    dataset = load_dataset(src, channel_map, options=options)
    return save_dataset(dataset, dst, format or "csv", overwrite=overwrite)
