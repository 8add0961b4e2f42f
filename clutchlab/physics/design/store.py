"""Kill-safe result storage of a sweep: atomic Parquet part files, consolidated at the end.

Layout for ``--out results.parquet``::

    results.parquet          consolidated table (written at the end, atomically)
    results.parquet.parts/   spec.json + part-<ns>-<pid>-<seq>.parquet, one per flush

A part file is written to a temporary name, flushed to disk and renamed into place, so a
killed sweep leaves only complete part files (and perhaps a stray ``*.tmp``, removed on the
next start). A restarted sweep reads the parts, skips the points already there and appends
new parts; consolidation keeps one row per point id (the newest).
"""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from .spec import SpecError

__all__ = ["ResultStore", "read_results"]


def _atomic_write_table(table: pa.Table, path: Path) -> None:
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp")
    pq.write_table(table, tmp)
    with open(tmp, "rb") as fh:
        os.fsync(fh.fileno())
    os.replace(tmp, path)


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
        Delete existing results and parts first.

    Raises
    ------
    SpecError
        If the parts folder belongs to a spec with a different core (model, scenario,
        simulation or metric settings) and ``overwrite`` is false.
    """

    def __init__(
        self, out: str | Path, core_hash: str, spec_doc: dict[str, Any], overwrite: bool = False
    ) -> None:
        self.out = Path(out)
        self.parts = self.out.with_name(self.out.name + ".parts")
        if overwrite:
            shutil.rmtree(self.parts, ignore_errors=True)
            self.out.unlink(missing_ok=True)
        self.parts.mkdir(parents=True, exist_ok=True)
        for stray in self.parts.glob("*.tmp"):
            stray.unlink(missing_ok=True)
        meta = self.parts / "spec.json"
        if meta.exists():
            old = json.loads(meta.read_text(encoding="utf-8")).get("core_hash")
            if old != core_hash:
                raise SpecError(
                    [
                        f"{self.parts} holds results of another spec (core {old}, this one "
                        f"{core_hash}): model, scenario, simulation or metrics changed; "
                        "use another --out or --overwrite"
                    ],
                    str(self.out),
                )
        else:
            doc = {"core_hash": core_hash} | spec_doc
            tmp = meta.with_suffix(".json.tmp")
            tmp.write_text(json.dumps(doc, indent=2, default=list) + "\n", encoding="utf-8")
            os.replace(tmp, meta)
        self._seq = 0

    def part_files(self) -> list[Path]:
        """Complete part files, oldest first."""
        return sorted(self.parts.glob("part-*.parquet"))

    def read(self) -> pd.DataFrame:
        """Every row of every part (duplicates kept, oldest first)."""
        files = self.part_files()
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
        the parts but are left out; of repeated ids the newest row is kept.

        Returns
        -------
        pandas.DataFrame
            The table written.
        """
        df = self.read()
        if df.empty:
            return df
        df = df.drop_duplicates("point_id", keep="last")
        order = {pid: k for k, pid in enumerate(point_ids)}
        df = df[df["point_id"].isin(order)].copy()
        df["index"] = df["point_id"].map(order).astype("int64")
        df = df.sort_values("index").reset_index(drop=True)
        _atomic_write_table(pa.Table.from_pandas(df, preserve_index=False), self.out)
        return df


def read_results(path: str | Path) -> pd.DataFrame:
    """Read a sweep's results: the consolidated file, else the parts of an unfinished sweep.

    Parameters
    ----------
    path : path
        The ``--out`` file of the sweep.

    Returns
    -------
    pandas.DataFrame
        One row per point (``point_id``, ``index``, ``status``, ``error``, design variables,
        metrics, ``wall_s`` and ``cpu_s``: wall and CPU time of the point, s).
    """
    path = Path(path)
    if path.exists():
        return pd.read_parquet(path)
    parts = path.with_name(path.name + ".parts")
    files = sorted(parts.glob("part-*.parquet"))
    if not files:
        raise FileNotFoundError(f"no results at {path} (nor parts in {parts})")
    df = pd.concat([pd.read_parquet(f) for f in files], ignore_index=True)
    return df.drop_duplicates("point_id", keep="last").sort_values("index", ignore_index=True)
