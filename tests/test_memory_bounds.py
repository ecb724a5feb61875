"""Memory and time bounded by the budget in every simulation method.

Every method is run at ``t_end = 1e9`` s in a child process whose address space is capped at
1 GiB with ``resource.setrlimit(RLIMIT_AS)``. RLIMIT_AS rather than RLIMIT_DATA: it counts
every mapping (numpy allocates large arrays with mmap, which older kernels leave out of
RLIMIT_DATA), and numpy, scipy and casadi import well within 1 GiB of address space when
OpenBLAS runs one thread (its per-thread buffers are address space too), so the stricter cap
is usable. A method that allocated in proportion to its steps would die with MemoryError
(the child reports it) or be killed; each must instead return a budget status with its
partial result, within a bounded wall time.

The in-process tests below check the machinery of the bound (the decimated step record, the
sampling at the requested times, casadi's blocks) against second computations.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from toolkit import Budget, ContactSet, PiecewiseConstant, Plant, SimulationStatus, simulate
from toolkit.simulation._reference import StepRecord

ROOT = Path(__file__).resolve().parents[1]
GIB = 2**30
#: The wall-clock budget of each run in the child: short, so that the 20 runs take seconds.
WALL = 0.3
#: The memory cap of the record in the switching scene: far below the steps any method needs.
SAMPLES = 2_000
#: Wall time allowed per run: the budget, plus one casadi block or solver step past the last
#: clock check, plus assembling the result (generous: the machine is shared and loaded).
WALL_BOUND = WALL + 5.0

# Each child run is bounded in wall time (WALL_BOUND): under pytest-xdist these tests run on
# one worker, one at a time, with the other tests that run against the wall clock.
pytestmark = pytest.mark.wall_clock

_METHODS = (
    [("exact", {}), ("moreau", {"step": 1e-3})]
    + [(solver, {"friction": law}) for solver in ("rk45", "lsoda", "radau", "bdf")
       for law in ("sign", "tanh", "stribeck")]
    + [("casadi", {"integrator": integrator, "friction": law})
       for integrator in ("cvodes", "idas") for law in ("tanh", "stribeck")]
)

_CHILD = r"""
import json, resource, sys, time
resource.setrlimit(resource.RLIMIT_AS, (GIB, GIB))
import numpy as np
from toolkit import Budget, ContactSet, PiecewiseConstant, Plant, simulate

def switching_plant():
    # The median contact switches between -0.1 and +0.1 m/s every 1e4 s up to 1e9 s
    # (1e5 switches): every method has work in every interval, so none can finish in WALL s.
    times = np.linspace(1e4, 1e9 - 1e4, 100_000)
    middle = np.where(np.arange(times.size + 1) % 2 == 0, 0.1, -0.1)
    rows = np.column_stack((np.full(middle.size, -0.2), middle, np.full(middle.size, 0.2)))
    return Plant(ContactSet([-0.2, 0.1, 0.2], [0.5, 0.5, 0.5]), mass=1.0,
                 commands=PiecewiseConstant(times, rows))

def settling_plant():
    # The issue's reproduction: 11 equal contacts from rest, default step and sample budgets.
    return Plant(ContactSet(np.linspace(-0.3, 0.3, 11), np.full(11, 0.2)), mass=1.0)

def peak_rss():
    # VmHWM: the peak resident set of this process's own memory map (reset by exec; unlike
    # ru_maxrss, which keeps the high-water mark of the parent forked before the exec).
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024

out = []
for scene, method, options, budget in json.loads(sys.argv[1]):
    plant = switching_plant() if scene == "switching" else settling_plant()
    start = time.perf_counter()
    try:
        r = simulate(plant, 1e9, v0=-0.05, method=method, budget=Budget(**budget), **options)
        row = {"status": r.status.name, "message": r.message, "samples": int(r.t.size),
               "t_final": r.t_final, "finite": bool(np.all(np.isfinite(r.V))),
               "increasing": bool(np.all(np.diff(r.t) >= 0))}
    except BaseException as error:          # MemoryError included: reported, not a crash
        row = {"status": type(error).__name__, "message": str(error)[:300]}
    row.update(scene=scene, method=method, options=options, wall=time.perf_counter() - start,
               maxrss=peak_rss())
    out.append(row)
