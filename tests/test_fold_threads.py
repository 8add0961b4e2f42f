"""The leave-one-experiment-out folds run two at a time without racing on BLAS's thread count.

OpenBLAS's (pthreads build) thread count is process-wide. When each fold entered and left its
own one-thread section, the first fold to leave gave the library its threads back while the
other fold still factorized, and the last to leave restored the one thread the first had set.
Here the two folds are forced into exactly that interleaving.
"""

from __future__ import annotations

import threading
from types import SimpleNamespace

import numpy as np
import pytest
from threadpoolctl import ThreadpoolController

from clutchlab.residual_ml import _threads
from clutchlab.residual_ml.residual_variance import loeo_residuals

_WAIT_S = 10.0


def _blas_threads() -> list[int]:
    blas = ThreadpoolController().select(user_api="blas")
    return [lib.num_threads for lib in blas.lib_controllers]


class _InterleavingGP:
    """Stand-in GP: fold 0 leaves its section while fold 1 is still inside its own."""

    def __init__(self):
        self.fold1_inside = threading.Event()
        self.fold0_left = threading.Event()
        self.seen_by_fold1: list[int] | None = None

    def conditioned_on(self, X, y, w):
        held = ({0.0, 1.0} - set(np.unique(y).tolist())).pop()
        if held == 0.0:  # fold 0: leave only once fold 1 is inside
            assert self.fold1_inside.wait(_WAIT_S), "fold 1 never started beside fold 0"
        else:  # fold 1: look at the thread count after fold 0 has left its section
            self.fold1_inside.set()
            assert self.fold0_left.wait(_WAIT_S), "fold 0 never left its section"
            self.seen_by_fold1 = _blas_threads()
        return SimpleNamespace(predict=lambda Xh, held=held: self._left(held, Xh))

    def _left(self, held, Xh):
        if held == 0.0:
            self.fold0_left.set()
        return np.zeros(Xh.shape[0])


def test_a_fold_keeps_one_blas_thread_while_the_other_leaves_and_the_count_is_restored(
    monkeypatch,
):
    monkeypatch.setattr(_threads, "default_workers", lambda: 2)
    blocks = [
        SimpleNamespace(X=np.full((4, 2), float(k)), y=np.full(4, float(k)), weight=np.ones(4))
        for k in range(2)
    ]
    gp = _InterleavingGP()
    with ThreadpoolController().limit(limits=2, user_api="blas"):
        before = _blas_threads()
        assert before and all(n == 2 for n in before), f"BLAS did not take 2 threads: {before}"
        X, r = loeo_residuals(gp, blocks, stride=1)
        after = _blas_threads()
    assert gp.seen_by_fold1 is not None and all(n == 1 for n in gp.seen_by_fold1), (
        f"fold 1 factorized with {gp.seen_by_fold1} BLAS threads after fold 0 left"
    )
    assert after == before
    np.testing.assert_array_equal(X[:, 0], [0, 0, 0, 0, 1, 1, 1, 1])
    np.testing.assert_array_equal(r, [0, 0, 0, 0, 1, 1, 1, 1])


def test_map_folds_keeps_the_fold_order_and_passes_errors_on(monkeypatch):
    monkeypatch.setattr(_threads, "default_workers", lambda: 2)
    assert _threads.map_folds(lambda k: k * k, 5) == [0, 1, 4, 9, 16]

    def fails(k):
        if k == 3:
            raise ValueError("fold 3")
        return k

    with pytest.raises(ValueError, match="fold 3"):
        _threads.map_folds(fails, 5)
