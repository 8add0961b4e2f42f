"""Kill-safe result storage of a sweep: atomic Parquet part files, consolidated at the end.

Layout for ``--out results.parquet``::

    results.parquet          consolidated table (written at the end, atomically)
    results.parquet.parts/   .clutchlab-owned.json + spec.json
                             + part-<ns>-<pid>-<seq>.parquet, one per flush

A part file is written to a temporary name, flushed to disk and renamed into place, so a
killed sweep leaves only complete part files (and perhaps a stray temporary file, removed on
the next start). A restarted sweep reads the parts, skips the points already there and
appends new parts; consolidation keeps one row per point id (the newest) and records in the
consolidated file's Parquet metadata the newest part it was built from, so that
:func:`read_results` can tell a consolidated file left behind by a later, unfinished run (an
extended sweep that was killed) and read the parts instead.

Only what clutchlab wrote is touched (:mod:`clutchlab.data.output`): the parts folder carries
the ownership record ``.clutchlab-owned.json``, and within it clutchlab reads, replaces and
deletes only ``spec.json``, part files named exactly ``part-<20 digits>-<pid>-<6 digits>.parquet``
and their temporary files. A folder without the record (and without the ``spec.json`` of an
earlier clutchlab version) that holds anything is refused; a user's file in a clutchlab
folder (``notes.txt``) is kept, also by ``overwrite``.
"""

from __future__ import annotations

import json
import os
import re
import time
import warnings
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from ...data.output import (
    OWNED_NAME,
    has_ownership_record,
    ownership_record,
    write_file_atomic,
)
from ...errors import DataError, OutputError
from .spec import SpecError

__all__ = [
    "OtherSpecResultsError",
    "ResultStore",
    "UnfinishedSweepWarning",
    "check_parts_folder",
    "read_results",
]

#: Part files clutchlab writes (``part-<time ns>-<pid>-<seq>.parquet``), and their temporaries.
_PART = re.compile(r"part-\d{20}-\d+-\d{6}\.parquet")
_PART_TMP = re.compile(r"part-\d{20}-\d+-\d{6}\.parquet\.\d+\.tmp")
#: Temporaries of spec.json and of the record (``write_file_atomic``; an older ``spec.json.tmp``).
_META_TMP = re.compile(
    r"(\.spec\.json\..+\.tmp|\.\.clutchlab-owned\.json\..+\.tmp|spec\.json\.tmp)"
)

#: Key of the consolidated file's Parquet metadata: the name of the newest part it holds.
NEWEST_PART_KEY = b"clutchlab.newest_part"
#: For a consolidated file without that record (an earlier clutchlab): a part counts as newer
#: only if its name's time is this much after the file's modification time (ns), as the two
#: come from different clocks (file times from a coarse kernel tick or a file server).
_MTIME_SLACK_NS = 2_000_000_000


class UnfinishedSweepWarning(UserWarning):
    """The results read are those of an unfinished run: the consolidated results file is
    missing (the sweep was stopped before it consolidated) or older than part files of a
    later, unfinished run.

    :func:`read_results` then reads the parts (the newest row per point), not the file.
    """


class OtherSpecResultsError(SpecError):
    """``--out`` holds results of a spec with another core: the spec itself is valid.

    A :class:`SpecError` (so a ``ValueError``) whose message does not call the spec invalid.
    """

    def __init__(self, message: str, source: str) -> None:
        super().__init__([message], source)
        self.args = (f"{source}: {message}",)


def _is_ours(parts: Path) -> bool:
    """Whether ``parts`` is a parts folder clutchlab wrote: its record, or an older spec.json."""
    if (parts / OWNED_NAME).exists():
        return has_ownership_record(parts)
    meta = parts / "spec.json"  # written by clutchlab before the record existed
    if meta.is_file() and not meta.is_symlink():
        try:
            return "core_hash" in json.loads(meta.read_text(encoding="utf-8"))
        except (OSError, ValueError, TypeError):
            return False
    return False


def check_parts_folder(parts: str | Path, what: str = "--out") -> bool:
    """Refuse a ``<out>.parts`` that is not clutchlab's (``OutputError``); True if it is ours.

    Missing or an empty folder: fine (False). A file there, or a non-empty folder without
    clutchlab's ownership record, is refused, naming it: nothing in it is read or touched.
    """
    parts = Path(parts)
    if parts.is_symlink() or (parts.exists() and not parts.is_dir()):
        raise OutputError(
            f"{what}: {parts} exists and is not a folder clutchlab wrote; move it away or "
            "choose another --out"
        )
    if not parts.exists():
        return False
    if _is_ours(parts):
        return True
    content = sorted(p.name for p in parts.iterdir())
    if content:
        shown = ", ".join(content[:5]) + (
            f" and {len(content) - 5} more" if len(content) > 5 else ""
        )
        raise OutputError(
            f"{what}: {parts} exists and clutchlab did not create it (no {OWNED_NAME}; it "
            f"holds {shown}); clutchlab keeps a sweep's part files there: move it away or "
            "choose another --out"
        )
    return False


