"""Independent jobs on forked workers (:mod:`clutchlab.forkmap`)."""

from __future__ import annotations

import multiprocessing as mp
import os

import numpy as np
import pytest

from clutchlab.forkmap import default_workers, fork_imap, fork_map

#: Where the platform cannot fork the jobs run here, in order (same results).
FORKS = "fork" in mp.get_all_start_methods()


def test_results_are_the_jobs_in_index_order_whatever_the_start_order():
    big = np.arange(200_000.0)  # inherited by the workers, not sent to them

    def job(i):
        return float(big[i::7].sum()), os.getpid()

    serial = fork_map(job, 7, 1)
    forked = fork_map(job, 7, 2, order=[6, 5, 4, 3, 2, 1, 0])
    assert [r[0] for r in forked] == [r[0] for r in serial]
    assert {r[1] for r in serial} == {os.getpid()}
    if FORKS:
        assert os.getpid() not in {r[1] for r in forked}  # the jobs ran elsewhere
    assert [i for i, _ in fork_imap(job, 4, 2, order=[2, 0, 3, 1])] == [2, 0, 3, 1]


def test_a_failing_job_raises_here_and_the_next_map_still_runs():
    def job(i):
        if i == 3:
            raise ValueError("job 3 is bad")
        return i

    with pytest.raises(ValueError, match="job 3 is bad"):
        fork_map(job, 5, 2)
    assert fork_map(lambda i: i * i, 4, 2) == [0, 1, 4, 9]


def test_a_map_inside_a_job_runs_in_that_worker():
    def inner(j):
        return os.getpid()

    def outer(i):
        return os.getpid(), fork_map(inner, 3, 2)

    for pid, inner_pids in fork_map(outer, 2, 2):
        assert set(inner_pids) == {pid} and (pid != os.getpid()) == FORKS


def test_bad_order_and_worker_count():
    with pytest.raises(ValueError, match="permutation"):
        fork_map(lambda i: i, 3, 2, order=[0, 0, 1])
    assert 1 <= default_workers() <= 2
