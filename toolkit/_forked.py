"""Work split over forked copies of this process: :func:`fork_map` and :func:`idle_cores`.

For Monte Carlo studies whose runs call Python objects per sample (an estimator in the loop):
threads would share one interpreter, a fresh interpreter ("spawn") pays the imports and the
kernels' load again, a forked child starts with this process's loaded kernels and objects.
Each item is computed whole by one process, so results do not depend on how the items are
split. A forked child must not run a parallel (``prange``) kernel: after the parent has started
OpenMP threads it would be killed (GNU OpenMP is not fork-safe), so callers use this only for
work whose kernels are serial.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["allowed_cores", "fork_map", "idle_cores", "stop"]


def allowed_cores() -> int:
    """The cores this process may run on (its affinity where the platform has one)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def idle_cores() -> int:
    """Processes worth forking now: the cores this process may run on (its affinity) that the
    load average leaves idle (:func:`toolkit._compiled.threads`' rule), at least 1."""
    from ._compiled import PARALLEL_AFTER, threads

    return max(1, min(allowed_cores(), threads(PARALLEL_AFTER)))


def _die_with(parent: int) -> None:
    """Have the kernel send this process SIGTERM when its parent dies (Linux's
    ``PR_SET_PDEATHSIG``; elsewhere nothing), and end now if ``parent`` has already gone: a
    parent killed outright (no clean-up of its own) leaves no child working on."""
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):                                # (not Linux)
        pass
    if os.getppid() != parent:
        os._exit(1)


def _child(fn: Callable[[Any], Any], item: Any, connection: Any, parent: int) -> None:
    _die_with(parent)
    try:
        connection.send((fn(item), None))
    except BaseException as error:                  # (reported to the parent, raised there)
        try:
            connection.send((None, error))
        except Exception:                           # an error that does not pickle
            connection.send((None, RuntimeError(repr(error))))
    finally:
        connection.close()


def fork_map(fn: Callable[[Any], Any], items: Sequence[Any]) -> list[Any]:
    """``[fn(item) for item in items]``, the first item in this process and each other in a
    forked child (all at once: one item per core). ``fn`` and the items are inherited, not
    pickled; each result comes back pickled through a pipe. An exception in a child is raised
    here; any exception here (an interrupt included) terminates the children and waits for
    them before it propagates, and a child whose parent dies outright is sent SIGTERM (Linux):
    no process is left behind. Without ``fork`` (not POSIX) the items run here, one after the
    other."""
    if len(items) <= 1 or "fork" not in multiprocessing.get_all_start_methods():
        return [fn(item) for item in items]
    context = multiprocessing.get_context("fork")
    children: list[tuple[Any, Any]] = []
    finished = False
    try:
        for item in items[1:]:
            connection, end = context.Pipe(duplex=False)
            process = context.Process(target=_child, args=(fn, item, end, os.getpid()), daemon=True)
            process.start()
            end.close()
            children.append((process, connection))
        results = [fn(items[0])]
        for process, connection in children:
            try:
                value, error = connection.recv()
            except EOFError:
                process.join()
                raise RuntimeError(f"a forked worker (pid {process.pid}) died with exit code "
                                   f"{process.exitcode} before it returned") from None
            if error is not None:
                raise error
            results.append(value)
        finished = True
        return results
    finally:
        for process, connection in children:
            stop(process, connection, busy=not finished)


def stop(process: Any, connection: Any, busy: bool) -> None:
    """End a worker ``process`` (a :mod:`multiprocessing` one) and close its ``connection``:
    terminated at once when ``busy`` (it may still be working: an error or an interrupt
    here), else given 5 s to exit after its last message; killed when it has not exited."""
    if busy and process.is_alive():
        process.terminate()
    process.join(timeout=5)
    if process.is_alive():
        process.kill()
        process.join()
    connection.close()
