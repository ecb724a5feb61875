"""Sweep benchmark: the median-law sweep of issue 12 on this machine and on Dask.

Run ``python -m toolkit.bench sweep [--runs R] [--loop L] [--seed K] [--dask] [--processes]``. Times the
median-law sweep (``toolkit.sweep(MedianLaw(), R)``: 10 random speeds per run, from rest,
20 s each, the exact batch path) and, as the baseline in the same run, the first ``L`` runs
one by one through ``simulate(..., method="exact")`` (extrapolated per run). Checks that the
looped runs give the sweep's speeds (to 1e-12 relative). With ``--dask``, also runs the
same sweep on a 2-worker ``distributed.LocalCluster`` and checks that its table equals the
local one bit for bit. With ``--processes``, also runs it on a 2-worker process pool (fresh
interpreters, start-up included) and prints the pool's time over the local one (the reason
the local default stays in one process). Exit status 0 when 1e5 runs take under 10 s and every check holds.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from toolkit.experiments import MedianLaw
from toolkit.model import ContactSet, Plant
from toolkit.simulation import simulate
from toolkit.sweeps import run_seeds, sweep


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench sweep", description=__doc__)
    parser.add_argument("--runs", type=int, default=100_000)
    parser.add_argument("--loop", type=int, default=1_000, help="runs looped one by one (baseline)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--dask", action="store_true", help="also run on a 2-worker LocalCluster")
    parser.add_argument("--processes", action="store_true", help="also run on a 2-worker process pool")
    args = parser.parse_args(argv)

    experiment = MedianLaw()
    result = sweep(experiment, args.runs, seed=args.seed)
    per_sweep = result.wall_time / args.runs
    print(f"sweep: {args.runs} median-law runs in {result.wall_time:.3f} s "
          f"({per_sweep * 1e6:.1f} us/run); slope {result.summary['slope']:.4f}")

    loop = min(args.loop, args.runs)
    _, actual, forces = experiment.draw(run_seeds(args.seed, 0, loop))
    start = time.perf_counter()
    finals = [simulate(Plant(ContactSet(actual[j], forces[j]), experiment.mass),
                       experiment.horizon()).V[-1] for j in range(loop)]
    loop_time = time.perf_counter() - start
    per_loop = loop_time / loop
    expected = result.table["true_speed"].to_numpy()[:loop]
    rel = float(np.max(np.abs(np.array(finals) - expected) / np.maximum(np.abs(expected), 1e-300)))
    print(f"baseline, single exact runs: {loop} runs in {loop_time:.3f} s ({per_loop * 1e6:.1f} us/run)")
    print(f"ratio baseline / sweep per run: {per_loop / per_sweep:.0f}x; "
          f"max relative difference over {loop} runs: {rel:.1e}")
    ok = rel <= 1e-12 and (args.runs < 100_000 or result.wall_time * 100_000 / args.runs < 10.0)

    if args.processes:
        pooled = sweep(experiment, args.runs, seed=args.seed, scheduler="processes", workers=2)
        same = pooled.table.equals(result.table)
        print(f"process pool (2 workers, start-up included): {pooled.wall_time:.3f} s, "
              f"{pooled.wall_time / result.wall_time:.2f}x the local sweep; table identical: {same}")
        ok = ok and same

    if args.dask:
        import distributed

        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                      dashboard_address=None) as cluster:
            start = time.perf_counter()
            remote = sweep(experiment, args.runs, seed=args.seed, scheduler=cluster.scheduler_address)
            remote_time = time.perf_counter() - start
        same = remote.table.equals(result.table)
        print(f"dask LocalCluster (2 workers): {remote_time:.3f} s; table identical: {same}")
        ok = ok and same
    return 0 if ok else 1
