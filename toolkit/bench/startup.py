"""Start-up benchmark: what compiled kernels cost a fresh process, and the command line
against a baseline tree before the compiled core.

Run ``python -m toolkit.bench startup [--runs R] [--baseline PATH | --base-commit REV]`` from
the repository root; what it measures and its exit status: docs/methods.md."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path

from toolkit.scenes.designs import design_path

_FIRST_CALL = """
import time
start = time.perf_counter()
import numpy as np
from toolkit.model.carousel import carousel_startup_plant
from toolkit.simulation import simulate
plant = carousel_startup_plant(0)
times = np.linspace(0.0, 5.0, 1004)
imported = time.perf_counter()
simulate(plant, 5.0, t_eval=times)
done = time.perf_counter()
print(imported - start, done - imported)
"""

_WARM_UP = """
import time
start = time.perf_counter()
from toolkit.simulation import warm_up
print(warm_up() + 0 * start)
"""


def _python(code: str, cwd: Path, env: dict[str, str]) -> list[float]:
    done = subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, check=True,
                          capture_output=True, text=True)
    return [float(x) for x in done.stdout.split()]


def _cli_run(tree: Path, env: dict[str, str], out: Path, design: Path) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "toolkit.cli", "run", str(design),
                    "--out", str(out)], cwd=tree, env=env, check=True, capture_output=True)
    return time.perf_counter() - start


def _before_compiled_core(repo: Path) -> str:
    """The commit before the one that added the compiled kernels' package (the baseline of
    this benchmark), from the repository's history."""
    added = subprocess.run(["git", "-C", str(repo), "log", "--diff-filter=A", "--format=%H", "--",
                            "toolkit/_compiled/__init__.py"], check=True, capture_output=True, text=True)
    return added.stdout.split()[-1] + "^"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench startup", description=__doc__)
    parser.add_argument("--runs", type=int, default=7, help="fresh processes per figure")
    parser.add_argument("--baseline", type=Path, help="a toolkit checkout before the change")
    parser.add_argument("--base-commit", help="made a worktree if no --baseline (default: the "
                        "commit before the compiled kernels' package came in)")
    args = parser.parse_args(argv)

    here = Path(__file__).resolve().parents[2]
    base_env = {k: v for k, v in os.environ.items()
                if k not in ("ACTIVE_CONTACTS_COMPILE", "NUMBA_CACHE_DIR", "NUMBA_DISABLE_JIT")}
    eager = {**base_env, "ACTIVE_CONTACTS_COMPILE": "eager"}
    with tempfile.TemporaryDirectory(prefix="bench-startup-") as tmp, ExitStack() as stack:
        tmp_path = Path(tmp)
        cache = tmp_path / "numba-cache"
        cold_env = {**eager, "NUMBA_CACHE_DIR": str(cache)}
        # Cold: an empty cache directory per process (numba compiles everything it runs).
        cold_first, cold_all = [], []
        for _ in range(max(1, min(args.runs, 2))):          # compiling is slow: 2 at most
            shutil.rmtree(cache, ignore_errors=True)
            cold_first.append(_python(_FIRST_CALL, here, cold_env)[1])
            shutil.rmtree(cache, ignore_errors=True)
            cold_all.append(_python(_WARM_UP, here, cold_env)[0])
        # Warm: the cache the last cold run left (warm_up compiled every kernel into it).
        warm_first = [_python(_FIRST_CALL, here, cold_env)[1] for _ in range(args.runs)]
        warm_all = [_python(_WARM_UP, here, cold_env)[0] for _ in range(args.runs)]
        lazy_first = [_python(_FIRST_CALL, here, base_env)[1] for _ in range(args.runs)]
        print(f"first simulate (carousel startup, 1004 times) in a fresh process, kernels "
              f"compiled at once: cold cache {min(cold_first):.2f} s, warm cache "
              f"{min(warm_first) * 1e3:.1f} ms; default (run as Python until it pays): "
              f"{min(lazy_first) * 1e3:.1f} ms")
        print(f"every kernel (toolkit.simulation.warm_up): cold cache {min(cold_all):.1f} s, "
              f"warm cache {min(warm_all):.2f} s")

        baseline = args.baseline
        worktree = None
        if baseline is None:
            worktree = tmp_path / "baseline"
            if args.base_commit is None:
                args.base_commit = _before_compiled_core(here)
            subprocess.run(["git", "-C", str(here), "worktree", "add", "--detach",
                            str(worktree), args.base_commit], check=True, capture_output=True)
            baseline = worktree
        try:
            out = tmp_path / "out"
            runs: dict[str, list[float]] = {"this tree": [], "this tree, compiled": [],
                                            "baseline": []}
            # This tree's design through the package (installed or not); the baseline is a checkout.
            design = stack.enter_context(design_path("carousel"))
            trees = {"this tree": (here, base_env, design),
                     "baseline": (baseline, base_env, baseline / "designs" / "carousel.toml"),
                     "this tree, compiled": (here, cold_env, design)}
            for name, (tree, env, path) in trees.items():          # once each: caches, page cache
                _cli_run(tree, env, out, path)
            for _ in range(args.runs):
                for name, (tree, env, path) in trees.items():
                    runs[name].append(_cli_run(tree, env, out, path))
        finally:
            if worktree is not None:
                subprocess.run(["git", "-C", str(here), "worktree", "remove", "--force",
                                str(worktree)], check=False, capture_output=True)
    best = {name: min(values) for name, values in runs.items()}
    print(f"active-contacts run designs/carousel.toml (min of {args.runs} fresh processes, "
          f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores):")
    for name, value in best.items():
        print(f"  {name:22s} {value:.3f} s   ratio to baseline {value / best['baseline']:.3f}")
    return 0 if best["this tree"] <= 1.03 * best["baseline"] else 1
