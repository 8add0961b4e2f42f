"""One-thread sections for BLAS / OpenMP.

The problems here are small per call (GP blocks of a few hundred points, kernel blocks of a
few thousand columns, skinny matrix products with d ≈ 5): multi-threaded BLAS gains nothing
on them and, on a loaded 2-core machine, thread contention made them 10–40x slower
(measured). The controller is created once; entering a limit then costs ~2 µs.
"""

from __future__ import annotations

from functools import lru_cache

from threadpoolctl import ThreadpoolController

__all__ = ["single_thread"]


@lru_cache(maxsize=1)
def _controller() -> ThreadpoolController:
    return ThreadpoolController()


def single_thread(user_api: str | None = None):
    """Context manager limiting BLAS (``user_api="blas"``) or all thread pools to one thread."""
    return _controller().limit(limits=1, user_api=user_api)
