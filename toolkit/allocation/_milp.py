"""Mixed-integer allocation for unequal magnitudes (cvxpy + HiGHS) (private).

Minimizes the sup error of the staircase against a realizable target with two exact
formulations, a partition of the contacts (one shared speed box) and a pairwise order
(per-contact boxes, rate limits, fixed or failed contacts, equilibrium margins); HiGHS's
dual bound is a certified lower bound. The formulations: docs/methods.md."""

from __future__ import annotations

import os
import sys
import time
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import ParameterError, parameter_message
from ..model import ContactSet
from ._evaluate import evaluate_errors, forced_error, margin_requirement
from ._problem import AllocationProblem, AllocationResult, AllocationStatus, make_result
from ._quantile import level_crossings
from .targets import EquilibriumSpeed, ForceCurve

__all__ = ["allocate_milp", "partition_applies"]

_VOID = 4.0          # |force| far beyond F_tot = 1 (forces are normalized): a void constraint


@dataclass(frozen=True)
class _Solution:
    speeds: np.ndarray
    active: np.ndarray
    bound: float
    status: AllocationStatus | None
    detail: str
    stats: dict[str, Any]


_TOLERANCE = 1e-9     # HiGHS primal, dual and integrality tolerances (units of F_tot)
# The dual bound is a floating-point number from LP relaxations solved to _TOLERANCE
# (primal and dual feasibility) with the branch-and-bound closed to mip_abs_gap =
# _TOLERANCE, on a problem normalized to F_tot = 1. The certified bound subtracts ten times
# that tolerance, 1e-8 F_tot: an allowance of the order of the tolerances against that
# rounding (not a proof in exact arithmetic), small enough that the gap target
# (1e-6 at F_tot ~ 50 for N = 30) is met.
BOUND_ALLOWANCE = 10.0 * _TOLERANCE


def _highs_options(problem: AllocationProblem, deadline: float) -> dict[str, Any]:
    # What is left of the caller's budget (0 once spent: HiGHS then stops at once, status
    # user_limit, and the heuristic's allocation is returned with status TIME_LIMIT).
    return {"time_limit": max(deadline - time.perf_counter(), 0.0), "mip_rel_gap": 0.0,
            "mip_abs_gap": _TOLERANCE, "primal_feasibility_tolerance": _TOLERANCE,
            "dual_feasibility_tolerance": _TOLERANCE,
            "mip_feasibility_tolerance": _TOLERANCE, "random_seed": 0}


@contextmanager
def _native_stdout_silenced() -> Iterator[None]:
    """File descriptor 1 pointed at the null device for the block: HiGHS prints its banner
    from native code when constructed, before any option applies, which would corrupt a
    command's ``--json`` output on stdout. C's buffers are flushed before it is restored."""
    sys.stdout.flush()
    try:
        saved = os.dup(1)
    except OSError:                      # no descriptor 1 (a closed stdout): nothing to guard
        yield
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        yield
    finally:
        try:
            import ctypes

            ctypes.CDLL(None).fflush(None)
        except (OSError, AttributeError):
            pass
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)


def _solve(objective: Any, constraints: list[Any], options: dict[str, Any]
           ) -> tuple[str, float, float, dict[str, Any]]:
    import cvxpy as cp  # cvxpy loads only when the MILP method runs

    prob = cp.Problem(cp.Minimize(objective), constraints)
    try:
        with warnings.catch_warnings(), _native_stdout_silenced():
            # cvxpy warns "inaccurate" when HiGHS stops at its time limit; the status says it.
            warnings.simplefilter("ignore", UserWarning)
            prob.solve(solver=cp.HIGHS, **options)
    except cp.error.SolverError as exc:
        return "error: " + str(exc), np.nan, -np.inf, {}
    info = prob.solver_stats.extra_stats
    dual = float(getattr(info, "mip_dual_bound", np.nan)) if info is not None else np.nan
    stats = {"solve_time": prob.solver_stats.solve_time,
             "mip_nodes": int(getattr(info, "mip_node_count", 0) or 0) if info else 0,
             "mip_gap": float(getattr(info, "mip_gap", np.nan)) if info else np.nan,
             "cvxpy_status": prob.status}
    value = float(prob.value) if prob.value is not None else np.nan
    return prob.status, value, dual, stats


