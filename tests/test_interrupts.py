"""Interrupts that end things: Ctrl-C or SIGTERM on a running sweep (in this process, on a
process pool, on a Dask cluster) exits 130 within 5 s, leaves no process of its own behind and
writes nothing.

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

import pytest

import toolkit

ROOT = Path(toolkit.__file__).resolve().parents[1]
#: A sweep that still runs when it is signalled: the outliers experiment (an exact
#: simulation with 50 Hz commands per run, milliseconds each) over 100000 runs takes minutes
#: in any scheduler; the median law (3e6 runs) on the Dask test's one worker.
SCENE, RUNS = ROOT / "designs" / "outliers.toml", "100000"
MEDIAN_LAW, MEDIAN_RUNS = ROOT / "designs" / "median_law.toml", "3000000"
#: The issue's bound on the time from the signal to the exit.
EXIT_WITHIN = 5.0

pytestmark = [pytest.mark.slow,
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


def _interrupt(process: subprocess.Popen[str], sig: int, *, whole_group: bool) -> float:
    """Send ``sig`` (to the group, as a terminal's Ctrl-C does, or to the parent alone, as
    ``kill`` does) and return the seconds until the process exited."""
    assert process.poll() is None, "the sweep ended before it could be interrupted: raise RUNS"
    sent = time.perf_counter()
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
    return time.perf_counter() - sent


def _check_ended(process: subprocess.Popen[str], elapsed: float, out: Path) -> None:
    stderr = process.stderr.read()
    assert process.returncode == 130, stderr
    assert elapsed < EXIT_WITHIN, f"{elapsed:.1f} s from the signal to the exit"
    assert "interrupted" in stderr and "Traceback" not in stderr, stderr
    # multiprocessing's resource tracker ends on its own once its parent has gone (it reads
    # the end of its pipe): allow it a moment, then nothing of the group may be left.
    deadline = time.monotonic() + 2.0
    while _group(process.pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = {pid: _command(pid) for pid in _group(process.pid)}
    assert not left, f"processes left in the sweep's group: {left}"
    assert not out.exists()
    assert not [p for p in out.parent.iterdir() if p.name.startswith(".out.")]   # no temp folder


@pytest.mark.parametrize("sig, whole_group", [(signal.SIGINT, True), (signal.SIGTERM, False),
                                              (signal.SIGTERM, True)],
                         ids=["ctrl-c", "kill-parent", "kill-group"])
def test_interrupted_process_pool_sweep_ends_everything(tmp_path, sig, whole_group):
    # The pool's workers must exist (and be at work) before the signal.
    process, out = _start(tmp_path, "--scheduler", "processes", "--workers", "2")
    deadline = time.monotonic() + 120
    while len(_group(process.pid)) < 3 and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.1)
    assert len(_group(process.pid)) >= 3, "the pool's workers did not start"
    time.sleep(2.0)                                   # (the workers import and take chunks)
    elapsed = _interrupt(process, sig, whole_group=whole_group)
    _check_ended(process, elapsed, out)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "kill"])
def test_interrupted_local_sweep_ends_everything(tmp_path, sig):
    process, out = _start(tmp_path)
    time.sleep(3.0)                                   # start-up, compile: then the sweep runs
    elapsed = _interrupt(process, sig, whole_group=True)
    _check_ended(process, elapsed, out)


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
        elapsed = _interrupt(process, signal.SIGINT, whole_group=True)
        _check_ended(process, elapsed, out)
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
    # the child is ended by the kernel's parent-death signal). Within 5 s (the bound
    # for interrupts) no process of the group is left.
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
        while _group(process.pid) and time.monotonic() - sent < 5.0:
            time.sleep(0.05)
        assert not _group(process.pid), f"left after 5 s: {_group(process.pid)}"
        assert process.wait(timeout=5) != 0
    finally:
        if _group(process.pid):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()
