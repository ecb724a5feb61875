"""Compile the planar kernels ahead of timing: ``warm_up`` (benchmarks call it)."""

from __future__ import annotations

import time

import numpy as np

from .._compiled import load
from .contacts import PlanarContactSet

__all__ = ["warm_up"]


def warm_up() -> float:
    """Compile (or load from numba's cache) the kernels of :mod:`toolkit._compiled.planar` and
    run them once on tiny inputs through the public entry points; returns the time (s)."""
    started = time.perf_counter()
    load("planar")
    rng = np.random.default_rng(0)
    contacts = PlanarContactSet(rng.normal(size=(8, 2)), rng.normal(size=(8, 2)), np.ones(8))
    contacts.wrench(np.zeros((3, 2)), np.zeros(3))
    contacts.dissipation(np.zeros(2), 0.0)
    contacts.equilibrium(method="newton")
    contacts.equilibrium(translation_only=True, method="newton")
    return time.perf_counter() - started
