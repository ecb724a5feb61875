"""Smooth allocation variants solved with casadi (ipopt): compliant contacts and continuous
patches (private).

Ipopt works on a smooth surrogate of the saturations; the reported errors are then computed
exactly on the true piecewise-linear law. A bound is certified only for a patch within
scalar speed limits; otherwise the result says it is uncertified. Details: docs/methods.md."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..model import ContactDistribution, ContactSet
from ..errors import ParameterError, parameter_message
from ._evaluate import compliant_force, forced_error, piecewise_linear_errors
from ._problem import AllocationProblem, AllocationResult, AllocationStatus
from ._quantile import quantile_speeds
from .targets import ForceCurve

__all__ = ["allocate_smooth", "compliant_force", "patch_force", "piecewise_linear_errors"]

_SAMPLES = 201
_SMOOTHING = (1e-1, 1e-2, 1e-3, 1e-4, 1e-6)     # corner widths d of the soft clip (continuation)
_UNCERTIFIED = ("no certified lower bound for this smooth model{beyond} (bound = {bound:.6g} "
                "N, gap = error - bound); errors evaluated exactly on the piecewise-linear law")


def patch_force(V: Any, low: float, high: float, total_force: float) -> np.ndarray:
    """Net force of a uniform patch on ``[low, high]``, ``F_tot (1 - 2 clip((V - a)/(b - a)))``, N."""
    share = np.clip((np.asarray(V, dtype=float) - low) / (high - low), 0.0, 1.0)
    return total_force * (1.0 - 2.0 * share)


def _soft_clip(ca: Any, x: Any, d: Any) -> Any:
    return 0.5 * (ca.sqrt((x + 1) ** 2 + d ** 2) - ca.sqrt((x - 1) ** 2 + d ** 2))


def _samples(curve: ForceCurve) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = curve.band
    V = np.unique(np.concatenate((np.linspace(lo, hi, _SAMPLES), curve.speeds)))
    target = 0.5 * (curve.value_left(V) + curve.value_right(V))
    return V, target


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
        With a :class:`~toolkit.model.ContactSet`: per-contact boxes, fixed, failed masks
        apply (liftable contacts are not lifted by this method). With a
        :class:`~toolkit.model.ContactDistribution`: the patch is replaced by a uniform
        patch of the same ``F_tot`` whose speed range ``[a, b]`` is optimized inside the
        scalar speed limits ``problem.lower[0] <= a < b <= problem.upper[0]``.
    compliance : float, (m/s)/N
        Motor compliance ``k > 0`` of the contacts (required for a ContactSet; Coulomb
        contacts are solved exactly by the "quantile" and "milp" methods).

    Returns
    -------
    AllocationResult
        ``speeds``: the contact speeds (n,), or ``[a, b]`` for a patch; ``contacts``: the
        contact speeds and magnitudes to drive with motors of compliance ``k``
        (``result.compliance``), or the achieved :class:`ContactDistribution`; errors
        evaluated exactly on the true (compliant or patch) law; ``extra`` holds ``model``,
        ``compliance``, solver status and iterations. ``bound``: for a patch, the error
        forced by the speed limits (certified); otherwise 0 (uncertified, said in the
        message) unless the error is 0 to rounding (then 0 is tight).
    """
    import casadi as ca  # casadi loads only when the smooth method runs

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

    if isinstance(problem.contacts, ContactDistribution):
        limit_lo, limit_hi = float(problem.lower[0]), float(problem.upper[0])
        guess = quantile_speeds(curve, 2, total)
        span = max(guess[1] - guess[0], 1e-3 * max(1.0, abs(guess[0])))
        floor = 1e-9 * max(1.0, float(np.max(np.abs(V))))
        x0 = np.clip([guess[0] - 0.5 * span, guess[1] + 0.5 * span], limit_lo, limit_hi)
        if np.isfinite(limit_hi):
            x0[0] = min(x0[0], limit_hi - floor)
        x0[1] = max(x0[1], x0[0] + floor)

        def build(x: Any, d: Any) -> tuple[Any, list[Any]]:
            share = 0.5 * (_soft_clip(ca, (2 * V - x[0] - x[1]) / (x[1] - x[0]), d) + 1.0)
            miss = total * (1.0 - 2.0 * share) - target
            return ca.dot(ca.DM(weights), miss ** 2) / total ** 2, [x[1] - x[0] >= floor]

        x, solver_status, iterations = _solve(ca, build, x0, np.full(2, limit_lo),
                                              np.full(2, limit_hi), problem.time_limit)
        a = float(np.clip(min(x), limit_lo, limit_hi - floor))
        b = float(np.clip(max(x[1], a + floor), a + floor, max(limit_hi, a + floor)))
        from scipy import stats  # scipy.stats: 0.6 s at import, only for a patch

        achieved: Any = ContactDistribution(stats.uniform(a, b - a), total)
        speeds = np.array([a, b])
        errors = piecewise_linear_errors(curve, lambda W: patch_force(W, a, b, total), [a, b])
        certified = forced_error(curve, total, (limit_lo, limit_hi))
        extra = {"model": "uniform patch", "patch": [a, b], "speed_limits": [limit_lo, limit_hi]}
    else:
        if compliance == 0:
            raise ParameterError(parameter_message(
                "compliance", "allocate_smooth", "be > 0 for a ContactSet (Coulomb contacts are "
                "solved exactly by method 'quantile' or 'milp'; 'casadi' handles compliant "
                "contacts and ContactDistribution patches)", compliance))
        n, f = problem.n, problem.forces
        lower, upper = problem.boxes()
        guess = np.empty(n)
        guess[np.argsort(-f)] = quantile_speeds(curve, n, total)   # heavy contacts first
        x0 = np.clip(guess, lower, upper)
        x0 = np.where(np.isfinite(x0), x0, np.clip(problem.contacts.speeds, lower, upper))
        scale = np.where(f > 0, compliance * f, 1.0)

        def build(x: Any, d: Any) -> tuple[Any, list[Any]]:
            force = 0
            for i in range(n):
                if f[i] > 0:
                    force = force + f[i] * _soft_clip(ca, (x[i] - V) / scale[i], d)
            miss = force - target
            return ca.dot(ca.DM(weights), miss ** 2) / total ** 2, []

        x, solver_status, iterations = _solve(ca, build, x0, lower, upper, problem.time_limit)
        speeds = np.clip(x, lower, upper)
        achieved = ContactSet(speeds, f)
        errors = piecewise_linear_errors(
            curve, lambda W: compliant_force(W, speeds, f, compliance),
            np.concatenate((speeds - scale, speeds + scale))[np.concatenate((f, f)) > 0])
        certified = 0.0
        extra = {"model": "compliant"}
    return _smooth_result(problem, speeds, achieved, errors, certified, compliance, extra,
                          solver_status, iterations, start)


