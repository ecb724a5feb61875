"""Closed-loop benchmark: 60 s at 50 Hz with the exact plant, sensors, Kalman filter and
controller, compiled against the same loop in Python around ``advance``.

Run ``python -m toolkit.bench loop [--seconds T] [--repeat R]``; what it prints and its exit
status: docs/methods.md."""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

import toolkit.loop.closed_loop as closed_loop
from toolkit import CentralDifference, ContactSet, Plant, Sensors
from toolkit.controllers import SpeedHold, VirtualViscosity
from toolkit.estimation import EstimatorModel, KalmanEstimator
from toolkit.model import sample_count
from toolkit.model.carousel import CAROUSEL
from toolkit.simulation import warm_up

_WHOLE, _LOOP = 0.5, 0.1      # s per 60 s: the whole loop, the loop itself


def _best(repeat: int, run: Any) -> tuple[float, Any]:
    results = [run() for _ in range(max(repeat, 1))]
    return min(r.wall_time for r in results), results[0]


def _python(run: Any) -> Any:
    """``run()`` with every loop in Python (the baseline)."""
    closed_loop._COMPILED = False
    try:
        return run()
    finally:
        closed_loop._COMPILED = True


def _estimator_time(plant: Plant, controller: Any, seconds: float, sensors: Sensors,
                    estimator: KalmanEstimator) -> tuple[float, float]:
    """One compiled run with the estimator's ``observe`` and ``commanded`` timed: (total,
    estimator) wall time, s."""
    spent = [0.0]
    clock = time.perf_counter
    observe, commanded = estimator.observe, estimator.commanded

    def timed(fn: Any) -> Any:
        def call(*args: Any) -> Any:
            start = clock()
            out = fn(*args)
            spent[0] += clock() - start
            return out
        return call

    estimator.observe, estimator.commanded = timed(observe), timed(commanded)  # type: ignore[method-assign]
    try:
        start = clock()
        closed_loop.simulate_closed_loop(plant, controller, seconds, sensors=sensors,
                                         estimator=estimator, seed=1)
        total = clock() - start
    finally:
        del estimator.observe, estimator.commanded
    return total, spent[0]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench loop", description=__doc__)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)

    print(f"kernels compiled or loaded from the cache in {warm_up():.2f} s (not timed)")
    plant = Plant(ContactSet([0.0] * 10, [1.0] * 10), 5.0, motors=CAROUSEL.motors())
    sensors = CAROUSEL.sensors(10)
    model = EstimatorModel(plant.contacts.forces, plant.mass, sensors, motor_lag=CAROUSEL.motor_lag,
                           speed_limits=plant.motors.speed_limits)
    samples = sample_count(args.seconds, sensors.rate)
    scale = 60.0 / args.seconds
    status = 0
    for name, controller in (("speed_hold", SpeedHold(0.2, 50.0)),
                             ("virtual_viscosity", VirtualViscosity(50.0, 0.15))):
        estimator = KalmanEstimator(model)
        # The estimator's own kernels compiled or loaded before any clock starts (the timing
        # policy of toolkit._compiled): its one-time cost on a line of its own.
        print(f"{name}: the estimator's kernels and one untimed run in {estimator.warm_up():.2f} s "
              f"(not timed)")

        def loop(seconds: float = args.seconds) -> Any:
            return closed_loop.simulate_closed_loop(plant, controller, seconds, sensors=sensors,
                                                    estimator=estimator, seed=1)

        loop(0.5)
        _python(lambda: loop(0.5))                                          # warm-up
        best, run = _best(args.repeat, loop)
        slow, reference = _best(args.repeat, lambda: _python(loop))
        same = bool(np.array_equal(run.speed, reference.speed)
                    and np.array_equal(run.estimate, reference.estimate))
        total, spent = _estimator_time(plant, controller, args.seconds, sensors, estimator)
        rest = best - spent * best / total                    # the loop without its estimator
        whole_ok, rest_ok = best * scale < _WHOLE, rest * scale < _LOOP
        status |= 0 if whole_ok and rest_ok else 1
        kf_rms = float(np.sqrt(np.mean(run.estimation_error ** 2)))
        fd_rms = CentralDifference(sensors).run(run.record).rms_error
        print(f"{name}: {args.seconds:g} s at {sensors.rate:g} Hz ({samples} samples) with the "
              f"Kalman filter: best of {max(args.repeat, 1)} {best:.3f} s "
              f"({best / samples * 1e6:.1f} us/sample, {args.seconds / best:.0f}x real time); "
              f"the Python loop (baseline, same run) {slow:.3f} s; ratio {slow / best:.2f}; "
              f"same trajectory and estimates: {same}")
        print(f"  estimator (observe + commanded) {spent / samples * 1e6:.1f} us/sample, "
              f"{100 * spent / total:.0f} % of the loop; the rest (plant, sensors and law in "
              f"the kernel, the per-sample calls) {rest / samples * 1e6:.1f} us/sample = "
              f"{rest * scale:.3f} s per 60 s ({'met' if rest_ok else 'SHORT'}: < {_LOOP} s)")
        print(f"  whole loop per 60 s {best * scale:.3f} s: target < {_WHOLE} s "
              f"{'met' if whole_ok else 'SHORT'}; loop target < {_LOOP} s "
              f"{'met' if best * scale < _LOOP else 'SHORT'}"
              f"; KF RMS {kf_rms * 1e3:.3f} mm/s vs central difference {fd_rms * 1e3:.3f} mm/s "
              f"({fd_rms / kf_rms:.1f}x)")

        def ideal(seconds: float = args.seconds) -> Any:
            return closed_loop.simulate_closed_loop(plant, controller, seconds, seed=1)

        ideal(0.5)
        _python(lambda: ideal(0.5))
        fast, kernel_run = _best(args.repeat, ideal)
        slow, python_run = _best(args.repeat, lambda: _python(ideal))
        same = bool(np.array_equal(kernel_run.speed, python_run.speed))
        print(f"  on the true speed (no sensors, no filter): one kernel call {fast * 1e3:.2f} ms "
              f"({fast / samples * 1e6:.2f} us/sample); the Python loop {slow * 1e3:.1f} ms; "
              f"ratio {slow / fast:.1f}; same trajectory: {same}")
    return status