print(json.dumps(out))
""".replace("GIB", str(GIB))


def _cases() -> list[tuple[str, str, dict, dict]]:
    switching = [("switching", method, options, {"wall_time": WALL, "max_samples": SAMPLES})
                 for method, options in _METHODS]
    # the failures as reported: moreau (MemoryError, then killed) and rk45 at 1e9 s
    settling = [("settling", "moreau", {"step": 1e-3}, {"wall_time": WALL}),
                ("settling", "rk45", {}, {"wall_time": WALL})]
    return switching + settling


@pytest.fixture(scope="module")
def child_runs() -> list[dict]:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", _CHILD, json.dumps(_cases())], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, (done.returncode, done.stderr[-2000:])
    return json.loads(done.stdout)


def _label(case: tuple) -> str:
    scene, method, options, _ = case
    return "-".join([scene, method, *map(str, options.values())])


@pytest.mark.slow
@pytest.mark.parametrize("index", range(len(_cases())), ids=[_label(c) for c in _cases()])
def test_method_at_1e9_returns_a_budget_status_under_1_gib(child_runs: list[dict], index: int) -> None:
    scene, method, options, budget = _cases()[index]
    row = child_runs[index]
    assert (row["scene"], row["method"], row["options"]) == (scene, method, options)
    # Not MemoryError, not an exception: a budget status with a partial result.
    assert row["status"] in ("WALL_TIME", "MAX_STEPS"), row
    assert 0.0 <= row["t_final"] < 1e9 and row["samples"] >= 1, row
    assert row["finite"] and row["increasing"], row
    assert row["wall"] <= WALL_BOUND, row
    # The child's peak resident memory is below the 1 GiB cap it ran under (RLIMIT_AS
    # enforces it; this states it as a number).
    assert row["maxrss"] < GIB, row
    if scene == "switching":
        # Memory cap: at most max_samples samples plus the last step (exact: segments).
        assert row["samples"] <= SAMPLES + 2, row


# -- the machinery, in process ---------------------------------------------------------------
def test_step_record_keeps_every_stride_th_step_and_the_last() -> None:
    for capacity, steps in ((8, 5), (8, 8), (8, 9), (8, 100), (9, 1000), (2, 37)):
        record = StepRecord(0.0, [0.0], capacity)
        for k in range(1, steps + 1):
            record.add(float(k), [10.0 * k])
        t, y = record.arrays()
        even = capacity - capacity % 2
        # the stride is the least power of two that fits the steps into the capacity
        stride = 1
        while steps // stride + 1 > even:
            stride *= 2
        expected = list(range(0, steps + 1, stride))
        if expected[-1] != steps:
            expected.append(steps)
        np.testing.assert_array_equal(t, expected)           # exact: integers as floats
        np.testing.assert_array_equal(y[:, 0], 10.0 * np.array(expected))
        assert t.size <= even + 1 and record.stride == stride
        assert record.decimated == (stride > 1)


def _pushed_plant() -> Plant:
    return Plant(ContactSet([-0.3, -0.1, 0.05, 0.2, 0.3], [0.3, 0.5, 0.2, 0.4, 0.6]), mass=0.7,
                 damping=0.05, external_force=PiecewiseConstant([0.4, 1.1], [0.0, 0.6, -0.3]))


@pytest.mark.parametrize("method, options", [("moreau", {"step": 1e-3}),
                                             ("rk45", {"friction": "tanh", "epsilon": 1e-5})])
def test_decimated_record_is_the_full_record_thinned(method: str, options: dict) -> None:
    plant = _pushed_plant()
    full = simulate(plant, 2.0, v0=0.1, method=method, **options)
    small = simulate(plant, 2.0, v0=0.1, method=method, budget=Budget(max_samples=100), **options)
    assert full.t.size > 400 and "decimated" not in full.message
    assert small.t.size <= 101 and "record decimated" in small.message
    # The same steps are taken (the record only drops samples): every kept sample equals the
    # full record's sample at that time, bit for bit, and the first and last are kept.
    index = np.searchsorted(full.t, small.t)
    np.testing.assert_array_equal(full.t[index], small.t)
    np.testing.assert_array_equal(full.V[index], small.V)
    np.testing.assert_array_equal(full.force[index], small.force)
    assert small.t[0] == 0.0 and small.t[-1] == full.t[-1] == 2.0


def test_moreau_t_eval_is_its_steps_interpolated() -> None:
    # Second method: the steps (t_eval=None) interpolated with np.interp give the values
    # sampled while stepping; the forces are those of the step ending at or after each time.
    plant = _pushed_plant()
    steps = simulate(plant, 2.0, v0=0.1, method="moreau", step=1e-2)
    times = np.concatenate(([0.0, 0.0], np.linspace(0.0, 2.0, 333), steps.t[5:9], [2.0]))
    times.sort()
    sampled = simulate(plant, 2.0, v0=0.1, method="moreau", step=1e-2, t_eval=times)
    np.testing.assert_array_equal(sampled.t, times)
    # np.interp and the sampler use the same formula; rtol 0, atol 1e-15 m/s: a few ulps of
    # speeds below 1 m/s from the order of the operations.
    np.testing.assert_allclose(sampled.V, np.interp(times, steps.t, steps.V), rtol=0, atol=1e-15)
    index = np.minimum(np.searchsorted(steps.t, times, side="left"), steps.t.size - 1)
    np.testing.assert_array_equal(sampled.force, steps.force[index])


def test_moreau_budget_stop_in_a_huge_segment_is_prompt() -> None:
    # 1e12 steps in one segment: the steps are generated lazily, the step budget stops the run.
    plant = Plant(ContactSet([-0.2, 0.0, 0.2], [1.0, 1.0, 1.0]), mass=1.0)
    result = simulate(plant, 1e9, method="moreau", step=1e-3, budget=Budget(max_steps=5_000))
    assert result.status is SimulationStatus.MAX_STEPS
    # 5000 steps of 1 ms: the partial result ends at 5 s (rtol 1e-12: the step times are
    # t0 + j h, exact to rounding).
    assert result.t_final == pytest.approx(5.0, rel=1e-12, abs=0)
    assert result.t.size == 5001


def test_casadi_stopped_run_returns_its_completed_blocks() -> None:
    # 10 000 output intervals; the force switches at times[2000] and times[5500] (on the
    # grid, so the grid is exactly times[1:]): the first block ends at the first switch.
    times = np.linspace(0.0, 2.0, 10_001)
    plant = Plant(ContactSet([-0.3, -0.1, 0.05, 0.2, 0.3], [0.3, 0.5, 0.2, 0.4, 0.6]), mass=0.7,
                  damping=0.05, external_force=PiecewiseConstant([times[2000], times[5500]],
                                                                 [0.0, 0.6, -0.3]))
    options = {"method": "casadi", "v0": 0.1, "epsilon": 1e-3}
    first = simulate(plant, float(times[2000]), t_eval=times[:2001], **options)
    full = simulate(plant, 2.0, t_eval=times, **options)
    assert first.success and full.success
    # A step budget that the first block fits and the second cannot: the run stops with
    # MAX_STEPS and returns the first block, the same integrator call as `first` (equal
    # values, bit for bit) and the start of the full run.
    cut = simulate(plant, 2.0, t_eval=times, budget=Budget(max_steps=first.n_steps + 1), **options)
    assert cut.status is SimulationStatus.MAX_STEPS, cut.message
    np.testing.assert_array_equal(cut.t, times[:2001])
    np.testing.assert_array_equal(cut.V, first.V)
    np.testing.assert_array_equal(cut.V, full.V[:2001])


def test_casadi_grid_of_many_switches_is_decimated_to_max_samples() -> None:
    times = np.arange(1, 3000) * 1e-3                  # 2999 switches of the external force
    values = np.where(np.arange(3000) % 2 == 0, 0.1, -0.1)
    plant = Plant(ContactSet([-0.2, 0.0, 0.2], [1.0, 1.0, 1.0]), mass=1.0,
                  external_force=PiecewiseConstant(times, values))
    full = simulate(plant, 3.0, method="casadi")
    small = simulate(plant, 3.0, method="casadi", budget=Budget(max_samples=500))
    assert full.success and small.success and full.t.size > 3000   # 201 uniform + 2999 switches, some equal
    assert small.t.size <= 501 and "output decimated to every 8th" in small.message
    index = np.searchsorted(full.t, small.t)        # the same integration, thinned
    np.testing.assert_array_equal(full.t[index], small.t)
    np.testing.assert_array_equal(full.V[index], small.V)