# -- partition formulation ------------------------------------------------------------------------
def _effective_band(problem: AllocationProblem) -> tuple[float, float]:
    lo, hi = problem.curve.band
    box_lo, box_hi = problem.boxes()
    return max(lo, float(box_lo[0])), min(hi, float(box_hi[0]))


def partition_applies(problem: AllocationProblem) -> bool:
    """True when the partition formulation is exact: one shared box, nothing fixed or failed,
    and a target that is continuous on a non-degenerate effective band."""
    if problem.n == 0 or np.any(problem.fixed | problem.failed):
        return False
    box_lo, box_hi = problem.boxes()
    if not (np.all(box_lo == box_lo[0]) and np.all(box_hi == box_hi[0])):
        return False
    if isinstance(problem.target, EquilibriumSpeed) and problem.target.margin > 0:
        return False
    a, b = _effective_band(problem)
    if not a < b:
        return False
    xs = problem.curve.speeds
    inside = (xs[1:] == xs[:-1]) & (xs[1:] > a) & (xs[1:] < b)
    jumps = problem.curve.forces[1:] != problem.curve.forces[:-1]
    return not np.any(inside & jumps)


def _solve_partition(problem: AllocationProblem, deadline: float) -> _Solution:
    import cvxpy as cp  # cvxpy loads only when the MILP method runs

    n, total = problem.n, problem.total_force
    f = problem.forces / total
    curve = problem.curve
    lo, hi = curve.band
    a, b = _effective_band(problem)
    t_a, t_b = float(curve.value_right(a)) / total, float(curve.value_left(b)) / total
    x = cp.Variable((n, 4), boolean=True)            # below, inside, above, lifted
    t = cp.Variable(nonneg=True)
    cons = [cp.sum(x, axis=1) == 1]
    if not np.all(problem.can_lift):
        cons.append(x[~problem.can_lift, 3] == 0)
    f_act = f @ (1 - x[:, 3])
    if np.any(problem.can_lift):
        # At least one contact stays down: lifting them all leaves no contact set at all.
        cons.append(f_act >= float(np.min(f[f > 0])))
    p_a = f @ (x[:, 1] + x[:, 2]) - f @ x[:, 0]
    p_b = f @ x[:, 2] - f @ (x[:, 0] + x[:, 1])
    cons += [t >= t_a - p_a, t >= p_a - t_a, t >= t_b - p_b, t >= p_b - t_b,
             t >= cp.multiply(f, x[:, 1])]
    if a > lo:               # V in [lo, a): every active contact is above V
        for value in (float(curve.value_right(lo)), float(curve.value_left(a))):
            cons += [t >= value / total - f_act, t >= f_act - value / total]
    if b < hi:               # V in (b, hi]: every active contact is below V
        for value in (float(curve.value_right(b)), float(curve.value_left(hi))):
            cons += [t >= value / total + f_act, t >= -f_act - value / total]
    status, value, dual, stats = _solve(t, cons, _highs_options(problem, deadline))
    if x.value is None:
        return _failed(problem, status, stats)
    cls = np.argmax(x.value, axis=1)
    speeds = np.clip(problem.contacts.speeds, *problem.boxes())
    speeds = np.where(cls == 0, a, np.where(cls == 2, b, speeds))
    inside = np.flatnonzero(cls == 1)
    if inside.size:
        # Steps follow the target: each at the speed where T crosses the middle of its step.
        forces = problem.forces
        plateau = total * (float(f @ (cls != 3)) - 2.0 * float(f @ (cls == 0)))
        order = inside[np.argsort(-forces[inside], kind="stable")]
        middles = plateau - 2.0 * np.concatenate(([0.0], np.cumsum(forces[order])[:-1])) \
            - forces[order]
        speeds[order] = level_crossings(curve.restrict(a, b), middles)
    stats["formulation"] = "partition"
    return _finish(problem, speeds, cls != 3, status, dual, stats)


def _subset_sums(weights: np.ndarray) -> np.ndarray:
    """All ``2^k`` subset sums; entry ``mask`` is the sum of the weights whose bit is set."""
    sums = np.zeros(1)
    for w in weights:
        sums = np.concatenate((sums, sums + w))
    return sums


