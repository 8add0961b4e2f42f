"""Run a sweep: skip finished points, evaluate the rest locally or on Dask, store as they finish."""

from __future__ import annotations

import contextlib
import math
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import pandas as pd
from tqdm.auto import tqdm

from ...data.output import check_output
from ...errors import OutputError
from .evaluate import STATUS_FAILED, STATUS_OK
from .executors import run_dask, run_local
from .metrics import metric_names
from .sampling import DesignPoint, design_points
from .spec import SpecError, SweepSpec
from .store import ResultStore

__all__ = ["SweepResult", "run_sweep"]


@dataclass(frozen=True)
class SweepResult:
    """What :func:`run_sweep` returns.

    Attributes
    ----------
    spec : SweepSpec
        The spec run.
    table : pandas.DataFrame
        One row per design point, design order (see :func:`read_results`).
    out : Path
        The consolidated results file.
    n_points : int
        Points in the design.
    n_run : int
        Points evaluated by this call (the others were already in the results).
    n_failed : int
        Points recorded as failed (all calls).
    wall_s : float
        Wall time of this call (s), figures excluded.
    backend : str
        ``local`` or ``dask``.
    workers : int
        Worker processes (local) or Dask workers at the start.
    figures : tuple of Path
        Figure files written.
    """

    spec: SweepSpec
    table: pd.DataFrame
    out: Path
    n_points: int
    n_run: int
    n_failed: int
    wall_s: float
    backend: str
    workers: int
    figures: tuple[Path, ...] = ()

    @property
    def n_skipped(self) -> int:
        """Points found already finished at the start."""
        return self.n_points - self.n_run

    @property
    def points_per_s(self) -> float:
        """Throughput of this call (points/s)."""
        return self.n_run / self.wall_s if self.wall_s > 0 else float("nan")

    @property
    def metric_names(self) -> tuple[str, ...]:
        """Metric columns of the table."""
        sc = self.spec.scenario
        return metric_names(tuple(r.label for r in sc.ramps), sc.step is not None)

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary: counts, timing, paths, failures (first 20)."""
        failed = self.table[self.table["status"] == STATUS_FAILED] if len(self.table) else []
        return {
            "name": self.spec.name,
            "out": str(self.out),
            "core_hash": self.spec.core_hash,
            "n_points": self.n_points,
            "n_run": self.n_run,
            "n_skipped": self.n_skipped,
            "n_ok": int((self.table["status"] == STATUS_OK).sum()) if len(self.table) else 0,
            "n_failed": self.n_failed,
            "wall_s": self.wall_s,
            "points_per_s": self.points_per_s,
            "backend": self.backend,
            "workers": self.workers,
            "figures": [str(f) for f in self.figures],
            "failures": [
                {"point_id": r.point_id, "error": r.error} for r in list(failed.itertuples())[:20]
            ]
            if len(failed)
            else [],
        }


def _batches(points: list[DesignPoint], workers: int, size: int | None) -> list[list]:
    if size is None:
        size = max(1, min(8, math.ceil(len(points) / (16 * max(workers, 1)))))
    return [points[k : k + size] for k in range(0, len(points), size)]


def _normalize(rows: list[dict[str, Any]], columns: list[str]) -> list[dict[str, Any]]:
    out = []
    for r in rows:
        row = {c: r.get(c, float("nan")) for c in columns}
        row["error"] = str(row["error"]) if isinstance(row["error"], str) else ""
        out.append(row)
    return out


def _spec_doc(spec: SweepSpec) -> dict[str, Any]:
    return {
        "name": spec.name,
        "source": spec.source,
        "core": spec.core(),
        "sampling": asdict(spec.sampling),
        "variables": [asdict(v) for v in spec.variables],
    }


def run_sweep(
    spec: SweepSpec,
    out: str | Path,
    *,
    workers: int | None = None,
    scheduler: Any = None,
    progress: bool = True,
    overwrite: bool = False,
    retry_failed: bool = False,
    figures: bool = True,
    batch_size: int | None = None,
    flush_s: float = 5.0,
) -> SweepResult:
    """Evaluate every design point of ``spec`` not yet in ``out``; write results and figures.

    Parameters
    ----------
    spec : SweepSpec
        The validated spec (:func:`load_spec`).
    out : path
        Consolidated results file (Parquet); part files go to ``<out>.parts/``, figures to
        ``<out>.figures/``.
    workers : int, optional
        Local worker processes, ≥ 1 (default: CPU count; 1: in this process); ignored with
        ``scheduler``.
    scheduler : str or distributed.Client, optional
        Run on this Dask cluster (address such as ``tcp://10.0.0.5:8786``, or a client).
    progress : bool
        Show a progress bar.
    overwrite : bool
        Discard existing results first.
    retry_failed : bool
        Evaluate points recorded as failed again (default: a failed point counts as done).
    figures : bool
        Write the tornado and metric-vs-variable figures.
    batch_size : int, optional
        Points per task, ≥ 1 (default: 1–8, so that each worker gets ≥ 16 tasks).
    flush_s : float
        Write finished rows to a new part file at least this often (s, ≥ 0); 0: after every
        batch. A killed sweep loses at most the rows of the last ``flush_s``.

    Returns
    -------
    SweepResult

    Raises
    ------
    ValueError
        ``workers``, ``batch_size`` or ``flush_s`` out of range (before anything is done).
    SpecError
        If ``out`` holds results of a spec with another core and ``overwrite`` is false.
    """
    _check_run_arguments(workers, batch_size, flush_s)
    t0 = time.perf_counter()
    out = check_sweep_output(out, overwrite)
    with output_lock(out):
        return _run_locked(
            spec, out, t0, workers, scheduler, progress, overwrite, retry_failed, figures,
            batch_size, flush_s,
        )  # fmt: skip


def _check_run_arguments(workers: Any, batch_size: Any, flush_s: Any) -> None:
    """Range checks of :func:`run_sweep`'s settings, every problem at once (``ValueError``)."""
    problems = []
    for name, value in (("workers", workers), ("batch_size", batch_size)):
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            problems.append(f"{name} must be an integer ≥ 1, not {value!r}")
    if isinstance(flush_s, bool) or not isinstance(flush_s, int | float):
        problems.append(f"flush_s must be a number of seconds ≥ 0, not {flush_s!r}")
    elif not (math.isfinite(flush_s) and flush_s >= 0):
        problems.append(f"flush_s must be ≥ 0 s and finite, not {flush_s!r}")
    if problems:
        raise ValueError("run_sweep: " + "; ".join(problems))


def check_sweep_output(out: str | Path, overwrite: bool = False) -> Path:
    """Check a sweep's results file before any work (``SpecError`` / ``OutputError``).

    It must be named ``*.parquet``; an existing file is replaced only with ``overwrite``,
    unless it is this kind of sweep's own results (``<out>.parts/spec.json`` beside it),
    which a restart continues.
    """
    out = Path(out)
    if out.suffix.lower() != ".parquet":
        raise SpecError(
            [f"--out {out}: results are written as Parquet; name the file *.parquet"], str(out)
        )
    ours = (out.with_name(out.name + ".parts") / "spec.json").is_file()
    return check_output(out, kind="file", overwrite=overwrite or ours, what="--out")


@contextlib.contextmanager
def output_lock(out: Path):
    """Hold an exclusive lock on ``<out>.lock`` for the whole run (POSIX ``flock``).

    A second sweep on the same ``--out`` fails at once, naming the process that holds it.
    """
    try:
        import fcntl
    except ImportError:  # no flock (Windows): no lock
        yield
        return
    lock = out.with_name(out.name + ".lock")
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "another process"
            raise OutputError(
                f"--out {out}: another sweep (PID {holder}) is writing these results; wait "
                "for it or choose another --out"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        yield
        lock.unlink(missing_ok=True)
    finally:
        os.close(fd)


def _run_locked(
    spec, out, t0, workers, scheduler, progress, overwrite, retry_failed, figures, batch_size,
    flush_s,
) -> SweepResult:  # fmt: skip
    points = design_points(spec)
    store = ResultStore(out, spec.core_hash, _spec_doc(spec), overwrite=overwrite)
    done = store.read()
    finished: set[str] = set()
    if not done.empty:
        keep = done if not retry_failed else done[done["status"] == STATUS_OK]
        finished = set(keep["point_id"])
    todo = [p for p in points if p.point_id not in finished]
    columns = ["point_id", "index", "status", "error", *spec.variable_names]
    sc = spec.scenario
    columns += [*metric_names(tuple(r.label for r in sc.ramps), sc.step is not None)]
    columns += ["wall_s", "cpu_s"]
    client, own_client = None, False
    if scheduler is not None:
        from distributed import Client

        own_client = not isinstance(scheduler, Client)
        client = Client(scheduler) if own_client else scheduler
        backend, n_workers = "dask", len(client.nthreads())
    else:
        backend, n_workers = "local", max(1, workers or os.cpu_count() or 1)
    batches = _batches(todo, n_workers, batch_size)
    stream = (
        run_dask(spec, batches, client)
        if client is not None
        else run_local(spec, batches, n_workers)
    )
    buffer: list[dict[str, Any]] = []
    last_flush, n_failed_now = time.perf_counter(), 0
    bar = tqdm(total=len(todo), desc="sweep", unit="pt", disable=not progress)
    try:
        for _, rows in stream:
            rows = _normalize(rows, columns)
            buffer += rows
            n_failed_now += sum(r["status"] == STATUS_FAILED for r in rows)
            bar.update(len(rows))
            bar.set_postfix(failed=n_failed_now, refresh=False)
            if time.perf_counter() - last_flush >= flush_s:
                store.append(buffer)
                buffer, last_flush = [], time.perf_counter()
    finally:
        stream.close()  # stop the workers' queue (on Ctrl-C or an error)
        store.append(buffer)  # also on Ctrl-C: keep what finished
        bar.close()
        if own_client:
            client.close()
    table = store.consolidate([p.point_id for p in points])
    wall = time.perf_counter() - t0
    n_failed = int((table["status"] == STATUS_FAILED).sum()) if len(table) else 0
    written: tuple[Path, ...] = ()
    if figures and len(table):
        from .figures import write_figures

        written = write_figures(table, spec, store.out.with_name(store.out.name + ".figures"))
    return SweepResult(
        spec, table, store.out, len(points), len(todo), n_failed, wall, backend, n_workers, written
    )
