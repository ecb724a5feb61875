"""Reference method: scipy's adaptive ODE solvers on the Coulomb or a smoothed friction law.

``simulate(plant, t_end, method="rk45" | "lsoda" | "radau" | "bdf", friction=..., ...)``: the
state ``[V]`` (ideal motors) or ``[V, v_1, ..., v_n]`` (dynamic motors) under the plant's own
right-hand side with the friction law of :mod:`toolkit.model.friction`, integrated piece by
piece between switches. The laws, tolerances and budgets: docs/physics.md, section 11.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.integrate

from ..errors import as_float, check_option
from ..model import Plant
from ._reference import (BudgetExceeded, Meter, StepRecord, build_result, check_smoothing,
                         format_setting, segment_edges)
from ._result import Budget, SimulationResult, SimulationStatus

__all__ = ["simulate_scipy", "SCIPY_SOLVERS"]

#: Method name -> scipy solver class name.
SCIPY_SOLVERS = {"rk45": "RK45", "lsoda": "LSODA", "radau": "Radau", "bdf": "BDF"}


def _right_hand_side(plant: Plant, t0: float, friction: str, epsilon: float,
                     meter: Meter) -> Any:
    """The ODE right-hand side on a segment starting at ``t0`` (commands and F_ext frozen):
    :meth:`Plant.rhs` with the segment's commands and external force, metered."""
    # Within a segment nothing depends on t except through the (constant) commands and F_ext,
    # so every evaluation uses t0's values: the solver may probe the segment's right end,
    # where PiecewiseConstant already holds the next value.
    # A non-finite value stops the run (status FAILED): no solver recovers from it, and some
    # (LSODA) would otherwise retry until the wall-clock budget is spent.
    command, external = plant.command(t0), plant.external(t0)

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        meter.evaluation()
        out = plant.rhs(t0, y, command, external=external, friction=friction, epsilon=epsilon)
        if not np.all(np.isfinite(out)):
            raise BudgetExceeded(SimulationStatus.FAILED, _non_finite(t, y))
        return out
    return rhs


def _non_finite(t: float, y: np.ndarray) -> str:
    return f"the right-hand side became non-finite at t = {t:.6g} s (V = {y[0]:.3g} m/s)"