def _solve_subset_sum(problem: AllocationProblem) -> _Solution | None:
    """Exact shortcut of the partition formulation when no contact sits inside the band.

    With every contact at ``a`` (set ``B``) or ``b``, ``P(a+) = P(b-) = F_tot - 2 w(B)`` and
    the error is ``h(w(B)) = max(|T(a+) - P|, |T(b-) - P|)`` (convex in ``w(B)``), besides the
    forced errors outside the box, which do not depend on the split. The subset sum nearest
    the minimizer of ``h`` is found exactly by meeting in the middle (``2^(n/2)`` sums per
    half). Any allocation with a contact inside the band costs at least the smallest
    magnitude, so when the best split costs no more than that it is optimal and its error is
    a certified bound. Returns None when the shortcut does not apply or cannot certify.
    """
    n = problem.n
    if n > 40 or np.any(problem.can_lift):
        # Lifting is the partition MILP's job (it keeps at least one contact down); the
        # split below never lifts, so every contact stays down here.
        return None
    forces, total = problem.forces, problem.total_force
    curve = problem.curve
    a, b = _effective_band(problem)
    t_a, t_b = float(curve.value_right(a)), float(curve.value_left(b))
    forced = forced_error(curve, total, (a, b))
    goal = 0.5 * (total - 0.5 * (t_a + t_b))        # w(B) minimizing h
    half = n // 2
    left, right = _subset_sums(forces[:half]), _subset_sums(forces[half:])
    order = np.argsort(right, kind="stable")
    ranked = right[order]
    pos = np.clip(np.searchsorted(ranked, goal - left), 1, ranked.size - 1)
    pick = np.where(np.abs(left + ranked[pos - 1] - goal) <= np.abs(left + ranked[pos] - goal),
                    pos - 1, pos) if ranked.size > 1 else np.zeros(left.size, dtype=int)
    sums = left + ranked[pick]
    plateau = total - 2.0 * sums
    cost = np.maximum(np.abs(t_a - plateau), np.abs(t_b - plateau))
    best = int(np.argmin(cost))
    error = max(float(cost[best]), forced)
    positive = forces[forces > 0]
    if positive.size == 0 or error > max(float(positive.min()), forced):
        return None
    mask_left, mask_right = best, int(order[pick[best]])
    below = np.zeros(n, dtype=bool)
    below[:half] = (mask_left >> np.arange(half)) & 1 == 1
    below[half:] = (mask_right >> np.arange(n - half)) & 1 == 1
    speeds = np.where(below, a, b)
    stats = {"formulation": "subset-sum", "subset_sums": int(left.size + right.size)}
    return _Solution(speeds, np.ones(n, dtype=bool), error, None,
                     "exact split by meeting in the middle; certified since no contact inside "
                     "the band can do better than the smallest magnitude", stats)


