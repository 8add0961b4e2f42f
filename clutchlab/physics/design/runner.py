"""Run a sweep: skip finished points, evaluate the rest locally or on Dask, store as they finish."""

from __future__ import annotations

import contextlib
import math
import os
import re
import time
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import pandas as pd
from tqdm.auto import tqdm

from ...data.output import check_output
from ...errors import ClutchlabError, OutputError
from ...forkmap import usable_cpus
from .evaluate import STATUS_FAILED, STATUS_OK
from .executors import run_dask, run_local
from .metrics import metric_names
from .sampling import DesignPoint, design_points
from .spec import SpecError, SweepSpec
from .store import ResultStore, check_parts_folder

__all__ = ["SchedulerError", "SweepInterrupted", "SweepNote", "SweepResult", "run_sweep"]


class SchedulerError(ClutchlabError, ConnectionError):
    """``scheduler`` is not a Dask scheduler address, or none answers there.

    Raised before any output (lock, parts folder) is created.
    """


class SweepNote(UserWarning):
    """Something the user should know that does not stop the sweep (a stale lock taken over)."""


class SweepInterrupted(KeyboardInterrupt):
    """A sweep stopped by Ctrl-C (``KeyboardInterrupt``): what finished is kept.

    Attributes
    ----------
    out : Path
        The results file of the sweep.
    parts : Path
        The folder that keeps the finished points.
    n_kept : int
        Points of this design finished (ok or failed) and kept in ``parts``.
    n_points : int
        Points in the design.
    """

    def __init__(self, out: Path, n_kept: int, n_points: int) -> None:
        self.out = Path(out)
        self.parts = self.out.with_name(self.out.name + ".parts")
        self.n_kept, self.n_points = n_kept, n_points
        super().__init__(
            f"interrupted; {n_kept} of {n_points} points kept in {self.parts}; run the same "
            "command to continue"
        )


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
        Worker processes started (local: at most one per batch) or Dask workers at the start.
    figures : tuple of Path
        Figure files written.
    n_failed_run : int
        Points evaluated by this call that failed (``n_failed`` counts earlier calls' too).
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
    n_failed_run: int = 0

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
            "n_failed_run": self.n_failed_run,
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
    spec: SweepSpec | str | os.PathLike,
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
    spec : SweepSpec or path
        The validated spec (:func:`load_spec`), or the spec file (TOML) to load.
    out : path
        Consolidated results file (Parquet); part files go to ``<out>.parts/``, figures to
        ``<out>.figures/``.
    workers : int, optional
        Local worker processes, ≥ 1 (default: the CPUs this process may use; 1: in this
        process), at most one per batch of points; ignored with ``scheduler``.
    scheduler : str or distributed.Client, optional
        Run on this Dask cluster (address such as ``tcp://10.0.0.5:8786``, or a client).
    progress : bool
        Show a progress bar.
    overwrite : bool
        Discard existing results first, and the figures clutchlab drew of them.
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
    OutputError
        ``out``, ``<out>.parts/`` or ``<out>.figures/`` holds something clutchlab did not write
        where it would write (before anything is done, see :func:`check_sweep_output`).
    SchedulerError
        ``scheduler`` is not an address or no scheduler answers there (before any output is
        created).
    SpecError
        If ``out`` holds results of a spec with another core and ``overwrite`` is false.
    SweepInterrupted
        Ctrl-C (a ``KeyboardInterrupt``): the finished points are kept in ``<out>.parts/``,
        the lock is released, and the same call continues the sweep.
    """
    if isinstance(spec, str | os.PathLike):
        from .spec import load_spec

        spec = load_spec(spec)
    if not isinstance(spec, SweepSpec):
        raise TypeError(f"run_sweep: spec must be a SweepSpec or a spec file, not {spec!r}")
    from .spec_parse import check_spec

    check_spec(spec)  # a spec built or changed in code is checked as a file is
    _check_run_arguments(workers, batch_size, flush_s)
    t0 = time.perf_counter()
    out = check_sweep_output(out, overwrite, figures=figures)
    client, own_client = _connect(scheduler)  # before the lock and the parts folder exist
    try:
        _make_parent(out)  # --out new/r.parquet: the lock file goes into new/
        with output_lock(out):
            try:
                return _run_locked(
                    spec, out, t0, workers, client, progress, overwrite, retry_failed,
                    figures, batch_size, flush_s,
                )  # fmt: skip
            except KeyboardInterrupt:
                raise SweepInterrupted(out, _n_kept(spec, out), len(design_points(spec))) from None
    finally:
        if own_client:
            with contextlib.suppress(Exception):
                client.close()


def _make_parent(out: Path) -> None:
    """Create the folder of ``out`` (checked writable by :func:`check_sweep_output`)."""
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(
            f"--out {out}: cannot create its folder {out.parent} ({exc.strerror or exc})"
        ) from exc


def _n_kept(spec: SweepSpec, out: Path) -> int:
    """Points of ``spec``'s design with a row in ``<out>.parts`` (0 if it cannot be read)."""
    try:
        ids = set(ResultStore.stored_ids(out))
    except Exception:  # only for the message: never hide the interrupt behind another error
        return 0
    return sum(p.point_id in ids for p in design_points(spec))


def _connect(scheduler: Any) -> tuple[Any, bool]:
    """``(client, own_client)`` for ``scheduler`` (None: no client), or ``SchedulerError``."""
    if scheduler is None:
        return None, False
    from distributed import Client

    if isinstance(scheduler, Client):
        return scheduler, False
    if isinstance(scheduler, str):
        from distributed.comm import parse_address
        from distributed.comm.addressing import parse_host_port

        try:
            scheme, location = parse_address(scheduler)
            if scheme in ("tcp", "tls", "ws", "wss"):
                parse_host_port(location)
        except ValueError as exc:
            raise SchedulerError(
                f"--scheduler {scheduler!r}: not a scheduler address ({exc}); expected "
                "tcp://HOST:PORT, e.g. tcp://10.0.0.5:8786"
            ) from None
    try:
        return Client(scheduler), True
    except (OSError, ValueError, TypeError) as exc:
        reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise SchedulerError(
            f"--scheduler {scheduler}: cannot connect to a Dask scheduler ({reason})"
        ) from None


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


def check_sweep_output(out: str | Path, overwrite: bool = False, *, figures: bool = True) -> Path:
    """Check everything a sweep writes before any work (``SpecError`` / ``OutputError``).

    The results file must be named ``*.parquet``; an existing one is replaced only with
    ``overwrite``, unless it is this kind of sweep's own results (clutchlab's
    ``<out>.parts/`` beside it), which a restart continues. ``<out>.parts/`` and (with
    ``figures``) ``<out>.figures/`` must be missing, empty or clutchlab's, and no user's file
    may stand where clutchlab writes one (:func:`~.store.check_parts_folder`,
    :func:`~.figures.check_figures_folder`); ``<out>.lock`` must be missing or a lock file
    (a PID).
    """
    out = Path(out)
    if out.suffix.lower() != ".parquet":
        raise SpecError(
            [f"--out {out}: results are written as Parquet; name the file *.parquet"], str(out)
        )
    _check_lock_file(out.with_name(out.name + ".lock"))
    ours = check_parts_folder(out.with_name(out.name + ".parts"))
    if figures:
        from .figures import check_figures_folder

        check_figures_folder(out.with_name(out.name + ".figures"), what="--out: figures")
    return check_output(out, kind="file", overwrite=overwrite or ours, what="--out")


_LOCK_TEXT = re.compile(rb"\s*\d*\s*")


def _check_lock_file(lock: Path) -> None:
    """A ``<out>.lock`` that exists must be a lock file (empty or a PID), never a user's file."""
    if not (lock.exists() or lock.is_symlink()):
        return
    if lock.is_symlink() or not lock.is_file():
        raise OutputError(f"--out: {lock} exists and is not a clutchlab lock file; move it away")
    try:
        with open(lock, "rb") as fh:
            head = fh.read(64)
    except OSError as exc:
        raise OutputError(f"--out: {lock} cannot be read ({exc.strerror or exc})") from exc
    if not _LOCK_TEXT.fullmatch(head):
        raise OutputError(
            f"--out: {lock} exists and is not a clutchlab lock file (it holds more than a "
            "process id); clutchlab would replace it: move it away or choose another --out"
        )


@contextlib.contextmanager
def output_lock(out: Path):
    """Hold an exclusive lock on ``<out>.lock`` for the whole run (POSIX ``flock``).

    A second sweep on the same ``--out`` fails at once, naming the process that holds it. The
    lock file holds the holder's PID and is removed when the run ends, also by an error or
    Ctrl-C. The lock itself is the kernel's ``flock``, released when its process dies: the
    file a killed sweep leaves behind blocks nothing, and the next sweep takes it over with a
    :class:`SweepNote` naming the PID it held.
    """
    try:
        import fcntl
    except ImportError:  # no flock (Windows): no lock
        yield
        return
    lock = out.with_name(out.name + ".lock")
    _check_lock_file(lock)
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "another process"
            os.close(fd)
            raise OutputError(
                f"--out {out}: another sweep (PID {holder}) is writing these results; wait "
                "for it or choose another --out"
            ) from None
        except BaseException:
            os.close(fd)
            raise
        # A sweep ending just now removes the file it locked: lock the file at the path.
        try:
            here = os.stat(lock, follow_symlinks=False)
            mine = os.fstat(fd)
            if (here.st_dev, here.st_ino) == (mine.st_dev, mine.st_ino):
                break
        except FileNotFoundError:
            pass
        os.close(fd)
    try:
        stale = os.pread(fd, 32, 0).decode(errors="replace").strip()
        if stale.isdigit() and int(stale) != os.getpid():
            warnings.warn(
                f"{lock} was left by sweep PID {stale}, which stopped without removing it "
                "(it no longer holds the lock); taken over",
                SweepNote,
                stacklevel=3,
            )
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        yield
    finally:
        with contextlib.suppress(OSError):
            lock.unlink()  # while still holding it: a waiting sweep then re-opens the path
        os.close(fd)


def _run_locked(
    spec, out, t0, workers, client, progress, overwrite, retry_failed, figures, batch_size,
    flush_s,
) -> SweepResult:  # fmt: skip
    points = design_points(spec)
    store = ResultStore(out, spec.core_hash, _spec_doc(spec), overwrite=overwrite)
    if overwrite:  # the figures of the discarded results go with them (drawn again at the end)
        from .figures import remove_figures

        remove_figures(out.with_name(out.name + ".figures"))
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
    if client is not None:
        backend, n_workers = "dask", len(client.nthreads())
    else:
        backend, n_workers = "local", max(1, workers or usable_cpus())
    batches = _batches(todo, n_workers, batch_size)
    if client is None:  # no more processes than batches: the count reported is the count run
        n_workers = max(1, min(n_workers, len(batches)))
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
        stream.close()  # stop the workers (on Ctrl-C or an error)
        store.append(buffer)  # also on Ctrl-C: keep what finished
        bar.close()
    table = store.consolidate([p.point_id for p in points])
    wall = time.perf_counter() - t0
    n_failed = int((table["status"] == STATUS_FAILED).sum()) if len(table) else 0
    written: tuple[Path, ...] = ()
    if figures and len(table):
        from .figures import write_figures

        try:
            written = write_figures(table, spec, store.out.with_name(store.out.name + ".figures"))
        except OutputError as exc:  # e.g. a user's file put there during the run
            warnings.warn(
                f"figures not written: {exc}; the results are complete in {store.out}",
                SweepNote,
                stacklevel=3,
            )
    return SweepResult(
        spec, table, store.out, len(points), len(todo), n_failed, wall, backend, n_workers,
        written, n_failed_now,
    )  # fmt: skip
