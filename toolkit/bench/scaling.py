"""Cost against size: what one call costs as contacts, horizon, runs and closed-loop length
grow (each row the best of three calls, with its cost per unit of size).

Run ``python -m toolkit.bench scaling [--quick]``; the rows: docs/methods.md."""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from toolkit.experiments import MedianLaw
from toolkit.loop.closed_loop import simulate_closed_loop
from toolkit.controllers import VirtualViscosity
from toolkit.model import ContactSet, Motors, PiecewiseConstant, Plant
from toolkit.model.carousel import CAROUSEL
from toolkit.simulation import simulate, warm_up
from toolkit.sweeps import sweep


def _best(call: Callable[[], Any], repeat: int = 3) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return min(times)


def _contacts(n: int, seed: int = 0) -> ContactSet:
    speeds = np.random.default_rng(seed).uniform(-0.35, 0.35, n)
    return ContactSet(speeds, np.full(n, 2.0 / n))


def _startup(n: int) -> Callable[[], Any]:
    contacts = _contacts(n)
    return lambda: simulate(Plant(contacts, 1.0), 5.0)       # a new plant: nothing cached


def _lagged(n: int) -> Callable[[], Any]:
    contacts = _contacts(n)
    other = _contacts(n, 1).speeds
    commands = PiecewiseConstant([1.0], np.array([contacts.speeds, other]))
    return lambda: simulate(Plant(contacts, 1.0, motors=Motors(lag=0.0075), commands=commands), 5.0)


def _horizon(seconds: float) -> Callable[[], Any]:
    rng = np.random.default_rng(0)
    pieces = int(round(50 * seconds))
    walk = np.clip(rng.uniform(-0.3, 0.3, 10) + np.cumsum(rng.normal(0, 0.01, (pieces, 10)), axis=0),
                   -0.35, 0.35)
    commands = PiecewiseConstant(np.arange(1, pieces) / 50.0, walk)
    contacts = ContactSet(walk[0], np.full(10, 1.0))
    return lambda: simulate(Plant(contacts, 5.0, motors=CAROUSEL.motors(), commands=commands), seconds)


def _runs(count: int) -> Callable[[], Any]:
    return lambda: sweep(MedianLaw(), count, seed=1)


_LOOP_PLANT = Plant(ContactSet([0.0] * 10, [1.0] * 10), 5.0, motors=CAROUSEL.motors())


def _loop(seconds: float, sensors: bool) -> Callable[[], Any]:
    suite = CAROUSEL.sensors(10) if sensors else None
    return lambda: simulate_closed_loop(_LOOP_PLANT, VirtualViscosity(50.0, 0.15), seconds,
                                        sensors=suite, seed=1)


ROWS: tuple[tuple[str, str, tuple[float, ...], Callable[[Any], Callable[[], Any]]], ...] = (
    ("contacts N, exact, ideal motors, 5 s", "contact", (10, 100, 1_000, 10_000, 100_000), _startup),
    ("contacts N, exact, motor lag, 5 s, one switch", "contact", (10, 100, 1_000, 10_000), _lagged),
    ("horizon T (s), carousel, lag, commands at 50 Hz", "s", (1, 10, 100, 1000), _horizon),
    ("runs R, median-law sweep", "run", (1, 100, 10_000, 1_000_000), _runs),
    ("closed loop L (s), 50 Hz, on the true speed", "sample", (1, 10, 60, 600),
     lambda L: _loop(L, False)),
    ("closed loop L (s), 50 Hz, encoders + Kalman filter", "sample", (1, 10, 60),
     lambda L: _loop(L, True)),
)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench scaling", description=__doc__)
    parser.add_argument("--quick", action="store_true", help="the two smallest sizes of each row")
    args = parser.parse_args(argv)

    print(f"kernels compiled or loaded from the cache in {warm_up():.2f} s (not timed); load "
          f"average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    for title, unit, sizes, make in ROWS:
        print(title)
        first = None
        for size in sizes[:2] if args.quick else sizes:
            call = make(size)
            call()                                         # once, untimed (the policy)
            wall = _best(call)
            units = size * 50 + 1 if unit == "sample" else size   # a loop of L s: 50 L + 1 samples
            per = wall / units
            first = per if first is None else first
            print(f"  {size:>9g}  {wall:10.4g} s  {per * 1e6:10.3g} us/{unit}  "
                  f"(x{per / first:.2f} the smallest size's)")
    return 0