# -- pairwise-order formulation -------------------------------------------------------------------
def _classes(curve: ForceCurve, total: float, vmin: float, vmax: float
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Segment classes of the left-limit (R role) and right-limit (L role) target functions.

    Returns ``(lo_c, hi_c, alpha_R, beta_R, alpha_L, beta_L)`` with one entry per class:
    before the band, every positive-width segment, after the band; ``T(v) = alpha + beta v``
    (normalized by ``total``) on the class's closed range.
    """
    xs, ys = curve.speeds, curve.forces / total
    lo, hi = curve.band
    wide = np.flatnonzero(xs[1:] > xs[:-1])
    slope = (ys[wide + 1] - ys[wide]) / (xs[wide + 1] - xs[wide])
    alpha = ys[wide] - slope * xs[wide]
    t_lo, t_hi = float(curve.value_right(lo)) / total, float(curve.value_left(hi)) / total
    lo_c = np.concatenate(([vmin], xs[wide], [hi]))
    hi_c = np.concatenate(([lo], xs[wide + 1], [vmax]))
    alpha_r = np.concatenate(([_VOID], alpha, [t_hi]))
    alpha_l = np.concatenate(([t_lo], alpha, [-_VOID]))
    beta = np.concatenate(([0.0], slope, [0.0]))
    return lo_c, hi_c, alpha_r, beta, alpha_l, beta


def _solve_pairwise(problem: AllocationProblem, deadline: float) -> _Solution:
    import cvxpy as cp  # cvxpy loads only when the MILP method runs

    total = problem.total_force
    curve = problem.curve
    lo, hi = curve.band
    box_lo, box_hi = problem.boxes()
    pad = 1.0 + (hi - lo)
    # Beyond the band only the side matters: pull infinite boxes in to a finite range.
    a_box = np.maximum(box_lo, np.minimum(box_hi, lo - pad))
    b_box = np.minimum(box_hi, np.maximum(a_box, hi + pad))
    use = np.flatnonzero(problem.forces > 0)
    n = use.size
    f = problem.forces[use] / total
    a_box, b_box = a_box[use], b_box[use]
    lift = problem.can_lift[use]
    vmin, vmax = min(float(a_box.min()), lo), max(float(b_box.max()), hi)
    lo_c, hi_c, alpha_r, beta, alpha_l, _ = _classes(curve, total, vmin, vmax)
    m = lo_c.size

    v = cp.Variable(n)
    t = cp.Variable(nonneg=True)
    cons: list[Any] = [v >= a_box, v <= b_box]
    # Order: before[i, j] = 1 if contact i is (weakly) before contact j.
    before = cp.Variable((n, n), boolean=True)
    fixed_one = np.zeros((n, n), dtype=bool)
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            same = (f[i] == f[j] and a_box[i] == a_box[j] and b_box[i] == b_box[j]
                    and lift[i] == lift[j])
            if (same and i < j) or (b_box[i] <= a_box[j] and not (b_box[j] <= a_box[i] and j < i)):
                fixed_one[i, j] = True
    big = np.maximum(b_box[:, None] - a_box[None, :], 0.0)
    ones = np.ones((1, n))
    diff = cp.reshape(v, (n, 1), order="F") @ ones - (cp.reshape(v, (n, 1), order="F") @ ones).T
    off = ~np.eye(n, dtype=bool)
    cons += [before + before.T == 1 - np.eye(n),
             cp.multiply(off, diff) <= cp.multiply(big, 1 - before)]
    if np.any(fixed_one):
        cons.append(before[fixed_one] == 1)
    # Transitivity: without it tied contacts could be "before" each other in a cycle.
    free = ~(fixed_one | fixed_one.T) & off
    tri = [(i, j, k) for i in range(n) for j in range(i + 1, n) for k in range(j + 1, n)
           if free[i, j] or free[j, k] or free[i, k]]
    if tri:
        i, j, k = (np.array(col) for col in zip(*tri))
        flat = cp.vec(before, order="C")
        cons += [flat[i * n + j] + flat[j * n + k] + flat[k * n + i] <= 2,
                 flat[i * n + k] + flat[k * n + j] + flat[j * n + i] <= 2]
    if np.any(lift):
        z = cp.Variable(n, boolean=True)
        if not np.all(lift):          # (cvxpy 1.6 refuses a constraint on an empty selection)
            cons.append(z[~lift] == 1)
        zcol = cp.reshape(z, (n, 1), order="F") @ ones
        below = cp.Variable((n, n), nonneg=True)
        cons += [below <= before, below <= zcol, below >= before + zcol - 1]
        f_act = f @ z
        cons.append(f_act >= float(f.min()))      # at least one contact stays down
        inactive = 1 - z
    else:
        z, below, f_act, inactive = None, before, float(f.sum()), np.zeros(n)
    a_minus = f_act - 2 * (f @ below)
    a_plus = a_minus - 2 * f
    # Target values at each contact: disaggregated segment choice, one per role.
    tau = []
    for alpha in (alpha_r, alpha_l):
        rho = cp.Variable((n, m), boolean=True)
        y = cp.Variable((n, m))
        cons += [cp.sum(rho, axis=1) == 1, cp.sum(y, axis=1) == v,
                 y >= cp.multiply(rho, np.broadcast_to(lo_c, (n, m))),
                 y <= cp.multiply(rho, np.broadcast_to(hi_c, (n, m)))]
        tau.append(rho @ alpha + y @ beta)
    slack = 2.0 * _VOID * inactive
    cons += [t >= a_minus - tau[0] - slack, t >= tau[1] - a_plus - slack,
             t >= float(curve.value_right(lo)) / total - f_act,
             t >= -f_act - float(curve.value_left(hi)) / total]
    target = problem.target
    if isinstance(target, EquilibriumSpeed) and target.margin > 0:
        speed = _step_speed(curve)
        q = cp.Variable((n, 3), boolean=True)        # below, at, above the speed
        reach = np.maximum(np.abs(b_box - speed), np.abs(a_box - speed)) + 1.0
        cons += [cp.sum(q, axis=1) == (z if z is not None else 1),
                 v <= speed + cp.multiply(reach, 1 - q[:, 0] - q[:, 1]),
                 v >= speed - cp.multiply(reach, 1 - q[:, 1] - q[:, 2])]
        w_at, w_lo, w_hi = f @ q[:, 1], f @ q[:, 0], f @ q[:, 2]
        need = margin_requirement(f, target.margin)
        cons += [w_at >= w_hi - w_lo + need, w_at >= w_lo - w_hi + need]
    status, value, dual, stats = _solve(t, cons, _highs_options(problem, deadline))
    if v.value is None:
        return _failed(problem, status, stats)
    active_use = np.ones(n, dtype=bool) if z is None else np.round(z.value) > 0.5
    speeds = np.clip(problem.contacts.speeds, *problem.boxes())
    speeds[use] = _snap(np.asarray(v.value), np.round(before.value) > 0.5, a_box, b_box, curve)
    active = np.zeros(problem.n, dtype=bool)
    active[use] = active_use
    stats["formulation"] = "pairwise"
    return _finish(problem, speeds, active, status, dual, stats)


def _step_speed(curve: ForceCurve) -> float:
    xs = curve.speeds
    repeated = np.flatnonzero(xs[1:] == xs[:-1])
    return float(xs[repeated[0]]) if repeated.size else float(xs[0])


def _snap(v: np.ndarray, before: np.ndarray, a_box: np.ndarray, b_box: np.ndarray,
          curve: ForceCurve) -> np.ndarray:
    """Remove solver round-off from the speeds so the true order is the model's order.

    Speeds within ``tol`` of a target breakpoint move onto it; then contacts are visited in
    the model's order and each is raised to at least its predecessor's speed when they are
    within ``tol`` (a tie the solver meant). Boxes are respected.
    """
    tol = 1e-7 * max(1.0, float(np.max(np.abs(curve.speeds))))
    points = np.unique(curve.speeds)
    near = np.abs(v[:, None] - points[None, :])
    k = np.argmin(near, axis=1)
    v = np.where(near[np.arange(v.size), k] <= tol, points[k], v)
    order = np.argsort(-before.sum(axis=1), kind="stable")   # most successors first
    out = np.clip(v, a_box, b_box)
    for prev, cur in zip(order[:-1], order[1:]):
        if out[cur] < out[prev] + tol and out[cur] >= out[prev] - tol:
            out[cur] = min(max(out[cur], out[prev]), b_box[cur])
    return out


def _failed(problem: AllocationProblem, status: str, stats: dict[str, Any]) -> _Solution:
    speeds = np.clip(problem.contacts.speeds, *problem.boxes())
    if status in ("infeasible", "infeasible_inaccurate"):
        kind, detail = AllocationStatus.INFEASIBLE, "the MILP is infeasible"
    elif "time" in str(stats.get("cvxpy_status", "")) or status == "user_limit":
        kind, detail = AllocationStatus.TIME_LIMIT, "no solution within the time limit"
    else:
        kind, detail = AllocationStatus.SOLVER_ERROR, f"HiGHS returned {status!r}"
    return _Solution(speeds, np.ones(problem.n, dtype=bool), 0.0, kind, detail, stats)


def _finish(problem: AllocationProblem, speeds: np.ndarray, active: np.ndarray, status: str,
            dual: float, stats: dict[str, Any]) -> _Solution:
    """Package a solve; ``dual`` is HiGHS's dual bound on the normalized problem (F_tot = 1).

    The reported bound is ``max(0, dual - BOUND_ALLOWANCE) * F_tot``: conservative by the
    solver tolerances (see ``BOUND_ALLOWANCE``).
    """
    total = problem.total_force
    bound = max(dual - BOUND_ALLOWANCE, 0.0) * total if np.isfinite(dual) else 0.0
    stats = dict(stats, dual_bound=float(dual * total) if np.isfinite(dual) else float("nan"),
                 bound_allowance=BOUND_ALLOWANCE * total)
    kind = None
    detail = (f"HiGHS {status}, dual bound {bound:.6g} N (HiGHS's value less "
              f"{BOUND_ALLOWANCE:.0e} F_tot for its tolerances)")
    if status not in ("optimal",):
        kind = AllocationStatus.TIME_LIMIT
        detail = f"HiGHS stopped ({status}); {detail}"
    return _Solution(speeds, active, bound, kind, detail, stats)


def _heuristic(problem: AllocationProblem) -> tuple[np.ndarray, float]:
    """A fast feasible allocation: weighted quantiles in the order of the box centres.

    Contacts are ordered by the centre of their box; contact ``i`` aims at the speed where
    the target crosses the middle of its own step (``F_tot - 2 W_before - f_i``), clipped to
    its box. Also tries the current speeds. Returns the better one and its evaluated error.
    """
    lo, hi = problem.boxes()
    forces, total = problem.forces, problem.total_force
    centre = np.where(np.isfinite(lo) & np.isfinite(hi), 0.5 * (lo + hi),
                      np.where(np.isfinite(lo), lo, np.where(np.isfinite(hi), hi, 0.0)))
    order = np.argsort(centre, kind="stable")
    before = np.concatenate(([0.0], np.cumsum(forces[order])[:-1]))
    aims = np.empty(problem.n)
    aims[order] = level_crossings(problem.curve, total - 2.0 * before - forces[order])
    best, best_error = None, np.inf
    for speeds in (np.clip(aims, lo, hi), np.clip(problem.contacts.speeds, lo, hi)):
        error = evaluate_errors(problem.curve, ContactSet(speeds, forces))[0]
        if error < best_error:
            best, best_error = speeds, error
    return best, best_error


def allocate_milp(problem: AllocationProblem, start: float | None = None) -> AllocationResult:
    """Solve ``problem`` with the exact mixed-integer formulation (HiGHS via cvxpy).

    The partition formulation is used when it applies (:func:`partition_applies`),
    the pairwise-order formulation otherwise. The bound is HiGHS's dual bound less
    ``BOUND_ALLOWANCE * F_tot`` (1e-8 F_tot; its tolerances are set to ``1e-9`` of ``F_tot``),
    floored at 0.
    """
    start = time.perf_counter() if start is None else start
    if problem.n == 0:
        raise ParameterError(parameter_message(
            "contacts", "allocate", "be a ContactSet for method 'milp'", problem.contacts))
    deadline = start + problem.time_limit
    if partition_applies(problem):
        sol = _solve_subset_sum(problem) or _solve_partition(problem, deadline)
    else:
        sol = _solve_pairwise(problem, deadline)
    result = make_result(problem, sol.speeds, sol.active, sol.bound, "milp", start,
                         status=sol.status, detail=sol.detail, extra=sol.stats,
                         gap_tolerance=1e-7)
    if sol.status is not None and sol.status is not AllocationStatus.INFEASIBLE:
        # The solver stopped early: fall back on the heuristic when it is better, with the
        # solver's bound and therefore an honest gap.
        speeds, error = _heuristic(problem)
        if error < result.error_sup or sol.status is not AllocationStatus.TIME_LIMIT:
            extra = dict(sol.stats, heuristic=True)
            result = make_result(problem, speeds, np.ones(problem.n, dtype=bool), sol.bound,
                                 "milp", start, status=sol.status,
                                 detail=sol.detail + "; speeds from the weighted-quantile "
                                 "heuristic, its gap against the solver's bound is reported",
                                 extra=extra, gap_tolerance=1e-7)
    if sol.status is None and result.error_sup < result.bound - 1e-7 * problem.total_force:
        return replace(result, status=AllocationStatus.SOLVER_ERROR,
                       message=f"{AllocationStatus.SOLVER_ERROR.value}; the evaluated error "
                               f"{result.error_sup:.9g} N is below HiGHS's bound "
                               f"{result.bound:.9g} N")
    return result
