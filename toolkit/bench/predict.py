"""Prediction benchmark: the 490-run viscosity sweep on one core and on every core.

Run ``python -m toolkit.bench predict [--runs N] [--repeat R] [--seed K]``; what it prints
and its exit status: docs/methods.md."""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable

import numpy as np

from toolkit._compiled import warm
from toolkit._forked import idle_cores
from toolkit.controllers import VirtualViscosity
from toolkit.loop.closed_loop import simulate_closed_loop
from toolkit.model import sample_count
from toolkit.simulation import warm_up
from toolkit.predictions import (Apparatus, FrictionFractionProblem, ViscosityCheck, ViscosityProblem,
                                 friction_fraction_check, viscosity_check)


def _one_core() -> tuple[str, set[int] | None]:
    """Pin the process to one core; return a note and the previous affinity (to restore)."""
    if hasattr(os, "sched_setaffinity"):
        before = os.sched_getaffinity(0)
        core = min(before)
        os.sched_setaffinity(0, {core})
        return f"pinned to core {core}", before
    return "not pinned (no sched_setaffinity)", None


def _samples(check: ViscosityProblem, result: ViscosityCheck) -> int:
    """Closed-loop samples the sweep simulated (from each run's planned length)."""
    t_end = check.pre_roll + result.design.stop_time + check.tail
    return sum(sample_count(float(t), check.rate) for t in t_end)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench predict", description=__doc__)
    parser.add_argument("--runs", type=int, default=490)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    note, before = _one_core()
    try:
        print(f"-- one core ({note}), {_load()}")
        print(f"kernels compiled or loaded from the cache in {warm_up() + warm(None, 'core', 'lines'):.2f} s "
              f"(not timed)")
        status = _run(args)
    finally:
        if before is not None:
            os.sched_setaffinity(0, before)
    return status | _every_core(args)


def _load() -> str:
    return f"load average {os.getloadavg()[0]:.2f}" if hasattr(os, "getloadavg") else "no load average"


