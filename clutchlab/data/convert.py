"""Convert a dataset folder or a single log to canonical names and units in another format.

Everything is read and validated first; only then is anything written, atomically (see
:mod:`clutchlab.data.output`), so a failed or killed conversion leaves no partial output and
no file clutchlab did not write is replaced or deleted. A destination overlapping the source
folder is refused.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import DataError
from .channel_map import ChannelMapLike
from .formats import FORMATS, suffix_of
from .io_dataset import load_dataset, save_dataset
from .manifest import MANIFEST_NAME
from .options import ReadOptions
from .output import check_output, write_file_atomic
from .reading import read_log

__all__ = ["convert"]


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
        Replace an existing file, or write into an existing non-empty folder (what clutchlab
        wrote there is replaced; every other file is kept, and one in the way is an error).

    Returns
    -------
    pathlib.Path
        The destination.

    Raises
    ------
    DataError
        Listing every problem of the input (nothing is written then), an unsupported format,
        or a destination overlapping the source.
    OutputError
        A destination that exists (without ``overwrite``), has a user's file in the way, or
        cannot be written.
    """
    src, dst = Path(src), Path(dst)
    if src.is_file() and src.name != MANIFEST_NAME:
        suffix = suffix_of(format) if format is not None else dst.suffix.lower()
        if suffix not in FORMATS:
            # the file must carry its format's suffix anyway (checked below), so that is
            # the remedy, not format= / --format
            raise DataError(
                f"{dst}: cannot tell the output format from the suffix {dst.suffix!r}; name "
                f"the file with one of the suffixes {', '.join(FORMATS)}"
            )
        if dst.suffix.lower() != suffix:
            raise DataError(
                f"{dst}: the suffix does not match the format {FORMATS[suffix].name!r} "
                f"(expected {suffix})"
            )
        if dst.resolve() == src.resolve():
            raise DataError(f"{dst}: is the source file")
        check_output(dst, kind="file", overwrite=overwrite, what="destination")
        trace = read_log(src, channel_map=channel_map, options=options)[0]
        return write_file_atomic(
            dst, lambda tmp: FORMATS[suffix].write(trace, tmp), overwrite=overwrite
        )
    folder = (src.parent if src.name == MANIFEST_NAME else src).resolve()
    target = dst.resolve()
    if target == folder or folder in target.parents or target in folder.parents:
        raise DataError(
            f"{dst}: the destination overlaps the source dataset folder {src}; convert into "
            "a separate folder (nothing was written)"
        )
    # the folder is swapped in whole: not the current folder (nor one holding it)
    check_output(dst, kind="folder", overwrite=overwrite, what="destination", whole=True)
    dataset = load_dataset(src, channel_map, options=options)
    return save_dataset(dataset, dst, format or "csv", overwrite=overwrite)