def _smooth_result(problem: AllocationProblem, speeds: np.ndarray, achieved: Any,
                   errors: tuple[float, float], certified: float, compliance: float,
                   extra: dict[str, Any], solver_status: str, iterations: int, start: float
                   ) -> AllocationResult:
    """Bound, gap, status and message of a smooth allocation (both models)."""
    error_sup, error_l1 = errors
    tolerance = 1e-9 * max(problem.total_force, 1.0)
    # The error itself is a tight bound when it is 0 to rounding.
    bound = min(error_sup, max(certified, error_sup if error_sup <= tolerance else 0.0))
    gap = error_sup - bound
    status = _status(gap <= tolerance, solver_status, problem)
    beyond = " beyond the error forced by the speed limits" if compliance == 0 else ""
    details = [] if gap <= tolerance else [_UNCERTIFIED.format(beyond=beyond, bound=bound)]
    if compliance > 0:
        details.append(f"contacts are the speeds and magnitudes for motors of compliance "
                       f"k = {compliance:g} (m/s)/N; their Coulomb staircase is not what was "
                       f"optimized (re-evaluate with evaluate_errors(..., compliance=k))")
    extra = dict(extra, compliance=compliance, solver_status=solver_status,
                 iterations=iterations)
    message = "; ".join([status.value, *details, *problem.notes])
    return AllocationResult(speeds, achieved, np.ones(speeds.size, dtype=bool), error_sup,
                            error_l1, bound, gap, "casadi", status, message,
                            time.perf_counter() - start, problem.projection, problem.curve,
                            extra, compliance)
