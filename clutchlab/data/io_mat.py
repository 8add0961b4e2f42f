"""MATLAB ``.mat`` logs: v5 – v7.2 through SciPy, v7.3 (HDF5) through h5py.

Layout read (what MATLAB and dSPACE exports look like):

- **one variable per channel**: numeric vectors of one length (``time_s``, ``P_CL``, …), or
- **one struct per experiment**: a single struct variable whose fields are those vectors,
  possibly next to scalar variables (``save('run.mat', 'run', 'Fs')``).

A numeric scalar is a constant channel (a logged set point such as a dither frequency).
Only the vectors that are read — those a channel map uses, or without a map those named like
canonical signals — must share one length; a variable that is not read may have any length
(a map ignores it; without a map, every name must still be canonical, as in every format).
Optional companions, written by :func:`write_mat` / :func:`write_mat73`: ``units`` (a struct
of unit strings per channel) and ``clutchlab`` (the experiment's name and metadata as JSON
text). Decoding only turns the file into named float64 columns; mapping, units and checks
are done for every format by :mod:`clutchlab.data.assemble`, so errors name the file, the
variable and the row.
"""

from __future__ import annotations

import datetime
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from .meta_json import embedded_meta_json, parse_embedded_meta
from .output import atomic_file_writer
from .paths import check_input_file
from .rawlog import RawChannel, RawLog
from .signals import CANONICAL_ORDER, SIGNALS
from .trace import Trace

__all__ = ["decode_mat", "write_mat", "write_mat73"]

META_VAR = "clutchlab"
UNITS_VAR = "units"
_RESERVED = (META_VAR, UNITS_VAR)


def _version(path: Path) -> tuple[int, int]:
    from scipy.io.matlab import matfile_version

    try:
        return matfile_version(str(path))
    except Exception as exc:  # SciPy raises ValueError / MatReadError / struct.error
        raise DataError(f"{path}: not a MATLAB .mat file ({type(exc).__name__}: {exc})") from None


def _load_v5(path: Path) -> dict[str, Any]:
    from scipy.io import loadmat

    try:
        data = loadmat(str(path), simplify_cells=True, mat_dtype=False)
    except Exception as exc:  # truncated / corrupt files raise many types
        raise DataError(
            f"{path}: not a readable .mat file (truncated or corrupt?): {type(exc).__name__}: {exc}"
        ) from None
    return {k: v for k, v in data.items() if not k.startswith("__")}


def _h5_value(obj) -> Any:
    import h5py

    cls = obj.attrs.get("MATLAB_class", b"")
    cls = cls.decode() if isinstance(cls, bytes) else str(cls)
    if isinstance(obj, h5py.Group):
        if cls not in ("struct", ""):
            return _Unsupported(f"a MATLAB {cls} (only numeric vectors and structs are read)")
        return {k: _h5_value(v) for k, v in obj.items()}
    if obj.attrs.get("MATLAB_empty", 0):
        return np.zeros(0)
    if cls == "char":
        codes = np.asarray(obj[()]).ravel()
        return "".join(map(chr, codes))
    if cls in ("cell", "function_handle", "logical") or obj.dtype.kind not in "iuf":
        if cls == "logical":
            return np.asarray(obj[()], dtype=float).T
        return _Unsupported(f"a MATLAB {cls or obj.dtype} (only numeric vectors are read)")
    return np.asarray(obj[()]).T  # MATLAB is column-major: HDF5 holds the transpose


def _load_v73(path: Path) -> dict[str, Any]:
    import h5py

    try:
        with h5py.File(path, "r") as f:
            return {k: _h5_value(v) for k, v in f.items() if not k.startswith("#")}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise DataError(
            f"{path}: not a readable MATLAB v7.3 (HDF5) file: {type(exc).__name__}: {exc}"
        ) from None


class _Unsupported:
    def __init__(self, why: str) -> None:
        self.why = why


def _vector(value: Any) -> tuple[np.ndarray | None, str | None]:
    """A numeric vector (or scalar) as float64; else None and why."""
    if isinstance(value, _Unsupported):
        return None, value.why
    if isinstance(value, bool | int | float | np.number):
        return np.array([float(value)]), None
    if not isinstance(value, np.ndarray):
        return None, f"not numeric ({type(value).__name__})"
    if value.dtype.kind not in "biuf":
        return None, f"not numeric (MATLAB type {value.dtype})"
    arr = np.asarray(value, dtype=float)
    if arr.ndim > 1:
        if sum(d > 1 for d in arr.shape) > 1:
            shape = "×".join(map(str, arr.shape))
            return None, f"a {shape} matrix; only vectors are read (one variable per channel)"
        arr = arr.ravel()
    return np.atleast_1d(arr), None


