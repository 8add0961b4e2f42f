"""Dataset folders: ``manifest.json`` plus one file per experiment (DESIGN §3).

Experiment files are read and written through the :data:`~clutchlab.data.formats.FORMATS`
registry (CSV, Parquet, MF4), so new formats are added by registering a
:class:`~clutchlab.data.formats.FileFormat`.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path

from ..errors import DataError
from .channel_map import ChannelMap, ChannelMapLike, load_channel_map
from .dataset import Dataset
from .formats import FORMATS, suffix_of
from .manifest import MANIFEST_NAME, Manifest, read_manifest
from .meta_json import json_default
from .options import ReadOptions
from .output import Content, write_folder_atomic
from .reading import check_log
from .report import LoadReport
from .trace import Trace

__all__ = [
    "FORMATS",
    "MANIFEST_NAME",
    "DatasetScan",
    "experiment_name_problems",
    "load_dataset",
    "save_dataset",
    "scan_dataset",
]

# Characters that are not portable in a file name (Windows / POSIX).
_BAD_STEM = re.compile(r'[<>:"/\\|?*\x00-\x1f]')


def experiment_name_problems(names: list[str]) -> list[str]:
    """Why experiment names cannot be a dataset's file names (empty list: they can).

    Parameters
    ----------
    names : list of str
        Experiment names, in dataset order (each becomes ``<name>.<format>``).

    Returns
    -------
    list of str
        One line per problem: a name that is not a portable file name, or that differs from
        an earlier one only in case (the files would collide on Windows and macOS).
    """
    problems: list[str] = []
    lower: dict[str, str] = {}
    for i, name in enumerate(names):
        if _BAD_STEM.search(name) or name.strip() != name or name in (".", ".."):
            problems.append(f"experiment {i}: name {name!r} is not a portable file name")
        if name.lower() in lower:
            problems.append(
                f"experiment {i}: name {name!r} differs only in case from {lower[name.lower()]!r}"
                " (the files would collide on case-insensitive file systems)"
            )
        lower.setdefault(name.lower(), name)
    return problems


def _manifest_text(dataset: Dataset, suffix: str) -> str:
    """``manifest.json`` content; DataError listing every problem (before anything is written)."""
    manifest = dataset.manifest(suffix=suffix)
    problems = experiment_name_problems([trace.name for trace in dataset])
    for i, (trace, entry) in enumerate(zip(dataset, manifest["experiments"], strict=True)):
        name = trace.name
        try:
            json.dumps(entry, default=json_default, allow_nan=False)
        except (TypeError, ValueError) as exc:
            problems.append(f"experiment {i} ({name!r}): metadata is not valid JSON ({exc})")
    extra = {k: v for k, v in manifest.items() if k != "experiments"}
    try:
        json.dumps(extra, default=json_default, allow_nan=False)
    except (TypeError, ValueError) as exc:
        problems.append(f"manifest_extra is not valid JSON ({exc})")
    if problems:
        raise DataError("cannot save dataset", problems)
    return (
        json.dumps(manifest, default=json_default, allow_nan=False, indent=2, ensure_ascii=False)
        + "\n"
    )


def save_dataset(
    dataset: Dataset,
    path: str | Path,
    format: str = "csv",
    *,
    overwrite: bool = False,
    extra: Mapping[str, Content] | None = None,
) -> Path:
    """Write a dataset folder atomically: ``manifest.json`` plus ``<name>.<format>`` files.

    Everything is written into a temporary sibling folder that is swapped into place only
    once complete (:func:`~clutchlab.data.output.write_folder_atomic`), so a failure or a kill
    leaves nothing half-written (and an existing folder intact). Files in the destination that
    clutchlab did not write are kept; one standing where a dataset file would go is refused.

    Parameters
    ----------
    dataset : Dataset
        Dataset to write; every experiment needs a ramp label and a name usable as a file
        name. Signals are written in canonical units (s, mA, Hz, bar, °C).
    path : path-like
        Destination folder. It must not exist or be empty, unless ``overwrite`` is True.
    format : str, optional
        Experiment file format: ``"csv"`` (9 significant digits), ``"parquet"`` (float64,
        units in the field metadata), ``"mf4"`` (MDF 4.10, float64, channel units) or
        ``"mat"`` (MATLAB v7, one column vector per signal, a ``units`` struct).
    overwrite : bool, optional
        Write into an existing non-empty folder. Files clutchlab wrote there before are
        replaced (or removed when no longer written); every other file is kept, and one in the
        way of a new file is an error.
    extra : mapping of str to bytes or callable, optional
        Further files written into the folder in the same atomic step (e.g. an overview
        figure): relative name → bytes or ``f(path)``.

    Returns
    -------
    pathlib.Path
        The dataset folder.

    Raises
    ------
    DataError
        Unsupported format, experiments without ramp label or with unusable names,
        metadata that is not JSON.
    OutputError
        A destination that may not be written (exists without ``overwrite``, a file of the
        user's in the way, a read-only folder).
    """
    if not isinstance(dataset, Dataset):
        raise TypeError(f"save_dataset expects a Dataset, got {type(dataset)!r}")
    suffix = suffix_of(format)
    writer = FORMATS[suffix].write
    text = _manifest_text(dataset, suffix)
    path = Path(path)
    files: dict[str, Content] = {
        f"{trace.name}{suffix}": (lambda p, tr=trace: writer(tr, p)) for trace in dataset
    }
    files[MANIFEST_NAME] = text.encode("utf-8")
    for name, content in (extra or {}).items():
        if name in files:
            raise DataError(f"{path}: extra file {name!r} collides with a dataset file")
        files[name] = content
    return write_folder_atomic(path, files, overwrite=overwrite, what="dataset folder")


def _resolve_map(
    override: ChannelMap | None, path: Path | None, cache: dict[Path, ChannelMap]
) -> ChannelMap | None:
    if override is not None:
        return override
    if path is None:
        return None
    if path not in cache:
        cache[path] = load_channel_map(path)
    return cache[path]


@dataclass(frozen=True)
class DatasetScan:
    """Every experiment of a dataset folder as read, problems collected, nothing raised.

    Parameters
    ----------
    manifest : Manifest
        The parsed manifest (valid entries, free top-level keys, manifest problems).
    traces : tuple of Trace or None
        One per valid manifest entry (None where the file has problems).
    reports : tuple of LoadReport
        One per valid manifest entry; problems prefixed with ``experiments[i]``.
    problems : tuple of str
        Problems of the manifest itself and of channel maps.
    """

    manifest: Manifest
    traces: tuple[Trace | None, ...]
    reports: tuple[LoadReport, ...]
    problems: tuple[str, ...]

    @property
    def all_problems(self) -> list[str]:
        """Manifest problems, then every file's problems."""
        return [*self.problems, *(p for r in self.reports for p in r.problems)]


def scan_dataset(
    path: str | Path,
    channel_map: ChannelMapLike = None,
    *,
    options: ReadOptions | None = None,
) -> DatasetScan:
    """Read every experiment of a dataset folder, collecting problems instead of raising.

    Parameters
    ----------
    path : path-like
        Dataset folder, or its ``manifest.json``.
    channel_map : ChannelMap, path-like or mapping, optional
        Map applied to every experiment; overrides the manifest's ``channel_map`` keys.
    options : ReadOptions, optional
        Gap interpolation, resampling, jitter tolerance.

    Returns
    -------
    DatasetScan

    Raises
    ------
    DataError
        If the folder or manifest is missing or the manifest is not a JSON object with an
        ``experiments`` list, or ``channel_map`` is unusable.
    """
    manifest = read_manifest(path)
    override = load_channel_map(channel_map) if channel_map is not None else None
    cache: dict[Path, ChannelMap] = {}
    problems = list(manifest.problems)
    traces: list[Trace | None] = []
    reports: list[LoadReport] = []
    for entry in manifest.entries:
        try:
            cmap = _resolve_map(override, entry.channel_map, cache)
        except DataError as exc:
            problems += [f"{entry.where}: {p}" for p in exc.problems or [str(exc)]]
            continue
        if entry.file.suffix.lower() not in FORMATS:
            problems.append(
                f"{entry.where}: file {entry.file.name!r}: unsupported format "
                f"{entry.file.suffix!r}; supported: {', '.join(FORMATS)}"
            )
            continue
        trace, report = check_log(
            entry.file, name=entry.file.stem, meta=entry.meta, channel_map=cmap, options=options
        )
        prefixed = tuple(f"{entry.where}: {p}" for p in report.problems)
        reports.append(replace(report, problems=prefixed))
        traces.append(trace)
    return DatasetScan(manifest, tuple(traces), tuple(reports), tuple(problems))


def load_dataset(
    path: str | Path,
    channel_map: ChannelMapLike = None,
    *,
    options: ReadOptions | None = None,
) -> Dataset:
    """Load a dataset folder, every experiment validated and in canonical units.

    Parameters
    ----------
    path : path-like
        Dataset folder, or its ``manifest.json``. The manifest is
        ``{"experiments": [{"file": ..., "ramp": ..., ...}, ...], ...}``; file paths are
        relative to the folder; files may be CSV, Parquet or MF4.
    channel_map : ChannelMap, path-like or mapping, optional
        Source channel → canonical signal with units and defaults, applied to every
        experiment. Without it, the manifest's ``channel_map`` keys apply (an entry's key
        overrides the top-level key; paths relative to the folder); without any map,
        channel names must be canonical.
    options : ReadOptions, optional
        ``interpolate_gaps`` (samples), ``rate_Hz`` (Hz), ``max_jitter`` (fraction of the
        sample interval).

    Returns
    -------
    Dataset
        Experiments in manifest order, named by file stem, with every manifest key except
        ``file`` and ``channel_map`` in :attr:`Trace.meta`; other top-level keys in
        ``manifest_extra``; how each file was read in :attr:`Dataset.reports`.

    Raises
    ------
    DataError
        Naming the manifest and listing every problem, each with its entry index
        (``experiments[i]``) and, for problems inside a file, the file, column and row:
        missing or invalid manifest, entries without ``file`` or ``ramp``, misspelt reserved
        keys, missing files, unsupported formats, duplicate names, and every problem of the
        experiment files (see :func:`~clutchlab.data.reading.read_log`).
    """
    scan = scan_dataset(path, channel_map, options=options)
    problems = scan.all_problems
    if problems:
        raise DataError(f"{scan.manifest.path}: invalid dataset", problems)
    return Dataset(
        [t for t in scan.traces if t is not None],
        root=scan.manifest.root,
        manifest_extra=scan.manifest.extra,
        reports={r.name: r for r in scan.reports},
    )
