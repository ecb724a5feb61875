"""The compiled engines reproduce, bit for bit, the outputs recorded from the kernels as they
stood before they were split by engine (``tests/data/kernel_reference.npz``, written by
``tests/data/make_kernel_reference.py``, which says how): exact and Moreau simulations,
``advance``, batches, closed loops and sampled batches, the Coulomb force and median on
unequal forces at several scales with ideal, lagging, rate-limited and compliant motors; and
the kernels other packages call, replayed from their recorded arguments. Tolerance: none
(``assert_array_equal``), compiled and under ``NUMBA_DISABLE_JIT=1`` alike."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data"
#: Entries that depend on code outside the kernels and the engines (the estimators, rewritten
#: elsewhere): recorded for the replays, not compared.
NOT_COMPARED = ("estimation/", "loop/speed_hold+sensors/", "replay/")


def _maker():
    spec = importlib.util.spec_from_file_location("make_kernel_reference", DATA / "make_kernel_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def reference():
    with np.load(DATA / "kernel_reference.npz") as data:
        return {key: data[key] for key in data.files}


@pytest.mark.parametrize("part", ["_simulations", "_steps", "_batches", "_loops", "_contact_sets"])
def test_engines_reproduce_the_reference(reference, part):
    out: dict[str, np.ndarray] = {}
    getattr(_maker(), part)(out)
    compared = {k for k in out if not k.startswith(NOT_COMPARED)}
    assert compared, part
    prefixes = {k.split("/", 1)[0] + "/" for k in compared}
    stored = {k for k in reference if k.startswith(tuple(prefixes)) and not k.startswith(NOT_COMPARED)}
    assert compared == stored
    for key in sorted(compared):
        np.testing.assert_array_equal(out[key], reference[key], err_msg=key, strict=True)


def test_replayed_kernels_reproduce_the_reference(reference):
    from toolkit._compiled import load

    core = load("core")
    calls = sorted({tuple(k.split("/")[1:3]) for k in reference if k.startswith("replay/")})
    assert {name for name, _ in calls} >= {"linearize_step", "period_bounds", "coulomb_force"}
    for name, k in calls:
        prefix = f"replay/{name}/{k}/"
        count = 1 + max(int(key[len(prefix) + 2:]) for key in reference
                        if key.startswith(prefix + "in"))
        args = []
        for i in range(count):
            value = reference[f"{prefix}in{i}"].copy()
            args.append(value if value.ndim else value.item())
        result = getattr(core, name)(*args)
        for i, value in enumerate(args):
            if f"{prefix}out{i}" in reference:
                np.testing.assert_array_equal(value, reference[f"{prefix}out{i}"], err_msg=f"{prefix}out{i}")
        if f"{prefix}result" in reference:
            np.testing.assert_array_equal(np.array(result, dtype=float), reference[f"{prefix}result"],
                                          err_msg=f"{prefix}result")