def _every_core(args: argparse.Namespace) -> int:
    """The issue-21 line: the in-loop sweep on every core this process may use (forked
    workers) against the serial per-run path, both timed in this run (min of the repeats)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    print(f"-- every core ({cores} allowed), {_load()}")
    problem = ViscosityProblem(Apparatus.carousel(), "loop", args.runs, seed=args.seed)
    small = ViscosityProblem(Apparatus.carousel(), "loop", 4, seed=args.seed)
    cost = warm(lambda: [viscosity_check(small, workers=w) for w in (1, cores)], "core", "lines")
    print(f"  warm-up (kernels loaded, one small sweep each way) {cost:.2f} s (not timed)")
    serial, forked = [], []
    results = {}
    for _ in range(max(args.repeat, 1)):
        for workers, times in ((1, serial), (cores, forked)):
            start = time.perf_counter()
            results[workers] = viscosity_check(problem, workers=workers)
            times.append(time.perf_counter() - start)
    one, many = results[1], results[cores]
    same = all(np.array_equal(one.tau[d], many.tau[d], equal_nan=True)
               and np.array_equal(one.tau_true[d], many.tau_true[d], equal_nan=True) for d in one.tau)
    best, base = min(forked), min(serial)
    scaled = '' if args.runs == 490 else f', scaled from {args.runs} runs'
    target = best * 490 / args.runs
    print(f"  in-loop sweep, runs shared among {cores} forked processes: {best:.2f} s (min of {len(forked)}: "
          f"{', '.join(f'{t:.2f}' for t in forked)}); {_load()}")
    print(f"  baseline: the serial per-run path (workers=1, unpinned) {base:.2f} s (min of {len(serial)}: "
          f"{', '.join(f'{t:.2f}' for t in serial)}); ratio {base / best:.2f}x; the same tau per run: {same}")
    print(f"  (viscosity_check's default at this load: {idle_cores()} process(es), the cores the load "
          "average leaves idle)")
    print(f"{'met  ' if target < 1.0 else 'SHORT'} in-loop sweep of 490 runs under 1 s on {cores} cores "
          f"(target {target:.2f} s{scaled}; {_load()})")
    return 0 if same else 1


def _run(args: argparse.Namespace) -> int:

    apparatus = Apparatus.carousel()
    status = 0
    for mode in ("ideal", "loop"):
        problem = ViscosityProblem(apparatus, mode, args.runs, seed=args.seed)
        viscosity_check(ViscosityProblem(apparatus, mode, 4, seed=args.seed), workers=1)  # warm-up, untimed
        times, result = [], None
        for _ in range(max(args.repeat, 1)):
            start = time.perf_counter()
            result = viscosity_check(problem, workers=1)
            times.append(time.perf_counter() - start)
        best = min(times)
        samples = _samples(problem, result)
        # Baseline: one fixed 10 s run of the same loop (first run's staircase), x runs.
        plant = apparatus.run_plant(result.v0[0], mode)
        controller = VirtualViscosity(float(result.slope[0]))
        sensors = apparatus.sensors if mode == "loop" else None
        simulate_closed_loop(plant, controller, 1.0, v0=float(result.v0[0]), sensors=sensors)  # warm
        base = min(_timed(lambda: simulate_closed_loop(plant, controller, 10.0, v0=float(result.v0[0]),
                                                       sensors=sensors)) for _ in range(3))
        print(f"viscosity sweep ({mode}): {result.runs} runs in {best:.2f} s (min of {len(times)}: "
              f"{', '.join(f'{t:.2f}' for t in times)}), {samples} samples, "
              f"{best / samples * 1e6:.0f} us/sample; "
              + "; ".join(f"{f.definition}: R^2 {f.r2:.4f}, k_fit / k_predicted {f.ratio:.4f}"
                          for f in result.fits))
        print(f"  baseline: 10 s fixed-length runs, {base:.3f} s each -> {base * result.runs:.1f} s for "
              f"{result.runs} runs; ratio {base * result.runs / best:.1f}x")
        slow, same = _python_loops(problem, result)
        print(f"  baseline: every loop in Python around advance (no kernel loop, no batch) "
              f"{slow:.2f} s; ratio {slow / best:.2f}x; the same tau per run: {same}")
        if mode == "loop":
            target = best * 490 / result.runs
            ok = target < 60.0
            scaled = '' if result.runs == 490 else ', scaled from ' + str(result.runs) + ' runs'
            print(f"{'met  ' if ok else 'SHORT'} in-loop sweep of 490 runs under 60 s on one core "
                  f"({target:.1f} s{scaled})")
            status |= 0 if ok else 1
    for mode in ("ideal", "loop"):
        start = time.perf_counter()
        check = friction_fraction_check(FrictionFractionProblem(apparatus, mode, seed=args.seed))
        print(f"friction fraction ({mode}): {time.perf_counter() - start:.2f} s, {check.status.name}")
    return status


def _python_loops(problem: ViscosityProblem, result: ViscosityCheck) -> tuple[float, bool]:
    """The sweep again with every closed loop in Python around ``advance`` (the loops one by
    one, ideal runs too): its wall time (s) and whether each run's tau is the same."""
    import toolkit.loop.closed_loop as closed_loop
    import toolkit.predictions.viscosity as viscosity

    def one_by_one(plants, controllers, lengths, v0):  # type: ignore[no-untyped-def]
        runs = []
        for plant, controller, length, start in zip(plants, controllers, lengths, v0):
            run = simulate_closed_loop(plant, controller, float(length), v0=float(start))
            runs.append((run.times, run.estimate, run.speed,
                         None if run.status.name == "SUCCESS" else run.message))
        return runs

    together = viscosity._together
    closed_loop._COMPILED = False
    viscosity._together = one_by_one                      # type: ignore[assignment]
    try:
        start = time.perf_counter()
        again = viscosity_check(problem, workers=1)
        slow = time.perf_counter() - start
    finally:
        closed_loop._COMPILED = True
        viscosity._together = together
    same = all(np.array_equal(again.tau[d], result.tau[d], equal_nan=True) for d in result.tau)
    return slow, bool(same)


def _timed(fn: Callable[[], object]) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start
