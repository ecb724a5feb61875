"""toolkit._forked: work split over forked copies of the process."""

from __future__ import annotations

import multiprocessing
import os
import signal
import subprocess
import sys
import time

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


_SCRIPT = """
import sys
from toolkit.predictions import Apparatus, ViscosityProblem, viscosity_check
print("started", flush=True)
viscosity_check(ViscosityProblem(Apparatus.carousel(), "loop", 20000), workers=2)
"""


def _group(pgid: int) -> list[int]:
    """Live processes of process group ``pgid`` (/proc/PID/stat: the group follows the state)."""
    members = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = open(f"/proc/{entry}/stat").read()
            except OSError:
                continue
            fields = stat[stat.rindex(")") + 2:].split()
            if int(fields[2]) == pgid and fields[0] != "Z":
                members.append(int(entry))
    return members


@pytest.mark.slow
@pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="needs /proc")
@pytest.mark.parametrize("sig, whole_group", [(signal.SIGINT, True), (signal.SIGTERM, False)],
                         ids=["ctrl-c", "kill-parent"])
def test_an_interrupted_forked_sweep_leaves_no_process(sig, whole_group):
    # A 20000-run in-loop sweep on 2 forked processes (minutes of work), signalled once both
    # work: Ctrl-C (the whole group) or a kill of the parent alone (no clean-up of its own:
    # the child is ended by the kernel's parent-death signal). Within 5 s (the bound
    # for interrupts) no process of the group is left.
    process = subprocess.Popen([sys.executable, "-c", _SCRIPT], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        assert process.stdout.readline().strip() == "started"
        deadline = time.monotonic() + 120
        while len(_group(process.pid)) < 2 and time.monotonic() < deadline and process.poll() is None:
            time.sleep(0.05)
        assert len(_group(process.pid)) >= 2, "the forked worker did not start"
        time.sleep(1.0)
        (os.killpg if whole_group else os.kill)(process.pid, sig)
        sent = time.monotonic()
        while _group(process.pid) and time.monotonic() - sent < 5.0:
            time.sleep(0.05)
        assert not _group(process.pid), f"left after 5 s: {_group(process.pid)}"
        assert process.wait(timeout=5) != 0
    finally:
        if _group(process.pid):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()
