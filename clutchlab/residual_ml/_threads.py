"""One-thread sections for BLAS / OpenMP.

The problems here are small per call (GP blocks of a few hundred points, kernel blocks of a
few thousand columns, skinny matrix products with d ≈ 5): multi-threaded BLAS gains nothing
on them and, on a loaded 2-core machine, thread contention made them 10–40x slower
(measured). The controller is created once; entering a limit then costs ~2 µs.

OpenBLAS (the pthreads build NumPy and SciPy ship) holds one thread count for the whole
process, so a limit must not be entered and left by threads that run at the same time: the
first to leave restores the library's threads while the other still factorizes, and the last
to leave restores the one thread the first had set. :func:`map_folds` holds the limit in the
calling thread for the whole map; the sections inside its workers then save and restore one
thread.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache
from typing import TypeVar

from threadpoolctl import ThreadpoolController

from ..forkmap import default_workers

__all__ = ["map_folds", "single_thread"]

T = TypeVar("T")


@lru_cache(maxsize=1)
def _controller() -> ThreadpoolController:
    return ThreadpoolController()


def single_thread(user_api: str | None = None):
    """Context manager limiting BLAS (``user_api="blas"``) or all thread pools to one thread."""
    return _controller().limit(limits=1, user_api=user_api)


def map_folds(fold: Callable[[int], T], n: int) -> list[T]:
    """``[fold(0), …, fold(n − 1)]`` on :func:`~clutchlab.forkmap.default_workers` threads.

    For independent folds whose work releases the GIL (factorizations, libsvm, sorting).
    BLAS is held at one thread by the calling thread for the whole map (see the module
    docstring), so each fold's floating-point result does not depend on the scheduling, and
    the process's thread count afterwards is the one before. Results keep the fold order.
    """
    with single_thread("blas"), ThreadPoolExecutor(max_workers=default_workers()) as pool:
        return list(pool.map(fold, range(n)))
