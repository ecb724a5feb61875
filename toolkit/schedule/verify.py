"""Verification of a schedule, never trusting a solver.

The commands are integrated on the smoothed law at tight tolerance (the prediction);
:func:`deviation_bound` proves how far every solution of the exact inclusion can be from it
(a monotonicity argument, bounded on enclosures between dense samples), and the exact
event-driven simulator runs the schedule as a second method that must stay within that
bound. The argument: docs/methods.md."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Callable

import numpy as np

from ..model import PiecewiseConstant, Plant
from ..model.friction import contact_forces
from ..simulation import simulate
from .commands import _Motor, _project
from .construct import speed_rate

__all__ = ["deviation_bound"]

#: Widths ``delta`` (units of ``epsilon``) tried by :func:`deviation_bound`.
_DELTAS = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0)
#: Intervals per piece (a period, or part of one) of the prediction's dense output.
_INTERVALS = 64
#: CVODES tolerances of the prediction.
_RTOL, _ATOL = 1e-10, 1e-13
#: Safety factor on CVODES's local error estimates in the integration allowance.
_LOCAL_SAFETY = 10.0


def deviation_bound(times: Any, body_speed: Any, contact_speeds: Any, forces: Any, mass: float,
                    epsilon: float, *, damping: float = 0.0, external: Any = 0.0,
                    allowance: float = 0.0) -> tuple[float, np.ndarray]:
    """Bound the distance between a smoothed-model trajectory and the exact Coulomb model.

    Let ``V_s`` solve ``m V' = sum f_i tanh((v_i - V)/eps) + F_ext - c V`` and ``V_e`` any
    solution of the inclusion ``m V' in sum f_i Sign(v_i - V) + F_ext - c V`` with the same
    contact speeds, external force and ``V_e(0) = V_s(0)``. The exact force is non-increasing
    in ``V``, so while ``V_e > V_s + delta`` its value is at most the lower end
    ``F_lo(V_s + delta)`` of the set at ``V_s + delta``, and

        m d|e|/dt <= d_delta = max(0, F_lo(V_s + delta) - F_s(V_s), F_s(V_s) - F_hi(V_s - delta))

    (drag only helps). Hence ``|e(t)| <= delta + (1/m) int_0^t d_delta`` for every delta.

    The integral is bounded rigorously, not estimated: on each interval between two samples
    every contact speed lies between its two end values (each is monotone there: samples
    come in pieces on which the motor law is one exponential or one ramp, so a switching
    time appears twice and the interval between the copies has length 0), and ``V_s`` lies
    in the enclosure ``(V_a + V_b)/2 +- A h/2`` of a function with ``|V_s'| <= A`` (and
    between ``min(V_a, V_b) - A h`` and ``max(V_a, V_b) + A h``), widened by
    ``allowance``; ``d_delta`` is bounded there by its interval extension (``tanh`` and the
    sign patterns are monotone) and multiplied by ``h``. ``A`` is
    ``speed_rate`` of ``F_tot + |F_ext|`` from the larger
    end speed plus ``allowance`` (drag included). Floating-point rounding of the sums is not
    accounted for (relative 1e-15).

    Parameters
    ----------
    times : array_like of shape (T,), s
        Samples of the trajectory, non-decreasing, in pieces as described above.
    body_speed : array_like of shape (T,), m/s
        ``V_s`` at ``times``, each within ``allowance`` of the true smoothed solution.
    contact_speeds : array_like of shape (T, n), m/s
    forces : array_like of shape (n,), N
    mass : float, kg
    epsilon : float, m/s
    damping : float, N s/m
    external : float or array_like of shape (T - 1,), N
        External force on each interval (constant there).
    allowance : float, m/s
        Bound on ``|body_speed - V_s|`` (the predictor's integration error); added to the
        result too, so the bound holds for the distance to ``body_speed``.

    Returns
    -------
    bound : float, m/s
        ``allowance + min over delta of (delta + int_0^T d_delta / m)``: valid on the whole
        interval ``[times[0], times[-1]]``.
    pointwise : ndarray of shape (T,), m/s
        ``allowance + min over delta of (delta + int_0^t d_delta / m)`` at each sample:
        valid on ``[times[0], t]``.
    """
    t = np.asarray(times, dtype=float)
    V = np.asarray(body_speed, dtype=float)
    v = np.asarray(contact_speeds, dtype=float)
    f = np.asarray(forces, dtype=float)
    h = np.diff(t)
    push = float(np.sum(np.abs(f))) + np.abs(np.broadcast_to(
        np.asarray(external, dtype=float), h.shape))
    A = speed_rate(push, damping, np.maximum(np.abs(V[:-1]), np.abs(V[1:])) + allowance, mass,
                   h)
    V_a, V_b = V[:-1], V[1:]
    low = np.maximum(0.5 * (V_a + V_b - A * h), np.minimum(V_a, V_b) - A * h) - allowance
    high = np.minimum(0.5 * (V_a + V_b + A * h), np.maximum(V_a, V_b) + A * h) + allowance
    v_min, v_max = np.minimum(v[:-1], v[1:]), np.maximum(v[:-1], v[1:])
    # F_s is decreasing in V and increasing in v_i: its extremes are at the interval ends.
    smooth_min = np.sum(contact_forces(v_min - high[:, None], f, law="tanh", epsilon=epsilon,
                                       owner="deviation_bound"), axis=-1)
    smooth_max = np.sum(contact_forces(v_max - low[:, None], f, law="tanh", epsilon=epsilon,
                                       owner="deviation_bound"), axis=-1)
    best = np.full(t.size, np.inf)
    total = np.inf
    for ratio in _DELTAS:
        delta = ratio * epsilon
        f_lo = np.where(v_max > low[:, None] + delta, 1.0, -1.0) @ f   # sup of F_lo(V_s + delta)
        f_hi = np.where(v_min >= high[:, None] - delta, 1.0, -1.0) @ f  # inf of F_hi(V_s - delta)
        defect = np.maximum(0.0, np.maximum(f_lo - smooth_min, smooth_max - f_hi)) / mass
        growth = np.concatenate(([0.0], np.cumsum(defect * h)))
        best = np.minimum(best, delta + growth)
        total = min(total, delta + float(growth[-1]))
    return total + allowance, best + allowance


def _smoothed_rate(ca: Any, plant: Plant, contact_speeds: Any, V: Any, F_ext: Any,
                   epsilon: float) -> Any:
    """``dV/dt`` (m/s^2) of the smoothed model as a casadi expression:
    ``(sum_i contact_forces(v_i - V, law="tanh") + F_ext - c V) / m``.

    Parameters
    ----------
    ca : module
        casadi.
    plant : Plant
        Friction magnitudes (N), mass (kg) and damping (N s/m).
    contact_speeds : casadi expression of shape (n, 1), m/s
    V, F_ext : casadi expressions
        Body speed (m/s) and external force (N).
    epsilon : float, m/s
        Smoothing width.
    """
    forces = contact_forces(contact_speeds - V, plant.contacts.forces, law="tanh",
                            epsilon=epsilon, xp=ca, owner="design_schedule")
    return (ca.sum1(forces) + F_ext - plant.damping * V) / plant.mass


def _make_predictor(ca: Any, plant: Plant, motor: _Motor, epsilon: float) -> Any:
    """CVODES (BDF, rtol 1e-10) over one piece ``[a, b]`` of a period on the smoothed model.

    Returns a casadi integrator with state ``V``, parameters ``(v_start (n), u (n), F_ext,
    a, b)`` and outputs at ``_INTERVALS`` equally spaced times of the piece after ``a``.
    """
    n = plant.n
    V, x = ca.SX.sym("V"), ca.SX.sym("x")                # x in [0, 1] along the piece
    v, u = ca.SX.sym("v", n), ca.SX.sym("u", n)
    F_ext, a, b = ca.SX.sym("F"), ca.SX.sym("a"), ca.SX.sym("b")
    s = a + (b - a) * x
    rate = _smoothed_rate(ca, plant, motor.symbolic(ca, v, u, s), V, F_ext, epsilon)
    dae = {"x": V, "p": ca.vertcat(v, u, F_ext, a, b), "t": x, "ode": (b - a) * rate}
    grid = np.linspace(0.0, 1.0, _INTERVALS + 1)
    return ca.integrator("prediction", "cvodes", dae, 0.0, grid[1:],
                         {"reltol": _RTOL, "abstol": _ATOL, "max_num_steps": 100000}), grid


def _predict(predictor: Any, plant: Plant, motor: _Motor, U: np.ndarray, speeds: np.ndarray,
             v0: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """Integrate the smoothed model at tight tolerance: dense times, V, contact speeds.

    Returns
    -------
    t : ndarray of shape (T,), s
        Non-decreasing: ``_INTERVALS + 1`` samples per piece (a period, split at rate
        kinks and external-force switches), both ends included.
    V : ndarray of shape (T,), m/s
    v : ndarray of shape (T, n), m/s
    ext : ndarray of shape (T,), N
        External force of each sample's piece.
    allowance : float, m/s
        Bound on the integration error of ``V``: CVODES keeps its estimate of each step's
        local error within ``rtol |V| + atol``, and the smoothed law is dissipative (its
        right side decreases in ``V``), so local errors add up without amplification; the
        allowance is ``_LOCAL_SAFETY`` (10, for the estimate being an estimate) times the
        number of steps times ``rtol max |V| + atol``.
    """
    integrator, grid = predictor
    dt = motor.period
    K = U.shape[0]
    all_t, all_V, all_v, all_ext = [], [], [], []
    steps = 0
    V = v0
    for k in range(K):
        start, u = speeds[k], U[k]
        t0 = k * dt
        cuts = [0.0, *motor.kinks(start, u),
                *(plant.external_force.breakpoints_in(t0, t0 + dt) - t0
                  if isinstance(plant.external_force, PiecewiseConstant) else []), dt]
        cuts = np.unique(np.clip(cuts, 0.0, dt))
        for a, b in zip(cuts[:-1], cuts[1:]):
            ext = plant.external(t0 + 0.5 * (a + b))
            out = integrator(x0=V, p=np.concatenate((start, u, [ext, a, b])))
            steps += int(integrator.stats().get("nsteps", 100000))
            path = np.concatenate(([V], np.asarray(out["xf"]).ravel()))
            offsets = a + (b - a) * grid
            # Both ends of every piece, with the piece's own contact speeds: a switching
            # time appears twice, so the certificate integrates each piece on its own law.
            all_t.append(t0 + offsets)
            all_V.append(path)
            all_v.append(motor.speeds(start, u, offsets))
            all_ext.append(np.full(grid.size, ext))
            V = float(path[-1])
    t = np.maximum.accumulate(np.minimum(np.concatenate(all_t), K * dt))   # rounding of t0 + b
    V_all = np.concatenate(all_V)
    allowance = _LOCAL_SAFETY * steps * (_RTOL * float(np.max(np.abs(V_all))) + _ATOL)
    return t, V_all, np.concatenate(all_v), np.concatenate(all_ext), allowance


@dataclass(frozen=True, eq=False)
class _Verified:
    """A candidate schedule, predicted on the smoothed model and simulated exactly (private)."""

    commands: np.ndarray
    contact_speeds: np.ndarray
    t_dense: np.ndarray
    V_dense: np.ndarray
    bound: float
    tracking: float
    objective: float
    body: np.ndarray
    exact_body: np.ndarray
    exact_V: np.ndarray
    exact_tracking: float
    deviation: float
    exact_finished: bool
    exact_message: str

    @property
    def verified(self) -> bool:
        return self.exact_finished and self.deviation <= self.bound


def _verifier(ca: Any, plant: Plant, motor: _Motor, *, start: np.ndarray, v0: float,
              lo: float, hi: float, pin_first: bool, ref_fn: Any, times: np.ndarray,
              smoothness: float, epsilon: float) -> Callable[..., _Verified]:
    """``verify(raw, width=epsilon) -> _Verified``: project raw commands (K, n) onto the motor
    model, predict them on the law smoothed at ``width`` (m/s), bound the exact model around
    the prediction, evaluate the objective and simulate the schedule exactly.

    ``ca`` is the casadi module; ``times`` (K + 1,) the period starts (s); ``ref_fn`` the
    reference ``V_ref(t)`` (m/s). Predictors are built once per width and reused.
    """
    forces = plant.contacts.forces
    K, period, n = times.size - 1, motor.period, plant.n
    scale = max(abs(lo), abs(hi))
    predictors: dict[float, Any] = {}

    def verify(raw: np.ndarray, width: float = epsilon) -> _Verified:
        if width not in predictors:
            predictors[width] = _make_predictor(ca, plant, motor, width)
        commands, contact = _project(raw, start, motor, lo, hi, pin_first)
        t_d, V_d, v_d, ext_d, allowance = _predict(predictors[width], plant, motor, commands,
                                                   contact, v0)
        ext_h = np.maximum(np.abs(ext_d[:-1]), np.abs(ext_d[1:]))
        bound, _ = deviation_bound(t_d, V_d, v_d, forces, plant.mass, width,
                                   damping=plant.damping, external=ext_h, allowance=allowance)
        ref_d = np.asarray(ref_fn(t_d), dtype=float)
        miss = V_d - ref_d
        moves = np.diff(np.vstack((start, commands)), axis=0)
        value = float(np.sum(0.5 * (miss[1:] ** 2 + miss[:-1] ** 2) * np.diff(t_d))
                      / (K * period * scale ** 2)
                      + smoothness * np.sum(moves ** 2) / (n * K * scale ** 2))
        at_times = np.searchsorted(t_d, times - 1e-12 * period)
        body = V_d[at_times]
        table = PiecewiseConstant(times[1:], np.vstack((commands, commands[-1])))
        try:
            exact = simulate(replace(plant, commands=table), float(times[-1]), v0=v0,
                             t_eval=t_d)
        except (ArithmeticError, ValueError, RuntimeError) as error:   # a simulator defect
            exact, finished = None, False
            report = f"the exact simulator raised {type(error).__name__}: {error}"
        else:
            finished = exact.success and exact.V.size == t_d.size
            report = exact.message
        exact_V = exact.V if finished else np.full(t_d.size, np.nan)
        # A second method: the closed-form exact solution against the prediction at the
        # dense samples (the bound itself holds over the whole run, by proof).
        deviation = float(np.max(np.abs(exact_V - V_d))) if finished else math.inf
        exact_tracking = float(np.max(np.abs(exact_V - ref_d))) if finished else math.inf
        return _Verified(commands, contact, t_d, V_d, bound, float(np.max(np.abs(miss))),
                         value, body, exact_V[at_times], exact_V, exact_tracking, deviation,
                         finished, report)

    return verify
