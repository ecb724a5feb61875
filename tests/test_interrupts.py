"""Interrupts that end things: Ctrl-C or SIGTERM on a running sweep (in this process, on a
process pool, on a Dask cluster), at any moment of its life, exits 130 with one line, leaves no
process of its own behind and writes nothing. No assertion here depends on how fast the
machine is: the waits are guards against a hang.

Each test runs ``active-contacts sweep`` (the last one: a script whose viscosity sweep runs on
forked workers, :func:`toolkit._forked.fork_map`) in a process group of its own (as a shell
runs a command), waits until the sweep is running, signals it as a terminal or a supervisor
would, and then looks at the group in ``/proc``.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

import toolkit

ROOT = Path(toolkit.__file__).resolve().parents[1]
#: A sweep that still runs when it is signalled: the outliers experiment (an exact
#: simulation with 50 Hz commands per run, milliseconds each) over 100000 runs takes minutes
#: in any scheduler; the median law (3e6 runs) on the Dask test's one worker.
SCENE, RUNS = ROOT / "designs" / "outliers.toml", "100000"
MEDIAN_LAW, MEDIAN_RUNS = ROOT / "designs" / "median_law.toml", "3000000"

# (make test runs them after the others, in one process: no busy sibling, no worker threads)
pytestmark = [pytest.mark.slow, pytest.mark.wall_clock,
              pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")]


def _group(pgid: int) -> list[int]:
    """The processes of process group ``pgid`` (from /proc/PID/stat: the group is the field
    after the state, past the command in parentheses)."""
    members = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:                      # gone meanwhile
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        if int(fields[2]) == pgid and fields[0] != "Z":
            members.append(int(entry))
    return members


def _command(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()[:120]
    except OSError:
        return "(gone)"


def _start(tmp_path: Path, *extra: str, scene: Path = SCENE,
           runs: str = RUNS) -> tuple[subprocess.Popen[str], Path]:
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("ACTIVE_CONTACTS_COMPILE", None)
    process = subprocess.Popen([sys.executable, "-m", "toolkit.cli", "sweep", str(scene), "--runs", runs,
                                "--out", str(out), *extra], cwd=tmp_path, env=env, text=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    return process, out


def _interrupt(process: subprocess.Popen[str], sig: int, *, whole_group: bool) -> None:
    """Send ``sig`` (to the group, as a terminal's Ctrl-C does, or to the parent alone, as
    ``kill`` does) and wait for the process to exit."""
    assert process.poll() is None, "the sweep ended before it could be interrupted: raise RUNS"
    if whole_group:
        os.killpg(process.pid, sig)
    else:
        os.kill(process.pid, sig)
    try:
        process.wait(timeout=60)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
        pytest.fail(f"no exit 60 s after signal {sig}")


def _check_ended(process: subprocess.Popen[str], out: Path) -> None:
    stderr = process.stderr.read()
    # 130, or the death by SIGINT that Python itself chooses once a KeyboardInterrupt went
    # through a C-level import (a shell reports both as $? = 130)
    assert process.returncode in (130, -signal.SIGINT), stderr
    assert stderr.splitlines() == ["active-contacts: interrupted"], stderr      # one line
    # multiprocessing's resource tracker ends on its own once its parent has gone (it reads
    # the end of its pipe): allow it a moment, then nothing of the group may be left.
    deadline = time.monotonic() + 30.0
    while _group(process.pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = {pid: _command(pid) for pid in _group(process.pid)}
    assert not left, f"processes left in the sweep's group: {left}"
    assert not out.exists()
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".out.")]   # no temp folder


def _importing(pid: int) -> bool:
    """Whether process ``pid`` has started importing numpy (the command line does so inside its
    own handlers; before that, Python itself is still starting, and a Ctrl-C then is
    Python's to report)."""
    try:
        return "_multiarray_umath" in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


def _wait_for(condition: Any, process: subprocess.Popen[str], what: str) -> None:
    deadline = time.monotonic() + 120                 # (a guard against a hang, not a timing)
    while not condition() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    assert condition(), f"never reached: {what}"


#: The moments of a process-pool sweep's life at which a Ctrl-C reaches its whole group: how
#: the test sees that the moment has come, then a delay (s). While the parent imports (its
#: SIGINT handler is Python's), while the first worker starts and imports, once both do, as
#: they compute, and after they have gone (the parent tabulates, draws and writes).
_MOMENTS = [("parent importing", "python", 0.0), ("parent importing", "python", 0.3),
            ("parent importing", "python", 0.8), ("first worker starting", "worker", 0.0),
            ("workers importing", "workers", 0.0), ("workers importing", "workers", 0.3),
            ("workers importing", "workers", 1.0), ("workers computing", "workers", 3.0),
            ("workers computing", "workers", 6.0), ("writing", "done", 0.0)]


@pytest.mark.parametrize("moment, sign, delay", _MOMENTS,
                         ids=[f"{m}+{d:g}s" for m, _, d in _MOMENTS])
def test_ctrl_c_at_any_moment_of_a_pool_sweep(tmp_path, moment, sign, delay):
    # One line, exit 130, no traceback from the parent or a worker, no process left, nothing
    # written, whatever the moment. The last moment needs a sweep that ends: 400 runs.
    process, out = _start(tmp_path, "--scheduler", "processes", "--workers", "2",
                          runs="400" if sign == "done" else RUNS)
    try:
        if sign == "python":
            _wait_for(lambda: _importing(process.pid), process, "the parent importing numpy")
        elif sign in ("worker", "workers"):
            count = 2 if sign == "worker" else 3
            _wait_for(lambda: len(_group(process.pid)) >= count, process, f"{count - 1} worker(s)")
        else:
            _wait_for(lambda: len(_group(process.pid)) >= 3, process, "the workers")
            _wait_for(lambda: len(_group(process.pid)) <= 2, process, "the workers' end")
        time.sleep(delay)
        assert process.poll() is None, f"the sweep ended before {moment}"
        os.killpg(process.pid, signal.SIGINT)
        process.wait(timeout=60)                      # (a guard against a hang)
        _check_ended(process, out)
    finally:
        if _group(process.pid):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()


@pytest.mark.parametrize("sig, whole_group", [(signal.SIGTERM, False), (signal.SIGTERM, True)],
                         ids=["kill-parent", "kill-group"])
def test_interrupted_process_pool_sweep_ends_everything(tmp_path, sig, whole_group):
    # The pool's workers must exist (and be at work) before the signal.
    process, out = _start(tmp_path, "--scheduler", "processes", "--workers", "2")
    deadline = time.monotonic() + 120
    while len(_group(process.pid)) < 3 and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.1)
    assert len(_group(process.pid)) >= 3, "the pool's workers did not start"
    time.sleep(2.0)                                   # (the workers import and take chunks)
    _interrupt(process, sig, whole_group=whole_group)
    _check_ended(process, out)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "kill"])
