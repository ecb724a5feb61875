"""toolkit._forked: work split over forked copies of the process."""

from __future__ import annotations

import multiprocessing
import os

import numpy as np
import pytest

from toolkit._forked import fork_map, idle_cores


def test_fork_map_equals_the_loop_and_runs_in_other_processes():
    # Each item computed in its own process (pids differ from the parent's but the first
    # item's), the results back in order and equal to the plain loop (a closure over an
    # array the children inherit; rtol = atol = 0: the same arithmetic).
    weights = np.array([0.3, 1.7, 2.9])
    items = [np.arange(k, k + 5, dtype=float) for k in range(4)]

    def work(item):
        return float(weights @ item[:3]), os.getpid()

    out = fork_map(work, items)
    assert [value for value, _ in out] == [work(item)[0] for item in items]
    pids = [pid for _, pid in out]
    assert pids[0] == os.getpid() and len(set(pids)) == len(items)
    assert not multiprocessing.active_children()


def test_an_error_in_a_child_is_raised_here_and_no_process_is_left():
    def work(k):
        if k == 2:
            raise ValueError(f"bad item {k}")
        return k

    with pytest.raises(ValueError, match="bad item 2"):
        fork_map(work, [0, 1, 2, 3])
    assert not multiprocessing.active_children()


def test_a_child_that_dies_is_reported():
    def work(k):
        if k == 1:
            os._exit(7)
        return k

    with pytest.raises(RuntimeError, match="exit code 7"):
        fork_map(work, [0, 1])
    assert not multiprocessing.active_children()


def test_idle_cores_is_within_the_allowed_cores():
    allowed = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert 1 <= idle_cores() <= allowed

