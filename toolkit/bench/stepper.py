"""Exact stepper benchmark: the cost of one sample period of a closed loop (``advance``), and of
a step with six motor-lag crossings, compiled against the same source run as Python.

Run ``python -m toolkit.bench stepper [--steps S] [--seed K]``; details: docs/methods.md."""

from __future__ import annotations

import argparse
import dataclasses
import os
import subprocess
import sys
import time
import timeit
from pathlib import Path

import numpy as np

from toolkit.simulation import warm_up
from toolkit.model import ContactSet, Motors, PiecewiseConstant, Plant
from toolkit.model.carousel import CAROUSEL, carousel_startup_plant
from toolkit.simulation import ExactState, advance, simulate

_PERIOD = 1.0 / CAROUSEL.rate          # s
_TARGET = 15e-6                        # s per advance step with lagging motors


def _commands(seed: int, steps: int, n: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.normal(0.0, 0.02, (steps, n)), axis=0)
    return np.clip(rng.uniform(-0.35, 0.35, n) + walk, -0.35, 0.35)


def lag_transient() -> tuple[Plant, ExactState, np.ndarray, float]:
    """A step full of events for the dynamic-motor engine: ten contacts (1 N each, spread
    0.1 m/s) cruising at 0.15-0.25 m/s under a 5 kg body at 0.194444 m/s are commanded
    0.3 m/s lower (motor lag 7.5 ms) for 20 ms from t = 5 s; the body crosses six of them
    within 1.6 ms. Returns ``(plant, state, command, t1)`` for :func:`advance`."""
    offsets = np.linspace(-0.05, 0.05, 10)
    cruise = 0.2 + offsets
    plant = Plant(ContactSet(cruise, np.ones(10)), 5.0, motors=Motors(lag=0.0075))
    return plant, ExactState(5.0, 0.194444, cruise), -0.1 + offsets, 5.02


def time_lag_transient(number: int = 200, repeat: int = 5) -> float:
    """Best time (s) per ``advance`` call of :func:`lag_transient` (after one untimed call)."""
    plant, state, command, t1 = lag_transient()
    advance(plant, state, command, t1)
    runs = timeit.repeat(lambda: advance(plant, state, command, t1), number=number,
                         repeat=repeat)
    return min(runs) / number


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench stepper", description=__doc__)
    parser.add_argument("--steps", type=int, default=3000, help="20 ms steps (3000: 60 s)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeat", type=int, default=5, help="passes over the steps (best kept)")
    args = parser.parse_args(argv)

    print(f"kernels compiled or loaded from the cache in {warm_up():.2f} s (not timed)")
    plant = dataclasses.replace(carousel_startup_plant(args.seed), motors=CAROUSEL.motors())
    commands = _commands(args.seed, args.steps, plant.n)
    state = initial = ExactState(0.0, 0.0, np.clip(commands[0], -0.35, 0.35))
    advance(plant, state, commands[0], _PERIOD)                       # imports, warm-up
    passes = []
    for _ in range(max(args.repeat, 1)):            # the best pass: others' load is not ours
        state, events, quiet = initial, 0, 0
        start = time.perf_counter()
        for k in range(args.steps):
            step = advance(plant, state, commands[k], (k + 1) * _PERIOD)
            state = step.state
            events += len(step.events)
            quiet += step.shortcut
        passes.append((time.perf_counter() - start) / args.steps)
    per_step = min(passes)

    # The same steps with the full engine on every one (the no-event shortcut off).
    state = initial
    start = time.perf_counter()
    for k in range(args.steps):
        state = advance(plant, state, commands[k], (k + 1) * _PERIOD, shortcut=False).state
    per_engine = (time.perf_counter() - start) / args.steps

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
    met = per_step <= _TARGET
    print(f"carousel, lag {CAROUSEL.motor_lag} s, {args.steps} steps of {_PERIOD * 1e3:.0f} ms "
          f"({events} events): advance {per_step * 1e6:.1f} us/step (best of {len(passes)} passes) "
          f"({'met' if met else 'SHORT'}: target <= {_TARGET * 1e6:.0f} us) "
          f"({per_step * args.steps:.3f} s per {args.steps * _PERIOD:.0f} s); simulate from "
          f"scratch per step {per_simulate * 1e6:.1f} us; ratio simulate / advance "
          f"{per_simulate / per_step:.2f}")
    print(f"no-event shortcut taken on {quiet} of {args.steps} steps "
          f"({100.0 * quiet / args.steps:.0f} %); full engine on every step "
          f"{per_engine * 1e6:.1f} us/step; ratio engine / advance {per_engine / per_step:.2f}")

    # A step with events (the dynamic-motor engine): compiled, and as Python in a subprocess.
    compiled = time_lag_transient()
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1",
           "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", "from toolkit.bench.stepper import "
                           "time_lag_transient; print(time_lag_transient(50, 5))"],
                          env=env, cwd=root, check=True, capture_output=True, text=True)
    python = float(done.stdout)
    events = len(advance(*lag_transient()).events)
    print(f"lag transient (10 contacts, lag 7.5 ms, {events} crossings within 1.6 ms of a "
          f"20 ms step): advance {compiled * 1e6:.0f} us/call; the same source as Python "
          f"(NUMBA_DISABLE_JIT=1) {python * 1e6:.0f} us/call; ratio Python / compiled "
          f"{python / compiled:.1f}")
    return 0 if met else 1
