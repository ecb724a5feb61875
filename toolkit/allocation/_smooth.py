"""Smooth allocation variants solved with casadi (ipopt): compliant contacts and patches.

Two models whose force-speed law is continuous, so that a gradient method applies:

- **Compliant contacts** (a motor torque-speed line of slope ``k``, (m/s)/N): contact ``i``
  pushes with the saturated linear law ``f_i clip((v_i - V) / (k f_i), -1, 1)``. Each
  contact is a ramp of slope ``-1/k`` and width ``2 k f_i`` centred on ``v_i``.
- **A continuous patch** (:class:`~toolkit.contacts.ContactDistribution`): a uniform density
  of contact speed on ``[a, b]`` gives ``F(V) = F_tot (1 - 2 clip((V - a)/(b - a), 0, 1))``;
  the optimizer chooses ``a`` and ``b``.

Both laws are piecewise linear in ``V`` but not differentiable in the decision variables at
the saturation corners, so the optimizer works on a smooth surrogate of ``clip``,
``0.5 (sqrt((x + 1)^2 + d^2) - sqrt((x - 1)^2 + d^2))`` (``d -> 0`` by continuation), and
minimizes the squared error over dense samples of the target's band. The reported errors are
then computed *exactly* on the true piecewise-linear law: the difference of two piecewise
linear functions attains its sup at a breakpoint and its L1 norm is a sum of exact pieces.

Without a Coulomb-free closed form there is no certified lower bound in general: ``bound`` is
0 and ``gap = error_sup``, and the status says the result is uncertified.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..contacts import ContactDistribution, ContactSet
from ..errors import ParameterError, parameter_message
from ._evaluate import abs_integral
from ._problem import AllocationProblem, AllocationResult, AllocationStatus
from .targets import ForceCurve

__all__ = ["allocate_smooth", "compliant_force", "patch_force", "piecewise_linear_errors"]

_SAMPLES = 201
_SMOOTHING = (1e-1, 1e-2, 1e-3, 1e-4, 1e-6)     # corner widths d of the soft clip (continuation)
_UNCERTIFIED = ("no certified lower bound for this smooth model (bound = 0, gap = error); "
                "errors evaluated exactly on the piecewise-linear law")


def compliant_force(V: Any, speeds: Any, forces: Any, compliance: float) -> np.ndarray:
    """Net force of compliant contacts, ``sum f_i clip((v_i - V) / (k f_i), -1, 1)``.

    Parameters
    ----------
    V : array_like of shape (m,), m/s
    speeds, forces : array_like of shape (n,), m/s and N
    compliance : float, (m/s)/N, ``> 0``

    Returns
    -------
    ndarray of shape (m,), N
    """
    V = np.asarray(V, dtype=float)[:, None]
    f = np.asarray(forces, dtype=float)
    scale = np.where(f > 0, compliance * f, 1.0)
    ratio = np.clip((np.asarray(speeds, dtype=float) - V) / scale, -1.0, 1.0)
    return np.where(f > 0, f * ratio, 0.0).sum(axis=1)


def patch_force(V: Any, low: float, high: float, total_force: float) -> np.ndarray:
    """Net force of a uniform patch on ``[low, high]``, ``F_tot (1 - 2 clip((V - a)/(b - a)))``, N."""
    share = np.clip((np.asarray(V, dtype=float) - low) / (high - low), 0.0, 1.0)
    return total_force * (1.0 - 2.0 * share)


def piecewise_linear_errors(curve: ForceCurve, force: Any, breakpoints: Any
                            ) -> tuple[float, float]:
    """Exact sup and L1 errors between a continuous piecewise-linear force and a target curve.

    Parameters
    ----------
    curve : ForceCurve
        Linear between samples; a repeated speed is a vertical step.
    force : callable
        ``force(V) -> ndarray``: continuous and linear between ``breakpoints``.
    breakpoints : array_like, m/s
        Every kink of ``force`` (those outside the band are ignored).

    Returns
    -------
    error_sup : float, N
        ``sup |force - target|`` over the band (one-sided limits at the target's steps).
    error_l1 : float, N m/s
        Exact integral of ``|force - target|`` over the band, or with the curve's weights
        ``sum_k w_k |force(V_k) - F_k|``.
    """
    lo, hi = curve.band
    points = np.concatenate((curve.speeds, np.asarray(breakpoints, dtype=float)))
    points = np.unique(np.clip(points, lo, hi))
    achieved = np.asarray(force(points), dtype=float)
    left = achieved - curve.value_left(points)
    right = achieved - curve.value_right(points)
    error_sup = float(np.max(np.maximum(np.abs(left), np.abs(right))))
    if curve.weights is not None:
        error_l1 = float(np.sum(curve.weights * np.abs(np.asarray(force(curve.speeds))
                                                      - curve.forces)))
    elif points.size > 1:
        error_l1 = float(np.sum(abs_integral(right[:-1], left[1:], np.diff(points))))
    else:
        error_l1 = 0.0
    return error_sup, error_l1


def _soft_clip(ca: Any, x: Any, d: Any) -> Any:
    return 0.5 * (ca.sqrt((x + 1) ** 2 + d ** 2) - ca.sqrt((x - 1) ** 2 + d ** 2))


def _samples(curve: ForceCurve) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = curve.band
    V = np.unique(np.concatenate((np.linspace(lo, hi, _SAMPLES), curve.speeds)))
    target = 0.5 * (curve.value_left(V) + curve.value_right(V))
    return V, target


def _quantile_guess(curve: ForceCurve, total: float, n: int) -> np.ndarray:
    """Speeds at the target's quantiles ``(i - 1/2)/n`` of ``(1 - F/F_tot)/2``."""
    V, target = _samples(curve)
    level = np.clip((1.0 - target / total) / 2.0, 0.0, 1.0)
    level = np.maximum.accumulate(level)               # the projected curve is non-increasing
    q = (np.arange(n) + 0.5) / n
    if level[-1] - level[0] <= 0:
        return np.full(n, 0.5 * (V[0] + V[-1]))
    return np.interp(q, level, V)


def _solve(ca: Any, build: Any, x0: np.ndarray, lower: np.ndarray, upper: np.ndarray,
           time_limit: float) -> tuple[np.ndarray, str, int]:
    """Minimize ``build(x, d)`` over the box by continuation in ``d``; return x, status, iters."""
    opti = ca.Opti()
    x = opti.variable(x0.size)
    d = opti.parameter()
    objective, extra = build(x, d)
    opti.minimize(objective)
    finite_lo, finite_hi = np.isfinite(lower), np.isfinite(upper)
    for i in range(x0.size):
        if finite_lo[i] and finite_hi[i] and lower[i] == upper[i]:
            opti.subject_to(x[i] == lower[i])
            continue
        if finite_lo[i]:
            opti.subject_to(x[i] >= lower[i])
        if finite_hi[i]:
            opti.subject_to(x[i] <= upper[i])
    for constraint in extra:
        opti.subject_to(constraint)
    opti.set_initial(x, x0)
    value, status, iterations = x0, "Not_Run", 0
    start = time.perf_counter()
    for width in _SMOOTHING:
        remaining = time_limit - (time.perf_counter() - start)
        if remaining <= 0:
            status = "Maximum_WallTime_Exceeded"
            break
        opti.solver("ipopt", {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                              "ipopt.max_wall_time": remaining, "ipopt.max_iter": 500})
        opti.set_value(d, width)
        try:
            sol = opti.solve()
            stats = sol.stats()
        except RuntimeError:
            sol, stats = opti.debug, opti.stats()
        iterations += int(stats.get("iter_count", 0))
        status = str(stats.get("return_status", "unknown"))
        value = np.atleast_1d(np.asarray(sol.value(x), dtype=float))
        if status not in ("Solve_Succeeded", "Solved_To_Acceptable_Level"):
            break
        opti.set_initial(x, value)
    return value, status, iterations


def _status(gap_ok: bool, solver_status: str, problem: AllocationProblem) -> AllocationStatus:
    if solver_status == "Maximum_WallTime_Exceeded":
        return AllocationStatus.TIME_LIMIT
    if solver_status not in ("Solve_Succeeded", "Solved_To_Acceptable_Level"):
        return AllocationStatus.SOLVER_ERROR
    if gap_ok:
        return (AllocationStatus.PROJECTED if problem.projection is not None
                else AllocationStatus.OPTIMAL)
    return AllocationStatus.FEASIBLE_WITH_GAP


def allocate_smooth(problem: AllocationProblem, *, compliance: float = 0.0) -> AllocationResult:
    """Allocate with casadi/ipopt for compliant contacts or a continuous patch.

    Parameters
    ----------
    problem : AllocationProblem
        With a :class:`~toolkit.contacts.ContactSet`: per-contact boxes, fixed, failed masks
        apply (liftable contacts are not lifted by this method). With a
        :class:`~toolkit.contacts.ContactDistribution`: the patch is replaced by a uniform
        patch of the same ``F_tot`` whose speed range ``[a, b]`` is optimized.
    compliance : float, (m/s)/N
        Motor compliance ``k > 0`` of the contacts (required for a ContactSet; Coulomb
        contacts are solved exactly by the "quantile" and "milp" methods).

    Returns
    -------
    AllocationResult
        ``speeds``: the contact speeds (n,), or ``[a, b]`` for a patch; ``contacts``: the
        achieved :class:`ContactSet` or :class:`ContactDistribution`; errors evaluated
        exactly on the true law; ``extra`` holds ``model``, ``compliance``, solver status
        and iterations. ``bound`` is certified only when the error is 0 to rounding (then
        the bound 0 is tight); otherwise ``bound = 0`` and the message says uncertified.
    """
    import casadi as ca

    start = time.perf_counter()
    if compliance < 0 or not np.isfinite(compliance):
        raise ParameterError(parameter_message("compliance", "allocate_smooth",
                                               "be finite and >= 0", compliance))
    curve = problem.curve
    total = problem.total_force
    V, target = _samples(curve)
    widths = np.diff(V)
    weights = np.concatenate(([widths[0]], widths[:-1] + widths[1:], [widths[-1]])) / 2.0
    weights = weights / weights.sum()
    tolerance = 1e-9 * max(total, 1.0)

    if isinstance(problem.contacts, ContactDistribution):
        guess = _quantile_guess(curve, total, 2)
        span = max(guess[1] - guess[0], 1e-3 * max(1.0, abs(guess[0])))
        x0 = np.array([guess[0] - 0.5 * span, guess[1] + 0.5 * span])
        floor = 1e-9 * max(1.0, float(np.max(np.abs(V))))

        def build(x: Any, d: Any) -> tuple[Any, list[Any]]:
            share = 0.5 * (_soft_clip(ca, (2 * V - x[0] - x[1]) / (x[1] - x[0]), d) + 1.0)
            miss = total * (1.0 - 2.0 * share) - target
            return ca.dot(ca.DM(weights), miss ** 2) / total ** 2, [x[1] - x[0] >= floor]

        x, solver_status, iterations = _solve(ca, build, x0, np.full(2, -np.inf),
                                              np.full(2, np.inf), problem.time_limit)
        a, b = float(min(x)), float(max(x[1], x[0] + floor))
        from scipy import stats

        achieved = ContactDistribution(stats.uniform(a, b - a), total)
        error_sup, error_l1 = piecewise_linear_errors(
            curve, lambda W: patch_force(W, a, b, total), [a, b])
        bound = error_sup if error_sup <= tolerance else 0.0
        status = _status(error_sup - bound <= tolerance, solver_status, problem)
        detail = [] if bound == error_sup else [_UNCERTIFIED]
        extra = {"model": "uniform patch", "patch": [a, b], "solver_status": solver_status,
                 "iterations": iterations}
        message = "; ".join([status.value, *detail, *problem.notes])
        return AllocationResult(np.array([a, b]), achieved, np.ones(2, dtype=bool),
                                error_sup, error_l1, bound, error_sup - bound, "casadi",
                                status, message, time.perf_counter() - start,
                                problem.projection, curve, extra)

    if compliance == 0:
        raise ParameterError(parameter_message(
            "compliance", "allocate_smooth", "be > 0 for a ContactSet (Coulomb contacts are "
            "solved exactly by method 'quantile' or 'milp'; 'casadi' handles compliant "
            "contacts and ContactDistribution patches)", compliance))
    n = problem.n
    f = problem.forces
    lower, upper = problem.boxes()
    guess = np.empty(n)
    order = np.argsort(-f)                              # heavy contacts first, spread evenly
    guess[order] = _quantile_guess(curve, total, n)
    x0 = np.clip(guess, lower, upper)
    x0 = np.where(np.isfinite(x0), x0, np.clip(problem.contacts.speeds, lower, upper))
    scale = np.where(f > 0, compliance * f, 1.0)

    def build(x: Any, d: Any) -> tuple[Any, list[Any]]:
        force = 0
        for i in range(n):
            if f[i] == 0:
                continue
            force = force + f[i] * _soft_clip(ca, (x[i] - V) / scale[i], d)
        miss = force - target
        return ca.dot(ca.DM(weights), miss ** 2) / total ** 2, []

    x, solver_status, iterations = _solve(ca, build, x0, lower, upper, problem.time_limit)
    extra = {"model": "compliant", "compliance": compliance, "solver_status": solver_status,
             "iterations": iterations}
    speeds = np.clip(x, lower, upper)
    achieved = ContactSet(speeds, f)
    error_sup, error_l1 = piecewise_linear_errors(
        curve, lambda W: compliant_force(W, speeds, f, compliance),
        np.concatenate((speeds - scale, speeds + scale))[np.concatenate((f, f)) > 0])
    bound = error_sup if error_sup <= tolerance else 0.0
    status = _status(error_sup - bound <= tolerance, solver_status, problem)
    detail = [] if bound == error_sup else [_UNCERTIFIED]
    message = "; ".join([status.value, *detail, *problem.notes])
    return AllocationResult(speeds, achieved, np.ones(n, dtype=bool), error_sup, error_l1,
                            bound, error_sup - bound, "casadi", status, message,
                            time.perf_counter() - start, problem.projection, curve, extra)
