"""Where batches of design points run: local worker processes or a Dask cluster.

Both executors take batches and yield ``(batch, rows)`` as batches finish, in completion
order. A batch whose task itself fails (a worker process killed, a lost Dask worker) yields
``failed`` rows carrying the exception, so the sweep goes on.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import uuid
from collections.abc import Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any

from . import lifetime
from .evaluate import STATUS_FAILED, evaluate_batch
from .sampling import DesignPoint
from .spec import SweepSpec

__all__ = ["run_dask", "run_local"]

Batch = list[DesignPoint]


def _failed_rows(batch: Batch, exc: BaseException) -> list[dict[str, Any]]:
    msg = f"{type(exc).__name__}: {exc} (task failed, not the point's simulation)"
    return [
        {"point_id": p.point_id, "index": p.index, "status": STATUS_FAILED, "error": msg}
        | dict(p.values)
        for p in batch
    ]


def _worker_context():
    """``forkserver`` preloaded with the evaluator where available, else ``spawn``.

    The fork server and every worker die with this process (:mod:`.lifetime`).
    """
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload([lifetime.__name__, evaluate_batch.__module__])
        os.environ[lifetime.FORKSERVER_ENV] = str(os.getpid())  # read by the server it starts
        return ctx
    return multiprocessing.get_context("spawn")


def run_local(
    spec: SweepSpec, batches: list[Batch], workers: int
) -> Iterator[tuple[Batch, list[dict[str, Any]]]]:
    """Evaluate ``batches`` in ``workers`` local processes (in this process when 1).

    Worker processes are forked from a fork server that has imported the evaluator once
    (``forkserver`` start method; ``spawn`` where there is none, e.g. Windows): no state is
    inherited from the parent, and the workers skip the ~1–2 s import of clutchlab and its
    dependencies that dominated short sweeps. At most ``2 · workers`` batches are queued.
    Workers ignore Ctrl-C; when the consumer stops early (Ctrl-C, an error, ``close()``) the
    queued batches are cancelled and the workers are killed at once rather than waited for
    (their batches in progress are lost; what was yielded is the consumer's).

    Yields
    ------
    batch, rows
        A finished batch and its result rows.
    """
    if workers <= 1:
        for batch in batches:
            yield batch, evaluate_batch(spec, batch)
        return
    ctx = _worker_context()
    pending: dict[Future, Batch] = {}
    todo = iter(batches)
    pool = ProcessPoolExecutor(
        max_workers=workers, mp_context=ctx, initializer=lifetime.init_worker
    )
    finished = False
    try:
        while True:
            while len(pending) < 2 * workers:
                batch = next(todo, None)
                if batch is None:
                    break
                pending[pool.submit(evaluate_batch, spec, batch)] = batch
            if not pending:
                finished = True
                return
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                batch = pending.pop(fut)
                try:
                    rows = fut.result()
                except Exception as exc:
                    rows = _failed_rows(batch, exc)
                yield batch, rows
    finally:
        if finished:
            pool.shutdown(wait=True)
        else:
            _stop_now(pool)


def _stop_now(pool: ProcessPoolExecutor) -> None:
    """Cancel what is queued and kill the workers, without waiting for running batches."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        with contextlib.suppress(OSError, ValueError, AttributeError):
            proc.kill()
    for proc in procs:
        with contextlib.suppress(OSError, ValueError, AttributeError):
            proc.join(timeout=5)


def run_dask(
    spec: SweepSpec, batches: list[Batch], client: Any
) -> Iterator[tuple[Batch, list[dict[str, Any]]]]:
    """Evaluate ``batches`` on a Dask cluster.

    Parameters
    ----------
    spec : SweepSpec
        The spec (scattered to every worker once).
    batches : list of list of DesignPoint
        The work.
    client : distributed.Client
        Connected to the cluster. The workers need clutchlab installed (same version) and a C
        compiler for the compiled model (else the model is interpreted: slower, and the last
        bits of the numbers may differ from a compiled run).

    Yields
    ------
    batch, rows
        A finished batch and its result rows.
    """
    from distributed import as_completed

    if not batches:
        return
    [spec_f] = client.scatter([spec], broadcast=True)
    run = uuid.uuid4().hex[:8]
    futures = {
        client.submit(evaluate_batch, spec_f, b, key=f"clutchlab-sweep-{run}-{k}"): b
        for k, b in enumerate(batches)
    }
    try:
        for fut in as_completed(futures):
            batch = futures[fut]
            try:
                rows = fut.result()
            except Exception as exc:
                rows = _failed_rows(batch, exc)
            fut.release()
            yield batch, rows
    finally:
        for fut in futures:
            if not fut.done():
                fut.cancel()
