"""Reference method: a casadi SUNDIALS integrator (CVODES or IDAS) on the smoothed model.

``simulate(plant, t_end, method="casadi", integrator="cvodes" | "idas", friction=..., ...)``:
the plant's own right-hand side over casadi symbols (``"tanh"`` or ``"stribeck"`` friction,
compliant motors, the motor law; ``"sign"`` is refused), integrated over the requested times
plus every switching time. The output grid, tolerances and budgets: docs/physics.md, section 11.
"""

from __future__ import annotations

import math
from typing import Any

import casadi as ca   # this module is loaded by casadi runs only (simulate imports it lazily)
import numpy as np

from ..errors import as_float, check_option
from ..model import Plant
from ._reference import (Meter, build_result, check_smoothing, external_forces, format_setting,
                         ideal_speeds)
from ._result import Budget, SimulationResult, SimulationStatus

__all__ = ["simulate_casadi", "CASADI_INTEGRATORS", "casadi_right_hand_side"]

#: Integrators accepted by ``integrator=``.
CASADI_INTEGRATORS = ("cvodes", "idas")

#: Output times used when ``t_eval`` is None.
_DEFAULT_SAMPLES = 201
#: Output intervals of the first integrator call at most; each later call takes up to twice
#: as many (fewer when the wall-clock budget left would not cover them at the pace so far).
_FIRST_BLOCK = 64
#: Every call starts the integrator afresh (a few small steps): between switching times, a
#: call covers at least this many output intervals, so a grid without switches of up to this
#: many times (the 201 default ones, the precision report's ~1000) is one call, as unblocked.
_SMOOTH_BLOCK = 4096


def casadi_right_hand_side(plant: Plant, friction: str, epsilon: float) -> tuple[Any, Any, Any]:
    """The symbolic ODE of the smoothed plant: :meth:`Plant.rhs` built over casadi.

    Parameters
    ----------
    plant : Plant
    friction : {"tanh", "stribeck"}
    epsilon : float, m/s
        Smoothing width, ``> 0``.

    Returns
    -------
    x : casadi.SX of shape (d, 1)
        State ``[V]`` or ``[V, v_1..v_n]``, m/s.
    u : casadi.SX of shape (n + 1, 1)
        Controls: the commanded speeds (m/s) and ``F_ext`` (N).
    ode : casadi.SX of shape (d, 1)
        ``dx/dt``, m/s^2.
    """
    n = plant.n
    x = ca.SX.sym("x", 1 + (n if plant.dynamic_motors else 0))
    u = ca.SX.sym("u", n + 1)
    ode = plant.rhs(0.0, x, u[:n], external=u[n], friction=friction, epsilon=epsilon, xp=ca)
    return x, u, ode


def _output_grid(plant: Plant, t_end: float, t_eval: np.ndarray | None) -> np.ndarray:
    base = np.linspace(0.0, t_end, _DEFAULT_SAMPLES) if t_eval is None else t_eval
    switches = plant.switching_times()
    grid = np.unique(np.concatenate((base, switches[(switches > 0) & (switches < t_end)], [t_end])))
    return grid[grid > 0.0]


def _block_end(ends: np.ndarray, done: int, size: int, total: int) -> int:
    """The exclusive end (a grid index) of the block that starts after ``done`` output times.

    At the last switching time within ``size`` output intervals if there is one, else at the
    first one within ``_SMOOTH_BLOCK``, else ``max(size, _SMOOTH_BLOCK)`` intervals on.
    """
    k = int(np.searchsorted(ends, done + size, side="right")) - 1
    if k >= 0 and ends[k] > done:
        return int(ends[k])
    if k + 1 < ends.size and ends[k + 1] <= done + _SMOOTH_BLOCK:
        return int(ends[k + 1])
    return min(total, done + max(size, _SMOOTH_BLOCK))


