"""Sweep benchmark: the median-law sweep in one process, from the command line, and
optionally on a process pool or a Dask cluster, against single runs measured in the same run.

Run ``python -m toolkit.bench sweep [--runs R] [--loop L] [--seed K] [--dask] [--processes]``;
what it prints and its exit status: docs/methods.md."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from toolkit.experiments import MedianLaw
from toolkit.scenes.designs import design_path
from toolkit.model import ContactSet, Plant
from toolkit.simulation import simulate, simulate_batch
from toolkit.sweeps import run_keys, sweep

_SWEEP, _CLI = 0.5, 3.0          # s for 1e5 runs: in one process, and the CLI from its start


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench sweep", description=__doc__)
    parser.add_argument("--runs", type=int, default=100_000)
    parser.add_argument("--loop", type=int, default=1_000, help="runs looped one by one (baseline)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--dask", action="store_true", help="also run on a 2-worker LocalCluster")
    parser.add_argument("--processes", action="store_true", help="also run on a 2-worker process pool")
    args = parser.parse_args(argv)

    experiment = MedianLaw()
    results = [sweep(experiment, args.runs, seed=args.seed) for _ in range(3)]
    result = min(results, key=lambda r: r.wall_time)
    per_sweep = result.wall_time / args.runs
    full = args.runs >= 100_000
    sweep_ok = not full or result.wall_time * 100_000 / args.runs < _SWEEP
    print(f"sweep: {args.runs} median-law runs in {result.wall_time:.3f} s (best of 3; "
          f"{per_sweep * 1e6:.2f} us/run; {'met' if sweep_ok else 'SHORT'}: target < {_SWEEP} s "
          f"per 1e5 runs), after a one-time {results[0].compile_time:.2f} s (kernels and run 0, "
          f"not timed); slope {result.summary['slope']:.4f}")

    loop = min(args.loop, args.runs)
    keys = run_keys(args.seed, 0, loop)
    _, actual, forces = experiment.draw(keys)
    start = time.perf_counter()
    finals = [simulate(Plant(ContactSet(actual[j], forces[j]), experiment.mass),
                       experiment.horizon()).V[-1] for j in range(loop)]
    per_loop = (time.perf_counter() - start) / loop
    expected = result.table["true_speed"].to_numpy()[:loop]
    rel = float(np.max(np.abs(np.array(finals) - expected) / np.maximum(np.abs(expected), 1e-300)))
    print(f"baseline, single exact runs: {loop} runs at {per_loop * 1e6:.1f} us/run; ratio "
          f"{per_loop / per_sweep:.0f}x; max relative difference {rel:.1e}")

    n = experiment.n
    start = time.perf_counter()
    chunk = keys.uniform(0, n, -experiment.speed_limit, experiment.speed_limit)
    chunk_time = time.perf_counter() - start
    start = time.perf_counter()
    rows = np.array([keys.generator(j).uniform(-experiment.speed_limit, experiment.speed_limit, n)
                     for j in range(loop)])
    row_time = time.perf_counter() - start
    same = bool(np.array_equal(rows, chunk))
    print(f"random draws of {loop} runs: one compiled call {chunk_time * 1e3:.2f} ms; a generator "
          f"per run {row_time * 1e3:.1f} ms; ratio {row_time / chunk_time:.0f}x; the same numbers: "
          f"{same}")

    t_end = experiment.horizon()
    start = time.perf_counter()
    probe = simulate_batch(actual, forces, experiment.mass, t_end, t_probe=0.5 * t_end)
    one = time.perf_counter() - start
    start = time.perf_counter()
    second = simulate_batch(actual, forces, experiment.mass, 0.5 * t_end)
    simulate_batch(actual, forces, experiment.mass, t_end)
    two = time.perf_counter() - start
    agree = bool(np.allclose(probe.probe_speeds, second.final_speeds, rtol=1e-12, atol=1e-15))
    print(f"settled check of {loop} runs: read from the run {one * 1e3:.2f} ms; a second "
          f"simulation {two * 1e3:.2f} ms; ratio {two / one:.2f}; the same speeds: {agree}")
    ok = rel <= 1e-12 and same and agree and sweep_ok

    root = Path(__file__).resolve().parents[2]
    with design_path("median_law") as design:          # the package's, installed or not
        command = [str(Path(sys.executable).with_name("active-contacts")), "sweep", str(design),
                   "--runs", str(args.runs), "--seed", str(args.seed), "--json"]
        if not Path(command[0]).exists():
            command[:1] = [sys.executable, "-m", "toolkit.cli"]
        start = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True, cwd=root,
                              env={**os.environ, "PYTHONPATH": str(root)})
        cli = time.perf_counter() - start
    cli_ok = done.returncode == 0 and (not full or cli * 100_000 / args.runs < _CLI)
    if done.returncode != 0:           # a failure, not a speed: say what failed
        print(f"active-contacts sweep median_law failed (exit {done.returncode}): "
              f"{(done.stderr.strip().splitlines() or [''])[-1]}")
    print(f"active-contacts sweep designs/median_law.toml --runs {args.runs}: {cli:.2f} s "
          f"including process start ({'met' if cli_ok else 'SHORT'}: target < {_CLI} s per 1e5 "
          f"runs; exit {done.returncode})")
    ok = ok and cli_ok

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
