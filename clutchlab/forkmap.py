"""Independent jobs on forked worker processes, their inputs inherited rather than pickled.

The jobs this is for (one fold of a leave-one-experiment-out, one experiment's simulation)
read large inputs (traces of 10⁵–10⁶ samples, fitted models) and return small results. A
forked worker sees the parent's memory as it was at the fork, so the inputs are not copied
through a pipe; only the job's index goes to the worker and its result comes back.

Where the platform cannot fork (Windows, or ``workers`` ≤ 1) the jobs run here, in order.
The results are the same either way: each job is a pure function of its index.
"""

from __future__ import annotations

import multiprocessing as mp
import os
from collections.abc import Callable, Iterator, Sequence
from typing import Any

__all__ = ["default_workers", "fork_imap", "fork_map", "usable_cpus"]

#: The job of the running :func:`fork_imap`, inherited by its forked workers, and the
#: process that runs the map.
_JOB: Callable[[int], Any] | None = None
_OWNER: int | None = None


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask; a container's limit), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # no affinity on this platform
        return max(1, os.cpu_count() or 1)


def default_workers() -> int:
    """Workers of the parallel sections that have no setting of their own: the CPUs this
    process may use, at most 2 (the budgets' machine; more rarely pays for the memory)."""
    return min(2, usable_cpus())


def _run(i: int) -> Any:
    return _JOB(i)


def fork_imap(
    job: Callable[[int], Any], n: int, workers: int, order: Sequence[int] | None = None
) -> Iterator[tuple[int, Any]]:
    """Run ``job(i)`` for ``i`` in ``range(n)``; yield ``(i, result)`` in ``order``.

    Parameters
    ----------
    job : callable
        ``job(i) -> result``; any callable (a closure over large inputs is fine: the
        workers inherit it). The result must pickle.
    n : int
        Number of jobs.
    workers : int
        Worker processes (at most ``n``); ≤ 1, or a platform without ``fork``, runs the
        jobs in this process.
    order : sequence of int, optional
        The order jobs start in (and results are yielded in), e.g. longest first so that
        the workers end together; ``range(n)`` by default.

    Yields
    ------
    i, result
        Each job's index and result, as soon as it and every job before it are done.

    Notes
    -----
    One map runs at a time per process (the job is a module global during the map); a
    job that maps again, in a worker, runs that inner map in the worker, in order.
    """
    global _JOB, _OWNER
    order = list(range(n) if order is None else order)
    if sorted(order) != list(range(n)):
        raise ValueError(f"order must be a permutation of range({n})")
    k = min(int(workers), n)
    in_worker = _JOB is not None and _OWNER != os.getpid()
    if k <= 1 or in_worker or "fork" not in mp.get_all_start_methods():
        for i in order:
            yield i, job(i)
        return
    if _JOB is not None:
        raise RuntimeError("fork_imap is already running in this process")
    from concurrent.futures import ProcessPoolExecutor

    _JOB, _OWNER = job, os.getpid()
    try:
        with ProcessPoolExecutor(k, mp_context=mp.get_context("fork")) as pool:
            yield from zip(order, pool.map(_run, order), strict=True)
    finally:
        _JOB = _OWNER = None


def fork_map(
    job: Callable[[int], Any], n: int, workers: int, order: Sequence[int] | None = None
) -> list[Any]:
    """``[job(0), …, job(n - 1)]`` computed by :func:`fork_imap` (same arguments)."""
    out: list[Any] = [None] * n
    for i, r in fork_imap(job, n, workers, order):
        out[i] = r
    return out
