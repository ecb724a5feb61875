"""Batch benchmark: ``simulate_batch`` against looping the single-run exact method.

Run ``python -m toolkit.bench batch [--scenes S] [--contacts N] [--loop L] [--seed K]``.
Random startup scenes (speeds uniform in [-0.35, 0.35] m/s, magnitudes uniform in
[0.05, 0.15] N, mass 0.5 kg, from rest, 5 s). The batch runs every scene; the loop runs the
first ``L`` scenes one by one through ``simulate(..., method="exact")``. Prints both times,
the per-scene ratio, and the largest relative difference of the final speeds. Exit status 0
when the issue-3 criterion holds (batch of 1e4 under 1 s, every compared scene within 1e-12).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from toolkit.model import ContactSet, Plant
from toolkit.simulation import simulate, simulate_batch


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench batch", description=__doc__)
    parser.add_argument("--scenes", type=int, default=10_000)
    parser.add_argument("--contacts", type=int, default=10)
    parser.add_argument("--loop", type=int, default=1_000, help="scenes run one by one")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    rng = np.random.default_rng(args.seed)
    speeds = rng.uniform(-0.35, 0.35, (args.scenes, args.contacts))
    forces = rng.uniform(0.05, 0.15, (args.scenes, args.contacts))
    mass, t_end = 0.5, 5.0

    start = time.perf_counter()
    batch = simulate_batch(speeds, forces, mass, t_end)
    batch_time = time.perf_counter() - start

    loop = min(args.loop, args.scenes)
    start = time.perf_counter()
    finals = [simulate(Plant(ContactSet(speeds[s], forces[s]), mass), t_end).V[-1]
              for s in range(loop)]
    loop_time = time.perf_counter() - start

    diff = np.abs(np.array(finals) - batch.final_speeds[:loop])
    rel = float(np.max(diff / np.maximum(np.abs(batch.final_speeds[:loop]), 1e-300)))
    per_batch = batch_time / args.scenes
    per_loop = loop_time / loop
    print(f"batch: {args.scenes} scenes x {args.contacts} contacts in {batch_time:.4f} s "
          f"({per_batch * 1e6:.2f} us/scene, {int(batch.n_events.sum())} events)")
    print(f"loop of single exact runs: {loop} scenes in {loop_time:.3f} s "
          f"({per_loop * 1e6:.1f} us/scene)")
    print(f"ratio loop / batch per scene: {per_loop / per_batch:.0f}x")
    print(f"max relative difference of final speeds over {loop} scenes: {rel:.1e}")
    ok = rel <= 1e-12 and (args.scenes < 10_000 or batch_time * 10_000 / args.scenes < 1.0)
    return 0 if ok else 1
