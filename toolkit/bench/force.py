"""Benchmark of :meth:`ContactSet.force` against the N x M broadcast baseline.

Run ``python -m toolkit.bench force``. The baseline evaluates the definition
``sum_i f_i sign(v_i - V)`` as an N x M broadcast, in chunks of body speeds so that its
memory stays near 100 MB (a single 1e4 x 1e5 matrix would need 8 GB). Both are timed in
the same run on the same inputs and their results compared. The kernel of
:meth:`ContactSet.force` (:func:`toolkit._compiled.core.coulomb_force`) is compiled or
loaded from numba's cache first, outside the timings. Exit status 0 when the ratio is at
least 100 and N = 1e5 contacts at M = 1e6 speeds take under 0.15 s, construction
included.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from toolkit.simulation import warm_up
from toolkit.model import ContactSet

TARGET = 0.15           # s for N = 1e5, M = 1e6


def broadcast_force(speeds: np.ndarray, forces: np.ndarray, V: np.ndarray, chunk: int = 1000) -> np.ndarray:
    """The definition evaluated as an N x chunk matrix per chunk of body speeds (the baseline)."""
    out = np.empty(V.shape)
    for start in range(0, V.size, chunk):
        block = V[start:start + chunk]
        out[start:start + chunk] = forces @ np.sign(speeds[:, None] - block[None, :])
    return out


def _best_of(repeats: int, function, *args):
    best, value = np.inf, None
    for _ in range(repeats):
        start = time.perf_counter()
        value = function(*args)
        best = min(best, time.perf_counter() - start)
    return best, value


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench force", description=__doc__)
    parser.add_argument("--n", type=int, default=10_000, help="contacts for the ratio (default 1e4)")
    parser.add_argument("--m", type=int, default=100_000, help="body speeds for the ratio (default 1e5)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    print(f"kernels compiled or loaded from the cache in {warm_up():.2f} s (not timed)")

    speeds, forces = rng.uniform(-0.35, 0.35, args.n), rng.uniform(0.5, 1.5, args.n)
    V = rng.uniform(-0.4, 0.4, args.m)
    t_fast, fast = _best_of(3, lambda: ContactSet(speeds, forces).force(V))
    t_base, base = _best_of(1, broadcast_force, speeds, forces, V)
    error = float(np.max(np.abs(fast - base)))
    print(f"N={args.n:.0e} M={args.m:.0e}: bucket-index kernel {t_fast * 1e3:.1f} ms "
          f"(construction included), N x M broadcast {t_base * 1e3:.0f} ms, "
          f"ratio {t_base / t_fast:.0f}x, max |difference| {error:.1e} N")

    big_n, big_m = 100_000, 1_000_000
    speeds, forces = rng.uniform(-0.35, 0.35, big_n), rng.uniform(0.5, 1.5, big_n)
    V = rng.uniform(-0.4, 0.4, big_m)
    t_big, _ = _best_of(5, lambda: ContactSet(speeds, forces).force(V))
    print(f"N={big_n:.0e} M={big_m:.0e}: bucket-index kernel {t_big:.3f} s (min of 5, "
          f"construction included, one core; target {TARGET} s; load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores)")
    return 0 if t_base / t_fast >= 100 and t_big < TARGET else 1


if __name__ == "__main__":
    raise SystemExit(main())
