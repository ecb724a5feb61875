"""Compile the kernels ahead of timing: ``warm_up`` (benchmarks and the tests call it; the
policy is :mod:`toolkit._compiled`'s).

It lives with the simulation, not in :mod:`toolkit._compiled`, because it exercises the
kernels through the simulation's and the contact model's own entry points: the compiled
package stays below both and imports neither.
"""

from __future__ import annotations

import time

import numpy as np

from .._compiled import load
from ..model import ContactSet, Motors, PiecewiseConstant, Plant
from ._batch import simulate_batch
from ._sampled import SampledLaw, SampledRun
from ._stepper import ExactState, advance

__all__ = ["warm_up"]


def warm_up() -> float:
    """Compile (or load from the cache) the kernels the exact method (ideal and lagging
    motors), ``advance``, the sampled loops, the batch path and :meth:`ContactSet.force` run,
    on tiny inputs of the usual array kinds; returns the time it took (s). Benchmarks and the
    tests call it before timing anything."""
    from . import simulate as _simulate   # the package's entry point (it imports this module)

    started = time.perf_counter()
    load("core")
    contacts = ContactSet([-0.2, 0.1, 0.3], [1.0, 2.0, 1.0])
    contacts.force(np.linspace(-1.0, 1.0, 64))
    contacts.force(0.0)
    for plant in (Plant(contacts, 1.0), Plant(contacts, 1.0, damping=0.5, external_force=0.5),
                  Plant(contacts, 1.0, motors=Motors(compliance=0.01))):
        result = _simulate(plant, 1.0)
        _simulate(plant, 1.0, t_eval=np.linspace(0.0, 1.0, 5))
        fixed = np.linspace(0.0, 1.0, 5)
        fixed.setflags(write=False)                # read-only times (no copy): their own kernel
        _simulate(plant, 1.0, t_eval=fixed)
        result.speed_at(np.array([0.5, 0.25]))
    lagged = Plant(contacts, 1.0, motors=Motors(lag=0.01))
    state = ExactState.initial(lagged)
    for k in range(4):
        command = np.array([-0.2, 0.1, 0.3 - 0.01 * k])
        command.setflags(write=k % 2 == 0)      # the caller's command, writable or not
        state = advance(lagged, state, command, 0.02 * (k + 1)).state
    schedule = PiecewiseConstant([0.5], [[-0.2, 0.1, 0.3], [0.2, -0.1, 0.0]])
    for motors in (Motors(lag=0.01, rate_limit=2.0), Motors(lag=0.01, compliance=0.05)):
        _simulate(Plant(contacts, 1.0, motors=motors, commands=schedule), 1.0)
    times = np.arange(4) * 0.02
    for plant in (lagged, Plant(contacts, 1.0)):
        SampledRun(plant, times, law=SampledLaw(np.array([[0.1, 0.2, 0.3]]))).run_to(4)
    simulate_batch(np.array([[0.1, -0.1, 0.2]]), None, 1.0, 1.0)
    simulate_batch(np.array([[0.1, -0.1, 0.2]]), None, 1.0, 1.0, t_probe=0.5)
    simulate_batch(np.array([[0.1, -0.1, 0.2]]), np.ones((1, 3)), np.ones(1), 1.0,
                   damping=np.zeros(1), external=np.zeros(1), v0=np.zeros(1))
    return time.perf_counter() - started