def _units(value: Any) -> dict[str, str]:
    if not isinstance(value, Mapping):
        return {}
    return {str(k): str(v) for k, v in value.items() if isinstance(v, str) and v}


def _is_series(value: Any) -> bool:
    """True for a numeric vector of more than one sample (a channel, not a scalar)."""
    values, _ = _vector(value)
    return values is not None and len(values) > 1


def _layout(
    data: Mapping[str, Any], path: Path, units: dict[str, str]
) -> tuple[dict[str, tuple[str, Any]], dict[str, str], list[str]]:
    """The variables holding channels: name → (label for messages, value); units; notes.

    One variable per channel, or — when no variable outside a struct is a vector — the
    fields of the one struct, next to the file's other variables (scalars such as a sample
    rate saved with it: ``save('run.mat', 'run', 'Fs')``).
    """
    variables = {k: v for k, v in data.items() if k not in _RESERVED}
    structs = {k: v for k, v in variables.items() if isinstance(v, Mapping)}
    if not structs or any(_is_series(v) for v in variables.values()):
        return {k: (k, v) for k, v in variables.items()}, units, []
    if len(structs) > 1:
        raise DataError(
            f"{path}: {len(structs)} structs ({', '.join(sorted(structs))}); one experiment "
            "per file is read — save one struct (or one variable per channel) per file"
        )
    ((struct, fields),) = structs.items()
    out = {k: (f"{struct}.{k}", v) for k, v in fields.items() if k != UNITS_VAR}
    notes = []
    for k, v in variables.items():
        if k == struct:
            continue
        if k in out:
            notes.append(f"variable {k!r} ignored: struct {struct!r} has a field of that name")
        else:
            out[k] = (k, v)
    return out, {**units, **_units(fields.get(UNITS_VAR))}, notes


def _common_length(
    columns: Mapping[str, tuple[np.ndarray | None, str | None]],
    used: Callable[[str], bool],
) -> int | None:
    """The most frequent length of the vectors used (of all vectors if none is used)."""
    lengths = {k: len(v) for k, (v, _) in columns.items() if v is not None and len(v) > 1}
    if not lengths:
        return None
    pool = [n for k, n in lengths.items() if used(k)] or list(lengths.values())
    return max(set(pool), key=pool.count)


def decode_mat(path: str | Path, wanted: Callable[[str], bool] | None = None) -> RawLog:
    """Decode a MATLAB ``.mat`` file into named float64 columns (no mapping, no value checks).

    Parameters
    ----------
    path : path-like
        ``.mat`` file, v5 – v7.2 or v7.3 (HDF5): one variable per channel, or one struct
        per experiment (with, optionally, scalar variables next to it).
    wanted : callable, optional
        ``wanted(name)`` tells whether a channel's values are needed; others are listed
        without values, and their lengths do not matter. Default: every channel.

    Returns
    -------
    RawLog
        One channel per numeric vector; unusable variables with ``values=None`` and the
        reason; scalars broadcast to constant channels (with a note).

    Raises
    ------
    DataError
        Missing or unreadable file, no numeric vector in it, several structs (which is the
        experiment is ambiguous), or wanted vectors of different lengths (each named, with
        the file).
    """
    path = check_input_file(path)
    if path.stat().st_size == 0:
        raise DataError(f"{path}: empty file")
    major, _ = _version(path)
    data = _load_v73(path) if major == 2 else _load_v5(path)
    version = "v7.3" if major == 2 else "v5-v7.2"

    meta = parse_embedded_meta(data[META_VAR]) if isinstance(data.get(META_VAR), str) else None
    units = _units(data.get(UNITS_VAR))
    if meta and isinstance(meta.get("units"), dict):
        units = {**meta["units"], **units}
    variables, units, layout_notes = _layout(data, path, units)
    used = wanted or (lambda name: True)
    columns = {k: _vector(v) for k, (_, v) in variables.items()}
    n = _common_length(columns, used)
    if n is None:
        raise DataError(
            f"{path}: no numeric vector in the file ({version}); variables: "
            f"{', '.join(repr(label) for label, _ in variables.values()) or 'none'}"
        )
    channels: list[RawChannel] = []
    notes: list[str] = [f"MATLAB {version} file", *layout_notes]
    problems: list[str] = []
    for name, (values, why) in columns.items():
        where = f"variable {variables[name][0]!r}"
        if values is not None and not used(name):
            values, why = None, "not loaded"
        elif values is not None and len(values) == 1:
            notes.append(f"{where} is a scalar ({values[0]:g}): used as a constant channel")
            values = np.full(n, values[0])
        elif values is not None and len(values) != n:
            problems.append(
                f"{path}: {where}: {len(values)} samples where the other vectors have {n}"
            )
            values, why = None, f"{len(values)} samples, not {n}"
        channels.append(RawChannel(name, values, units.get(name), where=where, problem=why))
    if problems:
        raise DataError(f"{path}: cannot read the MATLAB file", problems)
    return RawLog(path, "mat", channels, meta=meta, notes=notes)


