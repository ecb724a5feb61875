"""The benchmarks' baselines compute the same numbers as the fast paths (second method)."""

from __future__ import annotations

import numpy as np

from toolkit import ContactSet
from toolkit.bench.force import broadcast_force


def test_force_baseline_agrees_with_sorted_search():
    rng = np.random.default_rng(3)
    speeds, forces = rng.uniform(-0.35, 0.35, 300), rng.uniform(0.5, 1.5, 300)
    V = rng.uniform(-0.4, 0.4, 2500)
    # Sums of 300 terms of order 1: rounding below 300 * eps * 450 N ~ 3e-11 N.
    np.testing.assert_allclose(broadcast_force(speeds, forces, V, chunk=700),
                               ContactSet(speeds, forces).force(V), rtol=0, atol=1e-10)
