"""The timing policy of toolkit._compiled: no reported time and no budget includes a compile.

Checked without a clock: every reported run time and every wall-clock budget reads
:func:`toolkit._compiled.budget_clock`, which stands still while numba compiles; here a fake
``perf_counter`` drives it through a compile, and a fake ``budget_clock`` shows that reports
read it. How fast the compiled code is belongs to ``python -m toolkit.bench``.
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np
import pytest

import toolkit
from toolkit import _compiled, load_scene
from toolkit.scenes.study import control_scene, estimate_scene, run_study

ROOT = Path(toolkit.__file__).resolve().parents[1]
TICK = 2.0 ** -30


@pytest.fixture
def fake_clock(monkeypatch):
    """``time.perf_counter`` as _compiled reads it: the next value of a list, then stays."""
    values: list[float] = []

    def perf_counter() -> float:
        return values.pop(0) if len(values) > 1 else values[0]

    monkeypatch.setattr(_compiled.time, "perf_counter", perf_counter)
    monkeypatch.setitem(_compiled._COMPILING, "seconds", 0.0)
    monkeypatch.setitem(_compiled._COMPILING, "depth", 0)
    monkeypatch.setitem(_compiled._COMPILING, "listener", None)
    return values


def test_budget_clock_stands_still_while_a_kernel_compiles(fake_clock):
    # perf_counter reads 10 (before), 12 (compile starts), 19 and 30 (the nested compile's
    # start and end: no reading), 40 (the outer ends), 45: the clock reads 10, 12, 12, 17.
    # Exact: sums of small integers in doubles.
    fake_clock[:] = [10.0, 12.0, 40.0, 45.0]
    seen = []
    _compiled.on_compile(lambda event, name, seconds: seen.append((event, name, seconds)))
    assert _compiled.budget_clock() == 10.0
    _compiled.compile_started("outer")
    assert _compiled.budget_clock() == 12.0          # during the compile: still
    _compiled.compile_started("inner")                # nested: counted in the outer one
    _compiled.compile_ended("inner")
    assert _compiled.budget_clock() == 12.0
    _compiled.compile_ended("outer")                  # 28 s of compile, reported once
    assert _compiled.compile_seconds() == 28.0
    assert _compiled.budget_clock() == 45.0 - 28.0
    assert seen == [("start", "outer", 0.0), ("end", "outer", 28.0)]


def test_reported_run_times_read_the_budget_clock(monkeypatch):
    # With budget_clock replaced by a counter of ticks of 2**-30 s (exact in doubles; small,
    # so that no budget reading it runs out), each report's time is the difference of two of
    # its readings: a whole number of ticks, whatever the machine did.
    ticks = itertools.count()                 # one clock for all (a deadline set in one is read in another)
    readers = [module for name, module in sorted(sys.modules.items())
               if name.startswith("toolkit.") and getattr(module, "budget_clock", None) is _compiled.budget_clock]
    assert len(readers) >= 10, readers
    for module in readers:
        monkeypatch.setattr(module, "budget_clock", lambda: next(ticks) * TICK)
    study = estimate_scene(load_scene(ROOT / "designs" / "estimate.toml"))
    times = [result.wall_time for result in study.results]
    times.append(control_scene(load_scene(ROOT / "designs" / "closed_loop.toml")).loop.wall_time)
    times.append(toolkit.simulate(toolkit.Plant(toolkit.ContactSet([0.1, -0.2, 0.3], [1.0, 2.0, 0.5]), 1.0),
                                  1.0).wall_time)
    assert all(t > 0 and t / TICK == np.floor(t / TICK) for t in times), times


def test_study_reports_the_one_time_cost_apart(monkeypatch):
    # result.json's compile_time is the compile clock's advance over the whole study (what the
    # CLI's "compiled N kernels in X s" line reads), whatever stage compiled: with the clock
    # replaced by readings 5.0 s then 12.5 s it is exactly their difference; a timed stage
    # keeps its own warm-up cost (> 0) apart from its wall time.
    from toolkit.scenes import study as study_module
    from toolkit.scenes.report import study_to_dict

    readings = iter([5.0, 12.5])
    monkeypatch.setattr(study_module, "compile_seconds", lambda: next(readings))
    data = study_to_dict(run_study(load_scene(ROOT / "designs" / "closed_loop.toml")))
    assert data["compile_time"] == 7.5
    assert data["control"]["compile_time"] > 0
