"""ASAM MDF4 reader and writer (asammdf).

Written files (MDF 4.10) hold one channel group: the master ``time`` channel (s) and one
float64 channel per canonical signal, each with its unit and description; the trace name and
metadata go to an embedded attachment ``clutchlab.json``. Read files may hold any number of
channel groups at different rates (each group has its own master time base); channels are
aligned on one grid by :mod:`clutchlab.data.assemble`. Invalid samples (MDF invalidation
bits) are read as NaN. Rows are named ``row N`` (1-based record of the channel's group).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import DataError
from .mdf_check import check_mdf4_structure
from .meta_json import embedded_meta_json, parse_embedded_meta
from .output import atomic_file_writer
from .paths import check_input_file
from .rawlog import RawChannel, RawLog, TimeBase
from .signals import CANONICAL_ORDER, SIGNALS
from .trace import Trace

if TYPE_CHECKING:
    from .channel_map import ChannelMap
    from .options import ReadOptions

__all__ = ["decode_mf4", "read_mf4", "write_mf4"]

#: Name of the attachment holding the trace name and metadata.
ATTACHMENT = "clutchlab.json"


def _quiet_asammdf() -> None:
    # asammdf logs every problem of a damaged file at ERROR level; we raise DataError instead.
    logging.getLogger("asammdf").setLevel(logging.CRITICAL)


@atomic_file_writer
def write_mf4(trace: Trace, path: str | Path) -> Path:
    """Write a trace to an MDF 4.10 file.

    Parameters
    ----------
    trace : Trace
        Trace to write: one channel group, master ``time`` (s), one float64 channel per
        canonical signal present with its canonical unit (mA, Hz, bar, °C) and description.
    path : path-like
        Destination file. An existing file is replaced atomically: the new one is
        written to a temporary sibling and renamed into place, so a failure leaves
        the earlier file as it was.

    Returns
    -------
    pathlib.Path
        The file written.
    """
    from asammdf import MDF, Signal

    if not isinstance(trace, Trace):
        raise TypeError(f"write_mf4 expects a Trace, got {type(trace)!r}")
    _quiet_asammdf()
    path = Path(path)
    t = np.asarray(trace.time_s, dtype=np.float64)
    signals = [
        Signal(
            np.asarray(trace.signals[n], dtype=np.float64),
            t,
            unit=SIGNALS[n].unit,
            name=n,
            comment=SIGNALS[n].description,
        )
        for n in CANONICAL_ORDER
        if n != "time_s" and trace.has(n)
    ]
    # asammdf saves a name without an MDF suffix (the atomic writer's temporary) under that
    # name with ``.mf4``; it is moved to ``path`` below, or removed if anything fails.
    renamed = path if path.suffix.lower() == ".mf4" else path.with_suffix(".mf4")
    mdf = MDF(version="4.10")
    try:
        mdf.header.comment = f"clutchlab trace {trace.name}"
        mdf.append(signals, acq_name=trace.name, comment="clutchlab trace", common_timebase=True)
        mdf.attach(
            embedded_meta_json(trace).encode("utf-8"),
            file_name=ATTACHMENT,
            comment="clutchlab trace name and metadata",
            compression=False,
            mime="application/json",
            embedded=True,
        )
        written = Path(mdf.save(path, overwrite=True))
        if written != path:  # asammdf may normalise the suffix; keep the name asked for
            written.replace(path)
    except BaseException:
        if renamed != path:
            renamed.unlink(missing_ok=True)
        raise
    finally:
        mdf.close()
    return path


def _embedded_meta(mdf: Any) -> dict[str, Any] | None:
    for index, att in enumerate(getattr(mdf, "attachments", []) or []):
        if str(getattr(att, "file_name", "")) != ATTACHMENT:
            continue
        data = mdf.extract_attachment(index)[0]
        return parse_embedded_meta(data)
    return None


def decode_mf4(path: str | Path, wanted: Callable[[str], bool] | None = None) -> RawLog:
    """Decode an MDF file into channels with their groups' time bases (no mapping or checks).

    Parameters
    ----------
    path : path-like
        MDF 4 (or 3) file.
    wanted : callable, optional
        ``wanted(name)`` tells whether the samples of a channel are needed; other channels
        are listed (name, unit, group) without samples. Default: every channel.

    Returns
    -------
    RawLog
        One :class:`~clutchlab.data.rawlog.TimeBase` per channel group with samples, one
        channel per non-master channel.

    Raises
    ------
    DataError
        Missing or empty file, no MDF identification block, truncated or corrupt file.
    """
    path = check_input_file(path)
    size = path.stat().st_size
    if size == 0:
        raise DataError(f"{path}: empty file")
    check_mdf4_structure(path)  # a damaged file could crash asammdf's compiled readers
    _quiet_asammdf()
    try:
        return _decode(path, wanted or (lambda name: True))
    except DataError:
        raise
    except Exception as exc:  # asammdf raises many types on damaged input
        reason = f"{type(exc).__name__}: {exc}"
    _collect_broken_mdf()
    raise DataError(f"{path}: not a readable MDF file (truncated or corrupt?): {reason}")


def _collect_broken_mdf() -> None:
    """Collect the half-built MDF object of a failed open now, without its ``__del__`` noise.

    asammdf leaves a partly initialised object in a reference cycle whose ``__del__`` raises
    AttributeError when the garbage collector finally runs (printed as "Exception ignored").
    """
    import gc
    import sys

    previous = sys.unraisablehook

    def hook(unraisable: Any) -> None:
        if "MDF" not in repr(getattr(unraisable, "object", "")):
            previous(unraisable)

    sys.unraisablehook = hook
    try:
        gc.collect()
    finally:
        sys.unraisablehook = previous


def _source_names(block, attr: str) -> tuple[str, ...]:
    """Name and path of an MF4 source block (``block.<attr>``), where written."""
    src = getattr(block, attr, None)
    if src is None:
        return ()
    names = (
        str(getattr(src, "name", "") or "").strip(),
        str(getattr(src, "path", "") or "").strip(),
    )
    return tuple(n for n in names if n)


def _decode(path: Path, wanted: Callable[[str], bool]) -> RawLog:
    from asammdf import MDF

    mdf = MDF(path)
    try:
        bases: list[TimeBase] = []
        channels: list[RawChannel] = []
        base_of_group: dict[int, int] = {}
        selection: list[tuple[RawChannel, int, int]] = []
        for gi, group in enumerate(mdf.groups):
            master = mdf.masters_db.get(gi)
            group_sources = _source_names(group.channel_group, "acq_source")
            acq = str(getattr(group.channel_group, "acq_name", "") or "").strip()
            group_sources = ((acq,) if acq else ()) + group_sources
            for ci, ch in enumerate(group.channels):
                if ci == master:
                    continue
                name = str(ch.name)
                unit = str(getattr(ch, "unit", "") or "").strip() or None
                own = _source_names(ch, "source")
                raw = RawChannel(
                    name,
                    None,
                    unit,
                    where=f"channel {name!r} (group {gi})",
                    problem=None,
                    sources=tuple(dict.fromkeys(group_sources + own)),
                )
                channels.append(raw)
                if wanted(name):
                    selection.append((raw, gi, ci))
                    base_of_group.setdefault(gi, -1)
        for gi in base_of_group:
            t = np.asarray(mdf.get_master(gi), dtype=np.float64)
            base_of_group[gi] = len(bases)
            bases.append(TimeBase(t, f"group {gi}"))
        if selection:
            signals = mdf.select([(None, gi, ci) for _, gi, ci in selection], copy_master=False)
        else:
            signals = []
        for (raw, gi, _), sig in zip(selection, signals, strict=True):
            raw.base = base_of_group[gi]
            raw.unit = str(sig.unit or "").strip() or raw.unit
            raw.values, raw.problem = _samples(sig, bases[raw.base].time_s.size)
        for raw in channels:
            if raw.base is None:
                raw.problem = "not loaded"
        meta = _embedded_meta(mdf)
    finally:
        mdf.close()
    if not channels:
        raise DataError(f"{path}: no data channels (empty measurement)")
    if bases and all(b.time_s.size == 0 for b in bases):
        raise DataError(f"{path}: empty file (no samples in any channel group)")
    return RawLog(path, "mf4", channels, bases=bases, meta=meta, tabular=False)


def _samples(sig: Any, n_time: int) -> tuple[np.ndarray | None, str | None]:
    samples = np.asarray(sig.samples)
    if samples.dtype.names is not None or samples.ndim != 1:
        return None, f"not a scalar channel (samples of shape {samples.shape}, {samples.dtype})"
    if samples.dtype.kind not in "biuf":
        return None, f"not numeric (samples of type {samples.dtype})"
    if samples.dtype.kind == "b":
        return None, "not numeric (boolean samples)"
    if samples.size != n_time:
        return None, f"has {samples.size} samples but its time base has {n_time}"
    values = samples.astype(np.float64)
    bits = getattr(sig, "invalidation_bits", None)
    if bits is not None:
        invalid = np.asarray(bits, dtype=bool)
        if invalid.shape == values.shape:
            values[invalid] = np.nan
    return values, None


def read_mf4(
    path: str | Path,
    name: str | None = None,
    meta: Mapping[str, Any] | None = None,
    *,
    channel_map: ChannelMap | str | Path | None = None,
    options: ReadOptions | None = None,
) -> Trace:
    """Read one experiment from an MDF4 file.

    Parameters
    ----------
    path : path-like
        MDF file. Channel groups at different rates are aligned on one uniform grid.
        Without ``channel_map`` the channels must have canonical names; a channel unit must
        then be the canonical one.
    name : str, optional
        Trace name; defaults to the embedded name, else the file stem.
    meta : dict, optional
        Trace metadata; defaults to the metadata embedded by :func:`write_mf4`.
    channel_map : ChannelMap or path-like, optional
        Source channel → canonical signal with units.
    options : ReadOptions, optional
        Gap interpolation, resampling and jitter tolerance.

    Returns
    -------
    Trace

    Raises
    ------
    DataError
        Naming the file and listing every problem with channel, group and row.
    """
    from .reading import read_log

    return read_log(
        path, name=name, meta=meta, channel_map=channel_map, options=options, format="mf4"
    )[0]
