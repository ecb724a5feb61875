"""An independent check of the closed loop: the plant restated as a smoothed python-control model.

:func:`smoothed_plant` states the plant anew as a ``control.nlsys`` (tanh friction of width
``w``, first-order motor lag, drag, the controller's force); only its parameters come from the
toolkit's plant. :func:`cross_check` closes the same control law around it, commands held
between samples, each period integrated by ``control.input_output_response`` (scipy's LSODA),
and compares it with the toolkit's exact loop for a sequence of widths: the smoothed model
converges linearly in ``w``, so the differences shrink like ``w`` (observed order about 1).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ParameterError, ParameterTypeError, as_float, as_float_array, parameter_message
from ..model import Plant
from ..simulation import Budget, BudgetExceeded, Meter, SimulationStatus, refuse_backlash
from .closed_loop import LOOP_RATE, simulate_closed_loop

__all__ = ["CrossCheck", "cross_check", "smoothed_plant", "WIDTHS", "ORDER_BAND"]

#: Default friction widths of the smoothed model, m/s (largest first).
WIDTHS = (1e-2, 3e-3, 1e-3, 3e-4, 1e-4)
#: Band of the fitted order of convergence in which the check passes (the smoothed model
#: converges linearly in the width: order 1, approached from below as the width shrinks).
ORDER_BAND = (0.6, 1.4)
#: Integrator of each held period (``scipy.integrate.solve_ivp`` method) and its tolerances,
#: far below the smallest difference (m/s).
_METHOD, _RTOL, _ATOL = "LSODA", 1e-10, 1e-12


def smoothed_plant(plant: Plant, width: float) -> Any:
    """The plant as its own smoothed model, a continuous-time ``control.nlsys``.

    The model::

        m dV/dt  = sum_i f_i tanh((v_i - V) / w) + F - c V
        dv_i/dt  = (clip(u_i) - v_i) / tau          (v_i = clip(u_i) when tau = 0)

    Parameters
    ----------
    plant : Plant
        Gives ``f_i`` (N), ``m`` (kg), ``c`` (N s/m), ``tau`` (s) and the speed limits of
        ``clip`` (m/s); motors without a rate limit or compliance (refused: this model has
        neither).
    width : float, m/s
        ``w > 0``.

    Returns
    -------
    control.NonlinearIOSystem
        Inputs ``command[0..n-1]`` (m/s) and ``force`` (N); output ``speed`` (m/s); states
        ``V`` and, with a lag, ``v[0..n-1]`` (m/s).
    """
    import control   # python-control: loaded only by the cross-check

    owner = "smoothed_plant"
    _check_plant(plant, owner)
    w = as_float(width, "width", owner, low=0.0, low_open=True)
    forces, m, c = np.array(plant.contacts.forces, dtype=float), plant.mass, plant.damping
    n = forces.size
    motors = plant.motors
    tau = motors.lag if motors is not None else 0.0
    low, high = motors.speed_limits if motors is not None else (-math.inf, math.inf)

    def update(t: float, x: np.ndarray, u: np.ndarray, params: dict) -> np.ndarray:
        held = np.clip(u[:n], low, high)
        speeds = x[1:] if tau > 0 else held
        dV = (float(np.sum(forces * np.tanh((speeds - x[0]) / w))) + u[n] - c * x[0]) / m
        return np.concatenate(([dV], (held - speeds) / tau)) if tau > 0 else np.array([dV])

    def output(t: float, x: np.ndarray, u: np.ndarray, params: dict) -> np.ndarray:
        return x[:1]

    states = ["V"] + ([f"v[{i}]" for i in range(n)] if tau > 0 else [])
    return control.nlsys(update, output, inputs=[f"command[{i}]" for i in range(n)] + ["force"],
                         outputs=["speed"], states=states, name="smoothed_plant")


def _check_plant(plant: Any, owner: str) -> None:
    if not isinstance(plant, Plant):
        raise ParameterTypeError(parameter_message("plant", owner, "be a Plant", plant))
    refuse_backlash(plant, owner)
    motors = plant.motors
    if motors is not None and (math.isfinite(motors.rate_limit) or motors.compliance > 0):
        raise ParameterError(parameter_message(
            "plant", owner, "have motors without a rate limit or compliance (the smoothed model "
            "has a first-order lag only)",
            f"rate_limit = {motors.rate_limit:g} m/s^2, compliance = {motors.compliance:g} (m/s)/N"))


@dataclass(frozen=True, eq=False)
class CrossCheck:
    """The toolkit's exact closed loop against the smoothed model's, width by width.

    Attributes
    ----------
    widths : ndarray of shape (k,), m/s
        Friction widths ``w`` of the smoothed model, largest first.
    differences : ndarray of shape (k,), m/s
        Largest ``|V_smoothed - V_exact|`` over the samples, per width (the controller on
        each loop's own true speed).
    orders : ndarray of shape (k - 1,)
        Observed orders between neighbouring widths, ``ln(d_j / d_j+1) / ln(w_j / w_j+1)``.
    order : float
        Least-squares slope of ``ln d`` against ``ln w`` (NaN with fewer than two widths done).
    status : SimulationStatus
        ``SUCCESS``, or the budget that stopped the exact loop or the smoothed integrations
        (the widths done so far are kept).
    message : str
    samples : int
        Samples compared per width.
    wall_time : float, s
    """

    widths: np.ndarray
    differences: np.ndarray
    orders: np.ndarray
    order: float
    status: SimulationStatus
    message: str
    samples: int
    wall_time: float

    @property
    def converges(self) -> bool:
        """Every width done, no difference exactly 0, the differences shrinking with the width
        and the fitted order within ``ORDER_BAND``."""
        d = self.differences
        return (self.status is SimulationStatus.SUCCESS and d.size >= 2 and bool(np.all(d > 0))
                and bool(np.all(np.diff(d) < 0)) and ORDER_BAND[0] <= self.order <= ORDER_BAND[1])

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: the model, the widths and differences (m/s), the orders, the verdict."""
        return {"model": "tanh friction of width w, first-order motor lag, commands held "
                         f"between samples, {_METHOD} rtol {_RTOL:g} (python-control)",
                "compared": "largest |V_smoothed - V_exact| over the samples, m/s (controller "
                            "on each loop's true speed)",
                "widths": self.widths.tolist(), "max_speed_differences": self.differences.tolist(),
                "observed_orders": self.orders.tolist(), "fitted_order": self.order,
                "order_band": list(ORDER_BAND), "converges": self.converges,
                "status": self.status.name, "message": self.message, "samples": self.samples,
                "wall_time": self.wall_time}


def cross_check(plant: Plant, controller: Any, t_end: float, *, widths: Any = WIDTHS,
                rate: float | None = None, v0: float = 0.0,
                budget: Budget | None = None) -> CrossCheck:
    """Compare the toolkit's exact closed loop with the smoothed model's, for each width.

    Both loops sample at ``rate``, give the controller the true speed (the ideal loop: the
    sensor law and the estimator are not what is checked) and hold its commands and force
    over the period; the exact one is :func:`toolkit.simulate_closed_loop`, the other
    :func:`smoothed_plant` integrated period by period by python-control.

    Parameters
    ----------
    plant : Plant
        As :func:`smoothed_plant` accepts.
    controller : Controller
        E.g. :class:`~toolkit.controllers.SpeedHold`.
    t_end : float, s
    widths : array_like of shape (k,), m/s
        Distinct positive widths, largest first (default ``WIDTHS``).
    rate : float, Hz, optional
        Sample rate (default that of :func:`toolkit.simulate_closed_loop`).
    v0 : float, m/s
        Body speed at ``t = 0``.
    budget : Budget, optional
        Guards the exact loop's steps and every evaluation of the smoothed model (one meter
        over all widths).

    Returns
    -------
    CrossCheck
    """
    owner = "cross_check"
    _check_plant(plant, owner)
    w = as_float_array(widths, "widths", owner)
    if not (w.size >= 1 and np.all(w > 0) and np.all(np.diff(w) < 0)):
        raise ParameterError(parameter_message("widths", owner, "be positive and decreasing (m/s)",
                                               w.tolist()))
    rate = LOOP_RATE if rate is None else as_float(rate, "rate", owner, low=0.0, low_open=True)
    budget = Budget() if budget is None else budget
    if not isinstance(budget, Budget):
        raise ParameterTypeError(parameter_message("budget", owner, "be a Budget", budget))
    started = time.perf_counter()
    exact = simulate_closed_loop(plant, controller, t_end, rate=rate, v0=v0, budget=budget)
    times = exact.times
    meter = Meter(budget, counts="evaluations")
    differences: list[float] = []
    status, message = exact.status, exact.message
    if status is SimulationStatus.SUCCESS:
        try:
            for width in w.tolist():
                speed = _smoothed_loop(smoothed_plant(plant, width), plant, controller, times,
                                       rate, float(v0), meter)
                differences.append(float(np.max(np.abs(speed - exact.speed))))
            message = status.value
        except BudgetExceeded as stopped:
            status, message = stopped.status, (f"{stopped.status.value} ({stopped.detail}; "
                                               f"{len(differences)} of {w.size} widths done)")
    d = np.array(differences)
    done = w[:d.size]
    with np.errstate(divide="ignore", invalid="ignore"):
        orders = np.diff(np.log(d)) / np.diff(np.log(done))
        order = float(np.polyfit(np.log(done), np.log(d), 1)[0]) if d.size >= 2 and np.all(d > 0) else math.nan
    return CrossCheck(done, d, orders, order, status, message, int(times.size),
                      time.perf_counter() - started)


def _smoothed_loop(system: Any, plant: Plant, controller: Any, times: np.ndarray, rate: float,
                   v0: float, meter: Meter) -> np.ndarray:
    """The speed at each sample of the loop closed around ``system`` (commands and force held
    over each period), every right-hand-side evaluation counted by ``meter``."""
    import control   # python-control: loaded only by the cross-check

    law = controller.bind(plant, 1.0 / rate)
    z = law.initial_state()
    x = np.concatenate(([v0], plant.initial_speeds())) if system.nstates > 1 else np.array([v0])
    update = system.updfcn

    def metered(t: float, x: np.ndarray, u: np.ndarray, params: dict) -> np.ndarray:
        meter.evaluation()
        return update(t, x, u, params)

    held = control.nlsys(metered, system.outfcn, inputs=system.ninputs, outputs=system.noutputs,
                         states=system.nstates)
    speed = np.empty(times.size)
    for k, t in enumerate(times.tolist()):
        speed[k] = x[0]
        action = law.output(t, z, float(x[0]))
        z = law.update(t, z, float(x[0]))
        if k + 1 == times.size:
            break
        u = np.concatenate((action.commands, [float(action.force)]))
        response = control.input_output_response(
            held, [t, float(times[k + 1])], np.repeat(u[:, None], 2, axis=1), x,
            solve_ivp_method=_METHOD, solve_ivp_kwargs={"rtol": _RTOL, "atol": _ATOL})
        x = response.states[:, -1]
    return speed
