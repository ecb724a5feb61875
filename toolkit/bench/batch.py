"""Batch benchmark: ``simulate_batch`` against looping the single-run exact method.

Run ``python -m toolkit.bench batch [--scenes S] [--contacts N] [--loop L] [--repeats R]
[--seed K]``. Random startup scenes (speeds uniform in [-0.35, 0.35] m/s, magnitudes uniform
in [0.05, 0.15] N, mass 0.5 kg, from rest, 5 s). The kernels are compiled (or loaded from
numba's cache) first, and that time is printed apart. The batch runs every scene, ``R`` times
(the minimum is reported, with the load average: the machine may be shared); the loop runs
``L`` scenes spread over the batch one by one through ``simulate(..., method="exact")``.
Prints both times, the per-scene ratio, and the largest relative difference of the final
speeds (and whether every event count agrees). Exit status 0 when the issue-11 criterion
holds: 1e6 scenes under 0.4 s (scaled for other sizes), every compared scene within 1e-12.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from toolkit.simulation import warm_up
from toolkit.model import ContactSet, Plant
from toolkit.simulation import simulate, simulate_batch

TARGET = 0.4            # s per 1e6 scenes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench batch", description=__doc__)
    parser.add_argument("--scenes", type=int, default=1_000_000)
    parser.add_argument("--contacts", type=int, default=10)
    parser.add_argument("--loop", type=int, default=1_000, help="scenes run one by one")
    parser.add_argument("--repeats", type=int, default=5, help="batch timings (minimum shown)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    compile_time = warm_up()
    rng = np.random.default_rng(args.seed)
    speeds = rng.uniform(-0.35, 0.35, (args.scenes, args.contacts))
    forces = rng.uniform(0.05, 0.15, (args.scenes, args.contacts))
    mass, t_end = 0.5, 5.0

    times = []
    for _ in range(max(1, args.repeats)):
        start = time.perf_counter()
        batch = simulate_batch(speeds, forces, mass, t_end)
        times.append(time.perf_counter() - start)
    batch_time = min(times)

    loop = min(args.loop, args.scenes)
    picked = np.sort(rng.choice(args.scenes, loop, replace=False))
    start = time.perf_counter()
    singles = [simulate(Plant(ContactSet(speeds[s], forces[s]), mass), t_end) for s in picked]
    loop_time = time.perf_counter() - start

    finals = np.array([single.V[-1] for single in singles])
    mine = batch.final_speeds[picked]
    rel = float(np.max(np.abs(finals - mine) / np.maximum(np.abs(mine), 1e-300)))
    same_events = bool(np.all(batch.n_events[picked] == [s.n_events for s in singles]))
    per_batch = batch_time / args.scenes
    per_loop = loop_time / loop
    load = os.getloadavg()[0]
    print(f"kernels compiled or loaded from the cache in {compile_time:.2f} s (not timed below)")
    print(f"batch: {args.scenes} scenes x {args.contacts} contacts in {batch_time:.4f} s "
          f"(min of {len(times)}: {' '.join(f'{t:.3f}' for t in times)}; "
          f"{per_batch * 1e6:.3f} us/scene, {int(batch.n_events.sum())} events; "
          f"load average {load:.2f} on {os.cpu_count()} cores)")
    print(f"loop of single exact runs: {loop} scenes in {loop_time:.3f} s "
          f"({per_loop * 1e6:.1f} us/scene)")
    print(f"ratio loop / batch per scene: {per_loop / per_batch:.0f}x")
    print(f"max relative difference of final speeds over {loop} scenes: {rel:.1e}; "
          f"event counts {'equal' if same_events else 'DIFFER'}")
    ok = rel <= 1e-12 and same_events and batch_time * 1e6 / args.scenes < TARGET
    print(f"target (1e6 scenes under {TARGET} s, each within 1e-12): "
          f"{'met' if ok else 'missed'}")
    return 0 if ok else 1
