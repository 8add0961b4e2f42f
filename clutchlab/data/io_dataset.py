"""Dataset folders: ``manifest.json`` plus one file per experiment (DESIGN §3).

Readers and writers are looked up by file extension in :data:`FORMATS`, so new formats
(Parquet, MF4) are added by registering a ``(reader, writer)`` pair.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError
from .dataset import Dataset
from .io_csv import read_csv, write_csv
from .trace import Trace

__all__ = ["FORMATS", "MANIFEST_NAME", "load_dataset", "save_dataset"]

MANIFEST_NAME = "manifest.json"

#: ``reader(path, name=..., meta=...) -> Trace``
Reader = Callable[..., Trace]
#: ``writer(trace, path) -> Any``
Writer = Callable[[Trace, Path], Any]

#: File extension (lower case, with dot) to ``(reader, writer)``.
FORMATS: dict[str, tuple[Reader, Writer]] = {".csv": (read_csv, write_csv)}

# Characters that are not portable in a file name (Windows / POSIX).
_BAD_STEM = re.compile(r'[<>:"/\\|?*\x00-\x1f]')


def _suffix_of(format: str) -> str:
    suffix = format.lower() if format.startswith(".") else "." + format.lower()
    if suffix not in FORMATS:
        raise DataError(
            f"unsupported dataset format {format!r}; supported: "
            f"{', '.join(s.lstrip('.') for s in FORMATS)}"
        )
    return suffix


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} value {value!r} is not JSON serializable")


def _manifest_text(dataset: Dataset, suffix: str) -> str:
    """``manifest.json`` content; DataError listing every problem (before anything is written)."""
    manifest = dataset.manifest(suffix=suffix)
    problems: list[str] = []
    lower: dict[str, str] = {}
    for i, (trace, entry) in enumerate(zip(dataset, manifest["experiments"], strict=True)):
        name = trace.name
        if _BAD_STEM.search(name) or name.strip() != name or name in (".", ".."):
            problems.append(f"experiment {i}: name {name!r} is not a portable file name")
        if name.lower() in lower:
            problems.append(
                f"experiment {i}: name {name!r} differs only in case from {lower[name.lower()]!r}"
                " (the files would collide on case-insensitive file systems)"
            )
        lower.setdefault(name.lower(), name)
        try:
            json.dumps(entry, default=_json_default, allow_nan=False)
        except (TypeError, ValueError) as exc:
            problems.append(f"experiment {i} ({name!r}): metadata is not valid JSON ({exc})")
    extra = {k: v for k, v in manifest.items() if k != "experiments"}
    try:
        json.dumps(extra, default=_json_default, allow_nan=False)
    except (TypeError, ValueError) as exc:
        problems.append(f"manifest_extra is not valid JSON ({exc})")
    if problems:
        raise DataError("cannot save dataset", problems)
    return (
        json.dumps(manifest, default=_json_default, allow_nan=False, indent=2, ensure_ascii=False)
        + "\n"
    )


def _chmod_like_mkdir(folder: Path) -> None:
    """Give a ``mkdtemp`` folder (mode 0700) the permissions ``mkdir`` would (0777 & ~umask)."""
    mask = os.umask(0)
    os.umask(mask)
    os.chmod(folder, 0o777 & ~mask)


def save_dataset(
    dataset: Dataset,
    path: str | Path,
    format: str = "csv",
    *,
    overwrite: bool = False,
) -> Path:
    """Write a dataset folder atomically: ``manifest.json`` plus ``<name>.<format>`` files.

    Everything is written into a temporary sibling folder that is renamed into place only
    once complete, so a failure leaves nothing half-written (and an existing folder intact).

    Parameters
    ----------
    dataset : Dataset
        Dataset to write; every experiment needs a ramp label and a name usable as a file
        name. Signals are written in canonical units (s, mA, Hz, bar, °C).
    path : path-like
        Destination folder. It must not exist or be empty, unless ``overwrite`` is True.
    format : str, optional
        Experiment file format, a key of :data:`FORMATS` without the dot (``"csv"``).
    overwrite : bool, optional
        Replace an existing dataset folder (one containing ``manifest.json``) once the new one
        is complete. A non-empty folder without a manifest is never replaced.

    Returns
    -------
    pathlib.Path
        The dataset folder.

    Raises
    ------
    DataError
        Unsupported format, experiments without ramp label or with unusable names,
        metadata that is not JSON, or a destination that may not be replaced.
    """
    if not isinstance(dataset, Dataset):
        raise TypeError(f"save_dataset expects a Dataset, got {type(dataset)!r}")
    suffix = _suffix_of(format)
    writer = FORMATS[suffix][1]
    text = _manifest_text(dataset, suffix)

    path = Path(path)
    if path.exists() and not path.is_dir():
        raise DataError(f"{path}: exists and is not a folder")
    existing = path.is_dir() and any(path.iterdir())
    if existing and not overwrite:
        raise DataError(f"{path}: folder exists and is not empty (pass overwrite=True)")
    if existing and not (path / MANIFEST_NAME).is_file():
        raise DataError(
            f"{path}: not a dataset folder (no {MANIFEST_NAME}); refusing to replace it"
        )

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    _chmod_like_mkdir(tmp)
    try:
        for trace in dataset:
            writer(trace, tmp / f"{trace.name}{suffix}")
        (tmp / MANIFEST_NAME).write_text(text, encoding="utf-8")
        if existing:
            backup = tmp.with_name(tmp.name + ".old")
            os.replace(path, backup)
            try:
                os.replace(tmp, path)
            except BaseException:
                os.replace(backup, path)
                raise
            shutil.rmtree(backup, ignore_errors=True)
        else:
            if path.is_dir():
                path.rmdir()  # empty: replaced by the complete new folder
            os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return path


def _required_string(entry: dict, key: str, where: str, problems: list[str]) -> str | None:
    """``entry[key]`` if it is a non-empty string, else None with the problem recorded."""
    value = entry.get(key)
    if key not in entry:
        problems.append(f"{where}: missing {key!r}")
        return None
    if not isinstance(value, str) or not value:
        problems.append(f"{where}: {key!r} must be a non-empty string, got {value!r}")
        return None
    return value


def load_dataset(path: str | Path) -> Dataset:
    """Load a dataset folder.

    Parameters
    ----------
    path : path-like
        Dataset folder, or its ``manifest.json``. The manifest is
        ``{"experiments": [{"file": ..., "ramp": ..., ...}, ...], ...}``; file paths are
        relative to the folder.

    Returns
    -------
    Dataset
        Experiments in manifest order, named by file stem, with every manifest key except
        ``"file"`` in :attr:`Trace.meta`; other top-level keys in ``manifest_extra``.

    Raises
    ------
    DataError
        Naming the manifest and listing every problem, each with its entry index
        (``experiments[i]``): missing or invalid manifest, missing ``experiments`` list,
        entries without ``file`` or ``ramp``, missing files, unsupported formats, duplicate
        names, and every problem of the experiment files themselves.
    """
    path = Path(path)
    if path.suffix.lower() == ".json" and path.is_file():
        root, manifest_path = path.parent, path
    else:
        root, manifest_path = path, path / MANIFEST_NAME
    if not root.is_dir():
        raise DataError(f"{root}: dataset folder not found")
    if not manifest_path.is_file():
        raise DataError(f"{manifest_path}: manifest not found")
    try:
        manifest = json.loads(manifest_path.read_text(encoding="utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise DataError(f"{manifest_path}: not UTF-8 text ({exc})") from None
    except json.JSONDecodeError as exc:
        raise DataError(
            f"{manifest_path}: invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}"
        ) from None
    if not isinstance(manifest, dict):
        raise DataError(f"{manifest_path}: must be a JSON object with an 'experiments' list")
    entries = manifest.get("experiments")
    if not isinstance(entries, list):
        what = "missing" if entries is None else f"a {type(entries).__name__}, not a list"
        raise DataError(f"{manifest_path}: 'experiments' is {what}")

    problems: list[str] = []
    valid: list[tuple[int, Path, dict[str, Any]]] = []
    names: dict[str, int] = {}
    for i, entry in enumerate(entries):
        where = f"experiments[{i}]"
        if not isinstance(entry, dict):
            problems.append(f"{where}: must be an object, got {json.dumps(entry)}")
            continue
        file = _required_string(entry, "file", where, problems)
        ramp = _required_string(entry, "ramp", where, problems)
        if file is None or ramp is None:
            continue
        ok = True
        file_path = root / file
        name = file_path.stem
        if not file_path.is_file():
            problems.append(f"{where}: file {file!r} not found ({file_path})")
            ok = False
        elif file_path.suffix.lower() not in FORMATS:
            problems.append(
                f"{where}: file {file!r}: unsupported format {file_path.suffix!r}; supported: "
                f"{', '.join(FORMATS)}"
            )
            ok = False
        if name in names:
            problems.append(
                f"{where}: experiment name {name!r} (file stem) already used by "
                f"experiments[{names[name]}]"
            )
            ok = False
        names.setdefault(name, i)
        if ok:
            valid.append((i, file_path, {k: v for k, v in entry.items() if k != "file"}))

    traces: list[Trace] = []
    for i, file_path, meta in valid:
        reader = FORMATS[file_path.suffix.lower()][0]
        try:
            traces.append(reader(file_path, name=file_path.stem, meta=meta))
        except DataError as exc:
            problems += [f"experiments[{i}]: {p}" for p in exc.problems or [str(exc)]]
    if problems:
        raise DataError(f"{manifest_path}: invalid dataset", problems)
    extra = {k: v for k, v in manifest.items() if k != "experiments"}
    return Dataset(traces, root=root, manifest_extra=extra)