def _write_table_synced(table: pa.Table, path: Path) -> None:
    pq.write_table(table, path)
    with open(path, "rb") as fh:
        os.fsync(fh.fileno())


def _atomic_write_table(table: pa.Table, path: Path) -> None:
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    try:
        _write_table_synced(table, tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


class ResultStore:
    """The part-file folder of one results file.

    Parameters
    ----------
    out : path
        The consolidated results file (``.parquet``); parts go to ``<out>.parts/``.
    core_hash : str
        Hash of the spec core; a folder written by another spec core is refused.
    spec_doc : dict
        JSON-ready description of the spec, written once to ``spec.json``.
    overwrite : bool
        Delete existing results and the part files clutchlab wrote first (a user's file in the
        parts folder is kept).

    Raises
    ------
    OutputError
        If ``<out>.parts`` exists and is not clutchlab's (:func:`check_parts_folder`).
    SpecError
        If the parts folder belongs to a spec with a different core (model, scenario,
        simulation or metric settings) and ``overwrite`` is false.
    """

    def __init__(
        self, out: str | Path, core_hash: str, spec_doc: dict[str, Any], overwrite: bool = False
    ) -> None:
        self.out = Path(out)
        self.parts = self.out.with_name(self.out.name + ".parts")
        check_parts_folder(self.parts)
        self.parts.mkdir(parents=True, exist_ok=True)
        meta = self.parts / "spec.json"
        if overwrite:
            self._remove_ours(meta)
            self.out.unlink(missing_ok=True)
        for stray in self.parts.iterdir():
            if _PART_TMP.fullmatch(stray.name) or _META_TMP.fullmatch(stray.name):
                stray.unlink(missing_ok=True)
        record = ownership_record(
            ["spec.json"],
            "sweep parts",
            part_files="part-<time ns>-<pid>-<seq>.parquet (and their .tmp while written)",
        )
        write_file_atomic(self.parts / OWNED_NAME, record, overwrite=True)
        if meta.exists():
            try:
                old = json.loads(meta.read_text(encoding="utf-8")).get("core_hash")
            except (OSError, ValueError, AttributeError) as exc:
                raise OutputError(
                    f"--out {self.out}: {meta} cannot be read ({exc}); use --overwrite to "
                    "start these results again"
                ) from exc
            if old != core_hash:
                raise OtherSpecResultsError(
                    f"{self.parts} holds results of another spec (core {old}, this one "
                    f"{core_hash}): model, scenario, simulation or metrics changed; "
                    "use another --out or --overwrite",
                    str(self.out),
                )
        else:
            doc = {"core_hash": core_hash} | spec_doc
            text = json.dumps(doc, indent=2, default=list) + "\n"
            write_file_atomic(meta, text.encode("utf-8"))
        self._seq = 0

    def _remove_ours(self, meta: Path) -> None:
        """Delete the part files and spec.json clutchlab wrote; every other file stays."""
        for f in self.parts.iterdir():
            if _PART.fullmatch(f.name) or _PART_TMP.fullmatch(f.name):
                f.unlink(missing_ok=True)
        meta.unlink(missing_ok=True)

    @staticmethod
    def stored_ids(out: str | Path) -> list[str]:
        """Point ids with a row in ``<out>.parts`` (read only; nothing is created)."""
        out = Path(out)
        parts = out.with_name(out.name + ".parts")
        files = sorted(f for f in parts.glob("part-*.parquet") if _PART.fullmatch(f.name))
        ids: list[str] = []
        for f in files:
            ids += pq.read_table(f, columns=["point_id"]).column(0).to_pylist()
        return ids

    def part_files(self) -> list[Path]:
        """Complete part files, oldest first."""
        return sorted(f for f in self.parts.glob("part-*.parquet") if _PART.fullmatch(f.name))

    def read(self, files: list[Path] | None = None) -> pd.DataFrame:
        """Every row of every part (duplicates kept, oldest first); of ``files`` if given."""
        files = self.part_files() if files is None else files
        if not files:
            return pd.DataFrame()
        return pd.concat([pq.read_table(f).to_pandas() for f in files], ignore_index=True)

    def append(self, rows: list[dict[str, Any]]) -> Path | None:
        """Write ``rows`` as one new part file (atomically); None for no rows."""
        if not rows:
            return None
        self._seq += 1
        name = f"part-{time.time_ns():020d}-{os.getpid()}-{self._seq:06d}.parquet"
        path = self.parts / name
        _atomic_write_table(pa.Table.from_pylist(rows), path)
        return path

    def consolidate(self, point_ids: list[str]) -> pd.DataFrame:
        """Write ``out``: one row per id in ``point_ids`` that has a result, design order.

        Rows of points not in ``point_ids`` (another sampling of the same spec core) stay in
        the parts but are left out; of repeated ids the newest row is kept. The name of the
        newest part read is recorded in the file's metadata (``NEWEST_PART_KEY``).

        Returns
        -------
        pandas.DataFrame
            The table written.
        """
        files = self.part_files()
        df = self.read(files)
        if df.empty:
            return df
        df = df.drop_duplicates("point_id", keep="last")
        order = {pid: k for k, pid in enumerate(point_ids)}
        df = df[df["point_id"].isin(order)].copy()
        df["index"] = df["point_id"].map(order).astype("int64")
        df = df.sort_values("index").reset_index(drop=True)
        table = pa.Table.from_pandas(df, preserve_index=False)
        meta = dict(table.schema.metadata or {})
        meta[NEWEST_PART_KEY] = files[-1].name.encode("ascii")
        table = table.replace_schema_metadata(meta)
        write_file_atomic(self.out, lambda tmp: _write_table_synced(table, tmp), overwrite=True)
        return df


def _newer_parts(path: Path, files: list[Path]) -> list[Path]:
    """The part files (of ``files``, oldest first) written after ``path`` was consolidated."""
    try:
        newest = (pq.read_schema(path).metadata or {}).get(NEWEST_PART_KEY)
    except (OSError, pa.ArrowException):
        newest = None  # not readable as Parquet: pandas reports that below
    if newest is not None:
        newest_name = newest.decode("ascii", errors="replace")
        return [f for f in files if f.name > newest_name]  # names sort by their time (ns)
    limit = path.stat().st_mtime_ns + _MTIME_SLACK_NS
    return [f for f in files if int(f.name.split("-")[1]) > limit]


def read_results(path: str | Path) -> pd.DataFrame:
    """Read a sweep's results: the consolidated file, else the parts of an unfinished sweep.

    The consolidated file is read unless part files newer than it lie beside it: a later run
    (an extended sweep of the same spec, or one with ``retry_failed``) was stopped before it
    consolidated. Then, and when there is no consolidated file, the parts are read as for an
    unfinished sweep, with an :class:`UnfinishedSweepWarning`; running that sweep again
    finishes and consolidates it.

    Parameters
    ----------
    path : path
        The ``--out`` file of the sweep.

    Returns
    -------
    pandas.DataFrame
        One row per point (``point_id``, ``index``, ``status``, ``error``, design variables,
        metrics, ``wall_s`` and ``cpu_s``: wall and CPU time of the point, s); read from the
        parts, the newest row of each point, in ``index`` order.

    Raises
    ------
    FileNotFoundError
        Neither the file nor any part file exists.
    DataError
        ``path`` is a folder (e.g. the ``.parts`` folder) or a file that is not Parquet.

    Warns
    -----
    UnfinishedSweepWarning
        The consolidated file is missing, or older than part files of an unfinished run.
    """
    path = Path(path)
    if path.is_dir():
        hint = (
            f"pass the sweep's --out file ({path.with_name(path.name[: -len('.parts')])}), "
            "not its parts folder"
            if path.name.endswith(".parts")
            else "pass the --out file (.parquet) of a sweep"
        )
        raise DataError(f"{path}: is a folder, not a sweep's results file; {hint}")
    parts = path.with_name(path.name + ".parts")
    files = sorted(f for f in parts.glob("part-*.parquet") if _PART.fullmatch(f.name))
    if path.exists():
        newer = _newer_parts(path, files) if files else []
        if not newer:
            try:
                return pd.read_parquet(path)
            except (OSError, pa.ArrowException) as exc:
                raise DataError(
                    f"{path}: not a sweep's results file (not readable as Parquet: {exc})"
                ) from None
        warnings.warn(
            f"{path} is older than {len(newer)} part file{'s' if len(newer) > 1 else ''} of "
            f"an unfinished run in {parts}: read the parts instead (the newest row of each "
            "point); run that sweep again to finish and consolidate it",
            UnfinishedSweepWarning,
            stacklevel=2,
        )
    if not files:
        raise FileNotFoundError(f"no results at {path} (nor parts in {parts})")
    if not path.exists():
        warnings.warn(
            f"{path} does not exist: the sweep was stopped before it consolidated; read the "
            f"{len(files)} part file{'s' if len(files) > 1 else ''} in {parts} instead (the "
            "newest row of each point, not every point of the design); run that sweep again "
            "to finish and consolidate it",
            UnfinishedSweepWarning,
            stacklevel=2,
        )
    df = pd.concat([pd.read_parquet(f) for f in files], ignore_index=True)
    return df.drop_duplicates("point_id", keep="last").sort_values("index", ignore_index=True)