def test_interrupted_local_sweep_ends_everything(tmp_path, sig):
    process, out = _start(tmp_path)
    time.sleep(3.0)                                   # start-up, compile: then the sweep runs
    _interrupt(process, sig, whole_group=True)
    _check_ended(process, out)


def test_interrupted_dask_sweep_cancels_its_chunks(tmp_path):
    # A cluster of the test's own (one worker process): the interrupted command exits 130 at
    # once, and the cluster is left with no task of the sweep (cancelled, not run on).
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        process, out = _start(tmp_path, "--scheduler", cluster.scheduler_address,
                              scene=MEDIAN_LAW, runs=MEDIAN_RUNS)
        deadline = time.monotonic() + 120
        count = lambda: client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks))  # noqa: E731
        while count() == 0 and time.monotonic() < deadline and process.poll() is None:
            time.sleep(0.1)
        assert count() > 0, "the sweep's chunks never reached the cluster"
        _interrupt(process, signal.SIGINT, whole_group=True)
        _check_ended(process, out)
        deadline = time.monotonic() + 10
        while count() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert count() == 0


#: A script running a forked in-loop viscosity sweep (toolkit._forked.fork_map).
_FORKED_SWEEP = """
from toolkit.predictions import Apparatus, ViscosityProblem, viscosity_check
print("started", flush=True)
viscosity_check(ViscosityProblem(Apparatus.carousel(), "loop", 20000), workers=2)
"""


@pytest.mark.parametrize("sig, whole_group", [(signal.SIGINT, True), (signal.SIGTERM, False)],
                         ids=["ctrl-c", "kill-parent"])
def test_an_interrupted_forked_sweep_leaves_no_process(sig, whole_group):
    # A 20000-run in-loop sweep on 2 forked processes (minutes of work), signalled once both
    # work: Ctrl-C (the whole group) or a kill of the parent alone (no clean-up of its own:
    # the child is ended by the kernel's parent-death signal). Then no process of the group
    # is left (waited for up to 30 s: a guard, not a timing).
    process = subprocess.Popen([sys.executable, "-c", _FORKED_SWEEP], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, start_new_session=True,
                               env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        assert process.stdout.readline().strip() == "started"
        deadline = time.monotonic() + 120
        while len(_group(process.pid)) < 2 and time.monotonic() < deadline and process.poll() is None:
            time.sleep(0.05)
        assert len(_group(process.pid)) >= 2, "the forked worker did not start"
        time.sleep(1.0)
        (os.killpg if whole_group else os.kill)(process.pid, sig)
        sent = time.monotonic()
        while _group(process.pid) and time.monotonic() - sent < 30.0:
            time.sleep(0.05)
        assert not _group(process.pid), f"left: {_group(process.pid)}"
        assert process.wait(timeout=5) != 0
    finally:
        if _group(process.pid):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()