def simulate_scipy(plant: Plant, t_end: float, *, v0: float, t_eval: np.ndarray | None,
                   budget: Budget, solver: str, friction: str = "sign", epsilon: float = 1e-3,
                   rtol: float = 1e-6, atol: float = 1e-9) -> SimulationResult:
    """Integrate the plant with one of scipy's ``solve_ivp`` solvers.

    Parameters
    ----------
    plant, t_end, v0, budget
        As in :func:`toolkit.simulation.simulate` (checked there); ``budget.max_steps``
        counts right-hand-side evaluations (finite-difference Jacobian evaluations included).
    t_eval : ndarray of shape (T,) or None, s
        Report times, evaluated with the solver's own dense output on the step that
        contains each time (nothing else is stored per step); ``None``: every accepted step,
        up to ``budget.max_samples``, then a decimated record (said in the message). A run
        stopped by a budget reports only the times it reached.
    solver : {"rk45", "lsoda", "radau", "bdf"}
    friction : {"sign", "tanh", "stribeck"}
    epsilon : float, m/s
        Smoothing width of ``tanh``/``stribeck`` (ignored for ``sign``), ``> 0``.
    rtol, atol : float
        Solver tolerances (``atol`` in m/s), ``> 0``.

    Returns
    -------
    SimulationResult
        ``n_steps`` accepted steps, ``n_evaluations`` right-hand-side calls, no events.
    """
    owner = "simulate_scipy"
    check_option(solver, "solver", owner, tuple(SCIPY_SOLVERS))
    epsilon = check_smoothing(friction, epsilon, owner)
    rtol = as_float(rtol, "rtol", owner, low=0.0, low_open=True)
    atol = as_float(atol, "atol", owner, low=0.0, low_open=True)
    solver_class = getattr(scipy.integrate, SCIPY_SOLVERS[solver])
    setting = format_setting(friction=friction,
                             eps=epsilon if friction != "sign" else None, rtol=rtol, atol=atol)
    dynamic = plant.dynamic_motors
    meter = Meter(budget, counts="evaluations")
    y = np.concatenate(([v0], plant.initial_speeds() if dynamic else []))
    # Memory bounded whatever the number of steps: the requested times only (filled as the
    # steps pass them), or a record of at most budget.max_samples steps.
    record = StepRecord(0.0, y, budget.max_samples) if t_eval is None else None
    samples = None if t_eval is None else _Samples(t_eval, y)
    status, detail = SimulationStatus.SUCCESS, ""
    edges = segment_edges(plant, t_end)
    try:
        for t0, t1 in zip(edges[:-1], edges[1:]):
            rhs = _right_hand_side(plant, float(t0), friction, epsilon, meter)
            stepper = _solver_call(solver, solver_class, rhs, float(t0), y, float(t1),
                                   rtol=rtol, atol=atol)
            while stepper.status == "running":
                message = _solver_call(solver, stepper.step)
                if stepper.status == "failed":
                    raise BudgetExceeded(SimulationStatus.FAILED, f"{SCIPY_SOLVERS[solver]}: {message}")
                if not np.all(np.isfinite(stepper.y)):   # the state overflowed (LSODA does not stop)
                    raise BudgetExceeded(SimulationStatus.FAILED, f"{SCIPY_SOLVERS[solver]}: the state is not "
                                         f"finite at t = {stepper.t:g} s")
                meter.step()
                if samples is not None:
                    samples.take(stepper)
                else:
                    record.add(stepper.t, stepper.y.copy())
                meter.check_clock()
            y = stepper.y.copy()
    except BudgetExceeded as stop:
        status, detail = stop.status, stop.detail
    if record is not None:
        t_out, y_out = record.arrays()
        detail = "; ".join(part for part in (detail, record.note()) if part)
    else:
        t_out, y_out = samples.arrays()
    return build_result(
        plant, method=solver, setting=setting, t=t_out, V=y_out[:, 0],
        contact_speeds=y_out[:, 1:] if dynamic else None, force=None, meter=meter,
        status=status, detail=detail, friction=friction, epsilon=epsilon)


class _Samples:
    """The requested times of a run, filled from each step's dense output as the steps pass
    them (preallocated: memory is that of the request, not of the steps)."""

    def __init__(self, t_eval: np.ndarray, y0: np.ndarray) -> None:
        self.t_eval = t_eval
        self.y = np.empty((t_eval.size, y0.size))
        k = int(np.searchsorted(t_eval, 0.0, side="right"))   # requests at t = 0: y0 exactly
        self.y[:k] = y0
        self.k = k
        self.next_t = float(t_eval[k]) if k < t_eval.size else np.inf

    def take(self, stepper: Any) -> None:
        """Evaluate the solver's dense output on its last step at the requested times inside it."""
        if self.next_t > stepper.t:
            return
        j = int(np.searchsorted(self.t_eval, stepper.t, side="right"))
        values = stepper.dense_output()(self.t_eval[self.k:j])
        self.y[self.k:j] = np.atleast_2d(values.T).reshape(j - self.k, -1)
        self.k = j
        self.next_t = float(self.t_eval[j]) if j < self.t_eval.size else np.inf

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """``(t, y)`` at the requested times reached so far."""
        return self.t_eval[:self.k], self.y[:self.k]


def _solver_call(solver: str, function: Any, *args: Any, **kwargs: Any) -> Any:
    """Call into the scipy solver; its numerical failures become status ``FAILED``.

    Overflowing states make scipy raise ``ValueError`` ("array must not contain infs or
    NaNs"), a singular iteration matrix ``LinAlgError``; both (and ``ArithmeticError``) end
    the run with their message instead of escaping ``simulate``. Floating-point warnings are
    silenced: a non-finite value is caught by the right-hand side or by the result.
    """
    try:
        with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
            return function(*args, **kwargs)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as error:
        raise BudgetExceeded(SimulationStatus.FAILED, f"{SCIPY_SOLVERS[solver]}: {error}") from error
