"""The kernels' warm-ups in groups that compile at once: :data:`GROUPS` and :func:`warm_groups`.

Each group is a list of modules whose ``warm_up()`` compiles (or loads from numba's cache)
the kernels of one part of the toolkit; the groups share few kernels, so that two processes
compiling them at once do little twice (their saves to the cache are locked: see
``toolkit._compiled``). ``active-contacts warm`` and the test suite run them before anything
else.
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Sequence

__all__ = ["GROUPS", "run_group", "warm_groups"]

#: The warm-ups, by group: the exact method (with the sampled loops and the batch path); the
#: planar kernels and every estimator.
GROUPS: tuple[tuple[str, ...], ...] = (
    ("toolkit.simulation._warmup",),
    ("toolkit.planar._warmup", "toolkit.estimation._warmup"),
)


def run_group(modules: Sequence[str]) -> tuple[float, float]:
    """Run each module's ``warm_up`` in this process: the wall time it took and the part of
    it spent compiling kernels, s."""
    from . import _compiled

    started, compiled = time.perf_counter(), _compiled.compile_seconds()
    for module in modules:
        importlib.import_module(module).warm_up()
    return time.perf_counter() - started, _compiled.compile_seconds() - compiled


def warm_groups() -> list[tuple[float, float]]:
    """Run every group of :data:`GROUPS` at once, each in a forked child
    (:func:`~toolkit._forked.fork_map`; one after the other where processes cannot fork),
    and return :func:`run_group`'s times for each. This process compiles nothing itself, so
    that it may fork again afterwards (a process that has started a parallel kernel's threads
    must not)."""
    from ._forked import fork_map

    return fork_map(run_group, [(), *GROUPS])[1:]
