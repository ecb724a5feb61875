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


def test_scaling_rows_cost_what_their_problems_compute(capsys):
    # The scaling bench's rows build the problems the README's table names: the horizon row's
    # simulation ends at T with 50 T command pieces behind it, the contacts row's startup
    # stops on the weighted median (closed form: the equilibrium of its contacts, atol 1e-12),
    # and the quick run prints two sizes per row.
    from toolkit.bench import scaling

    result = scaling._horizon(2.0)()
    assert result.success and result.t[-1] == 2.0
    assert sum(event.kind == "command" for event in result.events) == 99
    contacts = scaling._contacts(101)
    startup = scaling._startup(101)()
    lo, hi = contacts.equilibrium()
    assert lo - 1e-12 <= startup.V[-1] <= hi + 1e-12
    assert scaling.main(["--quick"]) == 0
    out = capsys.readouterr().out
    assert out.count("us/") == 2 * len(scaling.ROWS)


def test_compile_bench_names_the_kernels_compiled_more_than_once():
    # The summary line of the compile bench: totals and the kernels of more than one
    # version, most first (an identity of its input).
    from toolkit.bench.compile import _versions

    assert _versions({"a": 1, "b": 3, "c": 2}) == "6 compiled versions of 3 kernels; more than one: b 3, c 2"
    assert _versions({"a": 1}) == "1 compiled versions of 1 kernels; more than one: none"
