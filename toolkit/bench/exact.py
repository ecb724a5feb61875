"""Exact-method benchmark: fixed cost per run, the landscape cache, and cost per event against N.

Run ``python -m toolkit.bench exact [--repeats R] [--seed K]``. Prints

- the carousel startup scene (11 random speeds, 5 s, from rest): the time per call on fresh
  plants (cold: the sorted force landscape is built) and on one plant (warm: the exact
  method keeps that plant's landscape in its cache), and their ratio;
- startups from below every contact for N = 1e3, 1e4, 1e5 (about N/2 crossings each): time
  per event, and its ratio to the N = 1e3 time per event (O(1) work per event keeps it near
  1; an O(N) scan per event would make it ~100 at N = 1e5); and the time per event when the
  caller also reads ``result.events`` (the :class:`Event` objects are built on first access).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from toolkit.simulation import warm_up
from toolkit.model import ContactSet, Plant
from toolkit.model.carousel import carousel_startup_plant as _carousel
from toolkit.simulation import simulate


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench exact", description=__doc__)
    parser.add_argument("--repeats", type=int, default=2000, help="carousel calls per timing")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    print(f"kernels compiled or loaded from the cache in {warm_up():.2f} s (not timed)")
    plants = [_carousel(args.seed) for _ in range(args.repeats)]   # same scene, fresh caches
    simulate(_carousel(args.seed), 5.0)                              # imports, warm-up
    start = time.perf_counter()
    for plant in plants:
        simulate(plant, 5.0)
    cold = (time.perf_counter() - start) / args.repeats
    plant = plants[0]
    start = time.perf_counter()
    for _ in range(args.repeats):
        simulate(plant, 5.0)
    warm = (time.perf_counter() - start) / args.repeats
    events = simulate(plant, 5.0).n_events
    print(f"carousel (11 contacts, {events} events): cold {cold * 1e6:.1f} us/run, "
          f"warm {warm * 1e6:.1f} us/run, ratio cold / warm {cold / warm:.2f}")

    rng = np.random.default_rng(args.seed)
    base = None
    for n in (1_001, 10_001, 100_001):
        scene = Plant(ContactSet(rng.uniform(-1.0, 1.0, n), np.full(n, 1.0 / n)), 1.0)
        times, with_events = [], []
        for _ in range(3):
            start = time.perf_counter()
            result = simulate(scene, 20.0, v0=-1.5)
            times.append(time.perf_counter() - start)
            start = time.perf_counter()
            simulate(scene, 20.0, v0=-1.5).events     # the Event objects, built on access
            with_events.append(time.perf_counter() - start)
        per_event = statistics.median(times) / result.n_events
        base = per_event if base is None else base
        print(f"N = {n:>7d}: {result.n_events:>6d} events, {statistics.median(times):.3f} s, "
              f"{per_event * 1e6:.2f} us/event, ratio to N = 1001: {per_event / base:.2f}; "
              f"reading result.events too: "
              f"{statistics.median(with_events) / result.n_events * 1e6:.2f} us/event")
    return 0