def simulate_casadi(plant: Plant, t_end: float, *, v0: float, t_eval: np.ndarray | None,
                    budget: Budget, integrator: str = "cvodes", friction: str = "tanh",
                    epsilon: float = 1e-3, rtol: float = 1e-8,
                    atol: float = 1e-10) -> SimulationResult:
    """Integrate the smoothed plant with casadi's CVODES or IDAS.

    Parameters
    ----------
    plant, t_end, v0, budget
        As in :func:`toolkit.simulation.simulate` (checked there); the module docstring says
        what of ``budget`` casadi can enforce.
    t_eval : ndarray of shape (T,) or None, s
        Report times; ``None``: 201 uniform times (plus the switching times).
    integrator : {"cvodes", "idas"}
    friction : {"tanh", "stribeck"}
    epsilon : float, m/s
        Smoothing width, ``> 0``.
    rtol, atol : float
        SUNDIALS tolerances (``atol`` in m/s), ``> 0``.

    Returns
    -------
    SimulationResult
        ``n_steps`` and ``n_evaluations`` from the integrator's statistics.
    """
    owner = "simulate_casadi"
    check_option(integrator, "integrator", owner, CASADI_INTEGRATORS)
    epsilon = check_smoothing(friction, epsilon, owner, ("tanh", "stribeck"))
    rtol = as_float(rtol, "rtol", owner, low=0.0, low_open=True)
    atol = as_float(atol, "atol", owner, low=0.0, low_open=True)
    meter = Meter(budget, counts="steps")
    dynamic = plant.dynamic_motors
    x, u, ode = casadi_right_hand_side(plant, friction, epsilon)
    grid = _output_grid(plant, t_end, t_eval)
    starts = np.concatenate(([0.0], grid[:-1]))          # u is held on (starts[k], grid[k]]
    controls = np.vstack((ideal_speeds(plant, starts).T, external_forces(plant, starts)))
    x0 = np.concatenate(([v0], plant.initial_speeds() if dynamic else []))
    states = np.empty((grid.size, x0.size))              # the grid is the whole output
    switches = plant.switching_times()
    # a block may end right after these grid indices: the switching times, where the
    # controls jump and a restart of the integrator costs nothing it would not cost anyway
    ends = np.flatnonzero(np.isin(grid, switches)) + 1
    status, detail = SimulationStatus.SUCCESS, ""
    done, size, state = 0, _FIRST_BLOCK, x0
    while done < grid.size:
        remaining = budget.max_steps - meter.steps
        if remaining <= 0:
            status, detail = SimulationStatus.MAX_STEPS, (
                f"{meter.steps} steps used of max_steps = {budget.max_steps}")
            break
        block = slice(done, _block_end(ends, done, size, grid.size))
        options = {"abstol": atol, "reltol": rtol, "max_num_steps": int(min(remaining, 2**31 - 1))}
        function = ca.integrator("contacts", integrator, {"x": x, "u": u, "ode": ode},
                                 float(starts[done]), grid[block].tolist(), options)
        try:
            solution = function(x0=state, u=controls[:, block])
        except RuntimeError as error:
            too_much = "TOO_MUCH_WORK" in str(error) or "too_much_work" in str(error).lower()
            status = SimulationStatus.MAX_STEPS if too_much else SimulationStatus.FAILED
            detail = (f"{integrator}: {str(error).strip().splitlines()[-1][:200]} in "
                      f"({starts[done]:.6g}, {grid[block.stop - 1]:.6g}] s")
        stats = function.stats()
        meter.steps += int(stats.get("nsteps", 0))
        meter.evaluations += int(stats.get("nfevals", 0))
        if status is not SimulationStatus.SUCCESS:
            break
        states[block] = np.array(solution["xf"]).reshape(x0.size, block.stop - done).T
        state = states[block.stop - 1]
        done = block.stop
        if meter.steps > budget.max_steps:
            status, detail = SimulationStatus.MAX_STEPS, (
                f"{meter.steps} steps used of max_steps = {budget.max_steps} (checked after "
                f"the block ending at t = {grid[done - 1]:.6g} s)")
            break
        if meter.elapsed() > budget.wall_time:
            status, detail = SimulationStatus.WALL_TIME, (
                f"{meter.elapsed():.3g} s used of wall_time = {budget.wall_time:g} s (checked "
                f"after the block ending at t = {grid[done - 1]:.6g} s)")
            break
        # Next block: twice as many output times, but no more than the rest of the wall
        # budget allows at the time per output interval seen so far.
        per_interval = meter.elapsed() / done
        room = (budget.wall_time - meter.elapsed()) / max(per_interval, 1e-12)
        size = int(max(1, min(2 * size, room)))
    t_out = np.concatenate(([0.0], grid[:done]))
    y_out = np.vstack((x0, states[:done]))
    if t_eval is not None:                               # every t_eval is on the grid
        keep = t_eval <= t_out[-1]
        t_out, y_out = t_eval[keep], y_out[np.searchsorted(t_out, t_eval[keep])]
    elif t_out.size > budget.max_samples + 1:            # a grid of many switching times
        stride = 1 << math.ceil(math.log2((t_out.size - 1) / budget.max_samples))
        index = np.arange(0, t_out.size, stride)
        if index[-1] != t_out.size - 1:
            index = np.append(index, t_out.size - 1)
        note = (f"output decimated to every {stride}th of {t_out.size} grid times "
                f"(max_samples = {budget.max_samples})")
        detail = f"{detail}; {note}" if detail else note
        t_out, y_out = t_out[index], y_out[index]
    return build_result(
        plant, method="casadi",
        setting=format_setting(integrator=integrator, friction=friction, eps=epsilon,
                               rtol=rtol, atol=atol),
        t=t_out, V=y_out[:, 0], contact_speeds=y_out[:, 1:] if dynamic else None, force=None,
        meter=meter, status=status, detail=detail, friction=friction, epsilon=epsilon)
