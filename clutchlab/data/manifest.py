"""The dataset manifest (``manifest.json``): parsing and checking, before any file is read.

Reserved keys have a fixed meaning and are type-checked; every other key is free metadata
(DESIGN §3). A key that is not reserved but looks like a misspelt reserved key (``"Ramp"``,
``"dither_freq"``, ``"chanel_map"``, ``"experiment"``) is an error, so that a typo is not
silently kept as metadata; any other key (``"operator"``, ``"experiment_notes"``) is free.

Entry keys: ``file`` (required; relative to the folder), ``ramp`` (required; the split label),
``dither_freq_Hz`` (number > 0, Hz), ``dither_shape`` (string), ``dither_waveform`` (sine,
triangle or square), ``channel_map`` (TOML file relative to the folder; overrides the
top-level one). Top-level keys: ``experiments`` (required list), ``channel_map``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import DataError
from .paths import check_input_file, contained_file, file_kind_problem

__all__ = [
    "ENTRY_KEYS",
    "MANIFEST_NAME",
    "TOP_KEYS",
    "WAVEFORMS",
    "Manifest",
    "ManifestEntry",
    "read_manifest",
]

MANIFEST_NAME = "manifest.json"
#: Reserved keys of an experiment entry.
ENTRY_KEYS = ("file", "ramp", "dither_freq_Hz", "dither_shape", "dither_waveform", "channel_map")
#: Reserved top-level keys.
TOP_KEYS = ("experiments", "channel_map")
#: Dither waveforms the data and physics layers know.
WAVEFORMS = ("sine", "triangle", "square")
_MISSING = object()  # a top-level channel map that could not be found


@dataclass
class ManifestEntry:
    """One valid experiment entry.

    Parameters
    ----------
    index : int
        Position in the ``experiments`` list.
    file : pathlib.Path
        Experiment file.
    meta : dict
        Every key except ``file`` and ``channel_map``.
    channel_map : pathlib.Path or None
        Channel map of this entry (entry key, else top-level key), or None.
    """

    index: int
    file: Path
    meta: dict[str, Any]
    channel_map: Path | None = None

    @property
    def where(self) -> str:
        """``experiments[i]``."""
        return f"experiments[{self.index}]"


@dataclass
class Manifest:
    """A parsed manifest.

    Parameters
    ----------
    root : pathlib.Path
        Dataset folder.
    path : pathlib.Path
        The manifest file.
    entries : list of ManifestEntry
        Entries without problems, in order.
    extra : dict
        Top-level keys other than ``experiments`` and ``channel_map`` (free metadata).
    problems : list of str
        Every problem of the manifest itself (bad entries, typos, missing files).
    """

    root: Path
    path: Path
    entries: list[ManifestEntry] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)


def _distance(a: str, b: str) -> int:
    """Edit distance (insertions, deletions, substitutions, adjacent transpositions)."""
    prev2: list[int] = []
    prev = list(range(len(b) + 1))
    for i, ca in enumerate(a, start=1):
        cur = [i]
        for j, cb in enumerate(b, start=1):
            d = min(prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (ca != cb))
            if i > 1 and j > 1 and ca == b[j - 2] and a[i - 2] == cb:
                d = min(d, prev2[j - 2] + 1)
            cur.append(d)
        prev2, prev = prev, cur
    return prev[-1]


def _typo(key: str, known: tuple[str, ...]) -> str | None:
    """The reserved key ``key`` probably meant, if it is not reserved but close to one.

    Close means: equal ignoring case, at most 2 edits away (1 for short keys), or the
    reserved key minus a short suffix such as its unit (``dither_freq`` for ``dither_freq_Hz``).
    """
    if key in known:
        return None
    low = key.lower()
    for k in known:
        k_low = k.lower()
        if low == k_low:
            return k
        if _distance(low, k_low) <= (2 if len(k) > 6 else 1):
            return k
        if k_low.startswith(low) and 0 < len(k_low) - len(low) <= 3 and len(low) >= 4:
            return k
    return None


def _string(entry: dict, key: str, where: str, problems: list[str]) -> str | None:
    if key not in entry:
        problems.append(f"{where}: missing {key!r}")
        return None
    value = entry[key]
    if not isinstance(value, str) or not value.strip():
        problems.append(f"{where}: {key!r} must be a non-empty string, got {json.dumps(value)}")
        return None
    return value


def _map_path(value: Any, root: Path, where: str, problems: list[str]) -> Path | None:
    path, why = contained_file(root, value, where, "channel_map")
    if why is not None:
        problems.append(why)
    return path


def _check_entry(
    i: int, entry: Any, root: Path, default_map: Path | object | None, problems: list[str]
) -> ManifestEntry | None:
    where = f"experiments[{i}]"
    if not isinstance(entry, dict):
        problems.append(f"{where}: must be an object, got {json.dumps(entry)}")
        return None
    for key in entry:
        meant = _typo(str(key), ENTRY_KEYS)
        if meant:
            problems.append(f"{where}: unknown manifest key {key!r} (did you mean {meant!r}?)")
    file = _string(entry, "file", where, problems)
    ramp = _string(entry, "ramp", where, problems)
    freq = entry.get("dither_freq_Hz")
    if "dither_freq_Hz" in entry and (
        isinstance(freq, bool)
        or not isinstance(freq, int | float)
        or not math.isfinite(freq)
        or freq <= 0
    ):
        problems.append(f"{where}: 'dither_freq_Hz' must be a number > 0 (Hz), got {freq!r}")
    wave = entry.get("dither_waveform")
    if "dither_waveform" in entry and wave not in WAVEFORMS:
        problems.append(
            f"{where}: 'dither_waveform' must be one of {', '.join(WAVEFORMS)}, got {wave!r}"
        )
    if "dither_shape" in entry and not isinstance(entry["dither_shape"], str):
        problems.append(f"{where}: 'dither_shape' must be a string, got {entry['dither_shape']!r}")
    cmap, map_ok = default_map, default_map is not _MISSING
    if "channel_map" in entry:
        cmap = _map_path(entry["channel_map"], root, where, problems)
        map_ok = cmap is not None
    path = None
    if file is not None:
        path, why = contained_file(root, file, where, "file")
        if why is not None:
            problems.append(why)
    # The file is still read when only optional keys are wrong, so that its own problems
    # are listed too; without a file, a ramp or its channel map there is nothing to read.
    if path is None or ramp is None or not map_ok:
        return None
    meta = {k: v for k, v in entry.items() if k not in ("file", "channel_map")}
    return ManifestEntry(i, path, meta, cmap if isinstance(cmap, Path) else None)


def read_manifest(path: str | Path) -> Manifest:
    """Parse and check a dataset manifest.

    Parameters
    ----------
    path : path-like
        Dataset folder, or its ``manifest.json``.

    Returns
    -------
    Manifest
        Valid entries and every problem of the others (bad or misspelt keys, wrong types,
        missing files, duplicate experiment names), each naming ``experiments[i]``.

    Raises
    ------
    DataError
        If the folder or the manifest is missing, the manifest is not valid JSON (line and
        column given), not an object, or has no ``experiments`` list.
    """
    path = Path(path)
    if path.suffix.lower() == ".json" and path.is_file():
        root, manifest_path = path.parent, path
    else:
        root, manifest_path = path, path / MANIFEST_NAME
    if not root.is_dir():
        why = file_kind_problem(root)
        if why == "not found":
            raise DataError(f"{root}: dataset folder not found")
        if why is None:  # a regular file where the folder was expected
            raise DataError(
                f"{root}: a file, not a dataset folder (give the folder or its manifest.json; "
                "one log is read with read_log)"
            )
        raise DataError(f"{root}: {why}; a dataset folder or a log file was expected")
    check_input_file(manifest_path, "manifest")
    try:
        data = json.loads(manifest_path.read_text(encoding="utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise DataError(f"{manifest_path}: not UTF-8 text ({exc})") from None
    except json.JSONDecodeError as exc:
        raise DataError(
            f"{manifest_path}: invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}"
        ) from None
    if not isinstance(data, dict):
        raise DataError(f"{manifest_path}: must be a JSON object with an 'experiments' list")
    entries = data.get("experiments")
    if not isinstance(entries, list):
        what = "missing" if entries is None else f"a {type(entries).__name__}, not a list"
        meant = [k for k in data if _typo(str(k), TOP_KEYS) == "experiments"]
        hint = f" (found {meant[0]!r})" if meant else ""
        raise DataError(f"{manifest_path}: 'experiments' is {what}{hint}")

    manifest = Manifest(root, manifest_path)
    problems = manifest.problems
    for key in data:
        meant = _typo(str(key), TOP_KEYS)
        if meant:
            problems.append(f"unknown manifest key {key!r} (did you mean {meant!r}?)")
    default_map: Path | object | None = None
    if "channel_map" in data:
        default_map = _map_path(data["channel_map"], root, "channel_map", problems) or _MISSING
    names: dict[str, tuple[int, Path]] = {}
    for i, entry in enumerate(entries):
        checked = _check_entry(i, entry, root, default_map, problems)
        if checked is None:
            continue
        name = checked.file.stem
        if name in names:
            first, first_file = names[name]
            problems.append(
                f"experiments[{i}]: experiment name {name!r} (file stem of {checked.file}) "
                f"already used by experiments[{first}] ({first_file}); experiments are named "
                "by their file's stem, so rename one of the files"
            )
            continue
        names[name] = (i, checked.file)
        manifest.entries.append(checked)
    manifest.extra = {k: v for k, v in data.items() if k not in TOP_KEYS}
    return manifest
