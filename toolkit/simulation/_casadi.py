"""Reference method: a casadi SUNDIALS integrator (CVODES or IDAS) on the smoothed model.

``simulate(plant, t_end, method="casadi", integrator="cvodes" | "idas", friction=..., ...)``.

The right-hand side is the plant's own :meth:`toolkit.model.Plant.rhs` evaluated over casadi
symbols (the friction laws ``"tanh"`` and ``"stribeck"`` of :mod:`toolkit.model.friction`; a
compliant motor's saturated linear law when the plant has compliance; the motor law of
:mod:`toolkit.model.motors`). ``"sign"`` is refused: SUNDIALS' error control assumes a smooth
right-hand side. The state is ``[V]`` or, with dynamic motors, ``[V, v_1, ..., v_n]``.

One ``casadi.integrator`` is built over the whole output grid (the requested times, or 201
uniform times when ``t_eval`` is None, plus every switching time of the commands and of the
external force). Commands and ``F_ext`` enter as the integrator's controls ``u``, which casadi
holds constant on each grid interval, so the integrator restarts exactly at every switch.

Budget, as far as casadi allows:

- ``budget.max_steps`` is passed as SUNDIALS' ``max_num_steps``, which bounds the steps **per
  output interval**, not per run; the total is checked after the call (status ``MAX_STEPS``
  if it is over budget or if SUNDIALS gave up with too much work).
- The wall clock cannot interrupt a running casadi call: it is checked after the call
  (status ``WALL_TIME`` if it overran; the trajectory is still returned).
- When SUNDIALS fails, casadi returns no partial trajectory: the result holds ``t = 0`` only.

``wall_time`` includes building the symbolic model and the integrator (as every call does).
"""

from __future__ import annotations

from typing import Any

import casadi as ca   # this module is loaded by casadi runs only (simulate imports it lazily)
import numpy as np

from .._validation import as_float, check_option
from ..model import Plant
from ._reference import (Meter, build_result, check_smoothing, external_forces, format_setting,
                         ideal_speeds)
from ._result import Budget, SimulationResult, SimulationStatus

__all__ = ["simulate_casadi", "CASADI_INTEGRATORS", "casadi_right_hand_side"]

#: Integrators accepted by ``integrator=``.
CASADI_INTEGRATORS = ("cvodes", "idas")

#: Output times used when ``t_eval`` is None.
_DEFAULT_SAMPLES = 201


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
    options = {"abstol": atol, "reltol": rtol, "max_num_steps": int(min(budget.max_steps, 2**31 - 1))}
    function = ca.integrator("contacts", integrator, {"x": x, "u": u, "ode": ode}, 0.0,
                             grid.tolist(), options)
    x0 = np.concatenate(([v0], plant.initial_speeds() if dynamic else []))
    status, detail = SimulationStatus.SUCCESS, ""
    try:
        solution = function(x0=x0, u=controls)
        states = np.array(solution["xf"]).reshape(x0.size, grid.size).T
        t_out = np.concatenate(([0.0], grid))
        y_out = np.vstack((x0, states))
    except RuntimeError as error:
        too_much = "TOO_MUCH_WORK" in str(error) or "too_much_work" in str(error).lower()
        status = SimulationStatus.MAX_STEPS if too_much else SimulationStatus.FAILED
        detail = f"{integrator}: {str(error).strip().splitlines()[-1][:200]}"
        t_out, y_out = np.zeros(1), x0[None, :]
    stats = function.stats()
    meter.steps = int(stats.get("nsteps", 0))
    meter.evaluations = int(stats.get("nfevals", 0))
    if status is SimulationStatus.SUCCESS:
        if meter.steps > budget.max_steps:
            status, detail = SimulationStatus.MAX_STEPS, (f"{meter.steps} steps used of max_steps = "
                                                f"{budget.max_steps} (checked after the call)")
        elif meter.elapsed() > budget.wall_time:
            status, detail = SimulationStatus.WALL_TIME, (f"{meter.elapsed():.3g} s used of wall_time = "
                                                f"{budget.wall_time:g} s (checked after the call)")
    if t_eval is not None and t_out.size > 1:            # a trajectory, complete or over budget
        keep = np.searchsorted(t_out, t_eval)            # every t_eval is on the grid
        t_out, y_out = t_out[keep], y_out[keep]
    return build_result(
        plant, method="casadi",
        setting=format_setting(integrator=integrator, friction=friction, eps=epsilon,
                               rtol=rtol, atol=atol),
        t=t_out, V=y_out[:, 0], contact_speeds=y_out[:, 1:] if dynamic else None, force=None,
        meter=meter, status=status, detail=detail, friction=friction, epsilon=epsilon)
