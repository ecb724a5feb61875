"""Exact stepper benchmark: the cost of one sample period of a closed loop.

Run ``python -m toolkit.bench stepper [--steps S] [--seed K]``. On the carousel (11 contacts,
motor lag 0.0075 s, speed limits +-0.35 m/s) it steps ``S`` periods of 20 ms (50 Hz) with
:func:`toolkit.simulation.advance`, the command of each period drawn near the previous one
(a random walk of 0.02 m/s per period, clipped to the limits, as a controller's would be),
and prints the time per step and its ratio against running ``simulate`` from scratch over
each period (a new plant holding that period's command, started from the same state). The
60 s closed loop of issue 9 takes 3000 steps: it wants <= 60 us per step. It also prints how
many steps took the certified no-event shortcut of ``advance`` and the time per step of the
full engine on every step (the shortcut off), measured in the same run.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from toolkit.simulation._warmup import warm_up
from toolkit.model import PiecewiseConstant
from toolkit.model.carousel import CAROUSEL, carousel_startup_plant
from toolkit.simulation import ExactState, _stepper, advance, simulate

_PERIOD = 1.0 / CAROUSEL.rate          # s


def _commands(seed: int, steps: int, n: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.normal(0.0, 0.02, (steps, n)), axis=0)
    return np.clip(rng.uniform(-0.35, 0.35, n) + walk, -0.35, 0.35)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench stepper", description=__doc__)
    parser.add_argument("--steps", type=int, default=3000, help="20 ms steps (3000: 60 s)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    print(f"kernels compiled or loaded from the cache in {warm_up():.2f} s (not timed)")
    plant = dataclasses.replace(carousel_startup_plant(args.seed), motors=CAROUSEL.motors())
    commands = _commands(args.seed, args.steps, plant.n)
    state = initial = ExactState(0.0, 0.0, np.clip(commands[0], -0.35, 0.35))
    advance(plant, state, commands[0], _PERIOD)                       # imports, warm-up
    events = quiet = 0
    start = time.perf_counter()
    for k in range(args.steps):
        step = advance(plant, state, commands[k], (k + 1) * _PERIOD)
        state = step.state
        events += len(step.events)
        quiet += step._quiet
    per_step = (time.perf_counter() - start) / args.steps

    # The same steps with the full engine on every one (the no-event shortcut off).
    _stepper._QUIET = False
    try:
        state = initial
        start = time.perf_counter()
        for k in range(args.steps):
            state = advance(plant, state, commands[k], (k + 1) * _PERIOD).state
        per_engine = (time.perf_counter() - start) / args.steps
    finally:
        _stepper._QUIET = True

    # Baseline: simulate from scratch per period (a plant per command, motors restarted
    # settled: simulate cannot take unsettled motors, so this is its cheapest equivalent).
    runs = min(args.steps, 300)
    start = time.perf_counter()
    for k in range(runs):
        held = dataclasses.replace(plant, commands=PiecewiseConstant([1e-9], commands[k:k + 2]
                                                                      if k + 1 < args.steps
                                                                      else commands[[k, k]]))
        simulate(held, _PERIOD, v0=0.0)
    per_simulate = (time.perf_counter() - start) / runs
    print(f"carousel, lag {CAROUSEL.motor_lag} s, {args.steps} steps of {_PERIOD * 1e3:.0f} ms "
          f"({events} events): advance {per_step * 1e6:.1f} us/step "
          f"({per_step * args.steps:.3f} s per {args.steps * _PERIOD:.0f} s); simulate from "
          f"scratch per step {per_simulate * 1e6:.1f} us; ratio simulate / advance "
          f"{per_simulate / per_step:.2f}")
    print(f"no-event shortcut taken on {quiet} of {args.steps} steps "
          f"({100.0 * quiet / args.steps:.0f} %); full engine on every step "
          f"{per_engine * 1e6:.1f} us/step; ratio engine / advance {per_engine / per_step:.2f}")
    return 0