def _columns(trace: Trace) -> list[tuple[str, np.ndarray]]:
    if not isinstance(trace, Trace):
        raise TypeError(f"expected a Trace, got {type(trace)!r}")
    return [(n, np.asarray(trace.signals[n], dtype=float)) for n in CANONICAL_ORDER if trace.has(n)]


@atomic_file_writer
def write_mat(trace: Trace, path: str | Path) -> Path:
    """Write a trace as a MATLAB v7 ``.mat`` file (compressed v5 format, readable by MATLAB).

    Parameters
    ----------
    trace : Trace
        Trace to write: one column vector per signal in canonical names and units (s, mA, Hz,
        bar, °C), a ``units`` struct and the metadata as JSON text in ``clutchlab``.
    path : path-like
        Destination file. An existing file is replaced atomically: the new one is
        written to a temporary sibling and renamed into place, so a failure leaves
        the earlier file as it was.

    Returns
    -------
    pathlib.Path
        The file written.
    """
    from scipy.io import savemat

    path = Path(path)
    doc: dict[str, Any] = {n: v.reshape(-1, 1) for n, v in _columns(trace)}
    doc[UNITS_VAR] = {n: SIGNALS[n].unit for n, _ in _columns(trace)}
    doc[META_VAR] = embedded_meta_json(trace)
    with open(path, "wb") as fh:
        savemat(fh, doc, format="5", do_compression=True, oned_as="column")
    return path


def _h5_char(group, name: str, text: str) -> None:
    codes = np.array([ord(c) for c in text] or [0], dtype=np.uint16).reshape(-1, 1)
    ds = group.create_dataset(name, data=codes)
    ds.attrs["MATLAB_class"] = np.bytes_("char")
    ds.attrs["MATLAB_int_decode"] = np.int32(2)
    if not text:
        ds.attrs["MATLAB_empty"] = np.uint8(1)


@atomic_file_writer
def write_mat73(trace: Trace, path: str | Path, *, struct: str | None = None) -> Path:
    """Write a trace as a MATLAB v7.3 ``.mat`` file (HDF5 in MATLAB's layout).

    Parameters
    ----------
    trace : Trace
        Trace to write (as :func:`write_mat`).
    path : path-like
        Destination file. An existing file is replaced atomically: the new one is
        written to a temporary sibling and renamed into place, so a failure leaves
        the earlier file as it was.
    struct : str, optional
        Write the signals (and ``units``) as fields of one struct of this name instead of one
        variable per channel.

    Returns
    -------
    pathlib.Path
        The file written.
    """
    import h5py

    path = Path(path)
    cols = _columns(trace)
    with h5py.File(path, "w", userblock_size=512) as f:
        root = f
        if struct:
            root = f.create_group(struct)
            root.attrs["MATLAB_class"] = np.bytes_("struct")
        for name, values in cols:
            ds = root.create_dataset(name, data=values.reshape(1, -1))  # MATLAB N×1
            ds.attrs["MATLAB_class"] = np.bytes_("double")
        units = root.create_group(UNITS_VAR)
        units.attrs["MATLAB_class"] = np.bytes_("struct")
        for name, _ in cols:
            _h5_char(units, name, SIGNALS[name].unit)
        _h5_char(f, META_VAR, embedded_meta_json(trace))
    stamp = datetime.datetime.now(datetime.UTC).strftime("%a %b %d %H:%M:%S %Y")
    text = f"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: {stamp} HDF5 schema 1.00 ."
    header = text.encode("ascii").ljust(116, b" ") + b"\0" * 8 + b"\x00\x02" + b"IM"
    with open(path, "r+b") as fh:
        fh.write(header.ljust(512, b"\0"))
    return path
