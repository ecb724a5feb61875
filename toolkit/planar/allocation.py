"""Allocation in the plane: leg velocities, within per-leg speed limits, that realize a wanted
equilibrium twist (:func:`allocate_twist`, with a checked certificate when none exists) or a
wanted local resistance around a twist (:func:`allocate_resistance`, ipopt, no certified
bound). Contacts are isotropic here (docs/planar.md section 7); the method: docs/methods.md."""

from __future__ import annotations

import enum
import math
import time
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ParameterError, as_float, as_float_array, as_int, parameter_message
from .contacts import PlanarContactSet
from .equilibrium import PlanarEquilibrium, solve_equilibrium

__all__ = ["PlanarAllocationStatus", "PlanarAllocationResult", "allocate_twist",
           "allocate_resistance", "infeasibility_margin"]


class PlanarAllocationStatus(enum.Enum):
    """Outcome of a planar allocation; the value is the message shown to users."""

    REALIZED = "realized: the target is the certified equilibrium of the achieved contacts"
    INFEASIBLE = ("infeasible: no leg velocities within the speed limits make the target an "
                  "equilibrium; 'certificate' is a twist direction that proves it")
    APPROXIMATE = ("not realized: the best allocation found misses the target by 'error'; no "
                   "certificate either way (the problem is not convex)")
    SOLVER_ERROR = "the numerical back end failed; see 'message'"


@dataclass(frozen=True, eq=False)
class PlanarAllocationResult:
    """Leg velocities and what they achieve.

    Attributes
    ----------
    velocities : ndarray of shape (n,), 2), m/s
        The allocated contact velocities (NaN when infeasible).
    contacts : PlanarContactSet or None
        The achieved contacts (positions, these velocities, the loads).
    target : ndarray of shape (3,)
        ``(Vx, Vy, omega)`` asked for.
    equilibrium : PlanarEquilibrium or None
        The certified equilibrium of the achieved contacts.
    error : float
        Twist targets: ``max(|V_eq - V_t|, |omega_eq - omega_t| L)`` (m/s, ``L`` the legs'
        largest distance from their load centroid), measured on the achieved contacts.
        Resistance targets: ``|R - R_t|_F / |R_t|_F`` (relative), likewise measured.
    bound : float
        A certified lower bound on what any allocation can reach: 0 for a realized target;
        for an infeasible twist target, the smallest net wrench the legs can leave at the
        target (N, torques over ``L``) from the convex relaxation, which is > 0; 0 (not
        certified) for resistance targets.
    gap : float
        ``error - bound``.
    status : PlanarAllocationStatus
    certificate : ndarray of shape (3,) or None
        For an infeasible twist target: a direction ``y`` (force components 1/N, torque 1/(N
        m)) with ``sum_i h_i(A_i y) < 0``, ``h_i`` the support function of leg ``i``'s
        achievable forces (:func:`infeasibility_margin` evaluates it): every admissible
        allocation leaves a net wrench ``w`` with ``y . w < 0``, never zero.
    slipping : ndarray of shape (n,), bool
        Legs that slip at the target.
    dissipation : float, W
        ``sum f_i |s_i|`` at the target.
    method : str
    wall_time : float, s
    message : str
    """

    velocities: np.ndarray
    contacts: PlanarContactSet | None
    target: np.ndarray
    equilibrium: PlanarEquilibrium | None
    error: float
    bound: float
    gap: float
    status: PlanarAllocationStatus
    certificate: np.ndarray | None
    slipping: np.ndarray
    dissipation: float
    method: str
    wall_time: float
    message: str = ""


def _twist_arrays(positions: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``A_i`` (n, 2, 3) and ``a_i = A_i x_t`` (n, 2): the body velocity at each leg."""
    n = positions.shape[0]
    A = np.zeros((n, 2, 3))
    A[:, 0, 0] = A[:, 1, 1] = 1.0
    A[:, 0, 2] = -positions[:, 1]
    A[:, 1, 2] = positions[:, 0]
    return A, A @ target


def _support(p: np.ndarray, f: np.ndarray, inside: np.ndarray, centre: np.ndarray,
             half: np.ndarray) -> np.ndarray:
    """Support functions ``h_i(p_i) = max F . p_i`` over each leg's relaxed force set: the
    disc ``f_i B`` (inside legs) or the circular segment of the arc of directions within
    ``half_i`` of ``centre_i`` (outside legs)."""
    norm = np.hypot(p[:, 0], p[:, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        cosang = np.clip(np.sum(p * centre, axis=1) / norm, -1.0, 1.0)
    ang = np.arccos(np.where(norm > 0, cosang, 1.0))
    arc = np.where(ang <= half, norm, norm * np.cos(ang - half))
    return f * np.where(inside, norm, arc)


def infeasibility_margin(positions: Any, forces: Any, speed_limits: Any, target: Any,
                         direction: Any) -> float:
    """``sum_i h_i(A_i y)`` for a direction ``y``: negative proves that ``target`` cannot be an
    equilibrium of these legs within their limits (see :class:`PlanarAllocationResult`)."""
    pos, f, vmax, xt, y = _inputs(positions, forces, speed_limits, target, "infeasibility_margin")
    yv = as_float_array(direction, "direction", "infeasibility_margin")
    A, a = _twist_arrays(pos, xt)
    speed = np.hypot(a[:, 0], a[:, 1])
    inside = speed <= vmax
    with np.errstate(invalid="ignore", divide="ignore"):
        centre = np.where(inside[:, None], 0.0, -a / speed[:, None])
        half = np.where(inside, np.pi, np.arcsin(np.minimum(vmax / speed, 1.0)))
    return float(np.sum(_support(A @ yv, f, inside, centre, half)))


def _inputs(positions: Any, forces: Any, speed_limits: Any, target: Any, owner: str):
    pos = as_float_array(positions, "positions", owner, ndim=2)
    n = pos.shape[0]
    if pos.shape[1] != 2:
        raise ParameterError(parameter_message("positions", owner, "have shape (n, 2)",
                                               f"an array of shape {pos.shape}"))
    f = np.broadcast_to(as_float_array(forces, "forces", owner), (n,)).astype(float)
    if np.any(f < 0) or not f.sum() > 0:
        raise ParameterError(parameter_message("forces", owner, "be >= 0 with a positive sum", f.tolist()))
    vmax = np.broadcast_to(as_float_array(speed_limits, "speed_limits", owner), (n,)).astype(float)
    if np.any(vmax < 0):
        raise ParameterError(parameter_message("speed_limits", owner, "be >= 0 (m/s)", vmax.tolist()))
    xt = as_float_array(target, "target", owner)
    if xt.shape != (3,):
        raise ParameterError(parameter_message("target", owner, "be a twist (Vx, Vy, omega)", xt.tolist()))
    return pos, f, vmax, xt, None


def _scale_length(pos: np.ndarray, f: np.ndarray) -> float:
    centre = f @ pos / f.sum()
    return float(np.max(np.hypot(*(pos - centre).T))) or 1.0


def allocate_twist(positions: Any, forces: Any, speed_limits: Any, target: Any, *,
                   tol: float = 1e-9, time_limit: float = 30.0) -> PlanarAllocationResult:
    """Leg velocities ``|v_i| <= speed_limits_i`` that make ``target`` the equilibrium twist.

    Parameters
    ----------
    positions : array_like of shape (n, 2), m
        Leg contact points relative to the body's reference point.
    forces : float or array_like of shape (n,), N
        Friction magnitudes ``f_i`` (isotropic).
    speed_limits : float or array_like of shape (n,), m/s
        Largest ``|v_i|`` of each leg.
    target : array_like of shape (3,)
        ``(Vx, Vy, omega)`` at the reference point, m/s and rad/s.
    tol : float
        A target is realized when the achieved equilibrium is within ``tol`` (relative to the
        target's speed scale, ``max(|V_t|, |omega_t| L, min speed limit)``) of it.
    time_limit : float, s
        For the non-convex polish.

    Returns
    -------
    PlanarAllocationResult
        Legs that can stick at the target do (``v_i`` = the body velocity there); the others
        slip with the least slip that gives their allocated force direction.
    """
    owner = "allocate_twist"
    started = time.perf_counter()
    pos, f, vmax, xt, _ = _inputs(positions, forces, speed_limits, target, owner)
    tol = as_float(tol, "tol", owner, low=0.0, low_open=True)
    n = pos.shape[0]
    A, a = _twist_arrays(pos, xt)
    speed = np.hypot(a[:, 0], a[:, 1])
    inside = (speed <= vmax) | (f == 0)
    L = _scale_length(pos, f)
    scale_v = max(float(np.hypot(xt[0], xt[1])), abs(xt[2]) * L, float(np.min(vmax[f > 0])), 1e-300)
    if np.all(inside):
        return _finish(pos, f, a.copy(), xt, L, scale_v, tol, np.zeros(n, bool), "stick", started,
                       "every leg can stick at the target")
    with np.errstate(invalid="ignore", divide="ignore"):
        centre = np.where(inside[:, None], 0.0, -a / speed[:, None])
        half = np.where(inside, np.pi, np.arcsin(np.minimum(vmax / speed, 1.0)))
    try:
        F, residual = _relaxation(A, f, inside, centre, half, L)
    except Exception as error:           # a back end that fails: a status, not a traceback
        return _failed(n, xt, started, f"cvxpy failed: {error}")
    y = -residual_direction(A, F, L)
    margin = infeasibility_margin(pos, f, vmax, xt, y) if residual > 0 else 0.0
    # Infeasible only when the direction checks from the exact support functions (a margin
    # well below the rounding of the sum), not on the solver's word.
    if residual > 1e-7 * f.sum() or margin < -1e-9 * f.sum() * float(np.hypot(*y[:2]) + abs(y[2]) * L):
        status = PlanarAllocationStatus.INFEASIBLE
        message = (f"the legs leave at least {residual:.3g} N (torques over L = {L:.3g} m) of net "
                   f"wrench at the target; certificate margin {margin:.3g} W < 0")
        if not margin < 0:
            status = PlanarAllocationStatus.SOLVER_ERROR
            message = f"the relaxation is infeasible but its certificate does not check (margin {margin:.3g})"
        return PlanarAllocationResult(
            velocities=np.full((n, 2), np.nan), contacts=None, target=xt, equilibrium=None,
            error=math.inf, bound=float(residual), gap=math.inf, status=status, certificate=y,
            slipping=~inside, dissipation=math.nan, method="socp", wall_time=time.perf_counter() - started,
            message=message)
    on_arc = inside | (np.hypot(F[:, 0], F[:, 1]) >= f * (1 - 1e-7))
    # The slipping legs' forces must lie on their arcs and balance to rounding: ipopt from the
    # relaxation's forces (angles within the cones, sticking forces within their discs).
    polished, ok = _arc_polish(A, f, inside, centre, half, F, time_limit)
    method = "socp+ipopt"
    if ok:
        F = polished
    elif not np.all(on_arc):
        velocities = _realize(a, vmax, inside, polished, f)
        return _finish(pos, f, velocities, xt, L, scale_v, tol, ~inside, method, started,
                       "the relaxation's forces are not on their arcs and the non-convex "
                       "polish did not balance them", approximate=True)
    velocities = _realize(a, vmax, inside, F, f)
    return _finish(pos, f, velocities, xt, L, scale_v, tol, ~inside, method, started,
                   f"{int(np.sum(~inside))} legs slip, {int(np.sum(inside & (f > 0)))} stick")


def residual_direction(A: np.ndarray, F: np.ndarray, L: float) -> np.ndarray:
    """The relaxation's residual wrench ``w = sum A_i^T F_i`` as the direction ``(w_F, w_tau /
    L^2)``: the closest point to 0 in the metric ``|F|^2 + (tau / L)^2`` separates 0 from the
    set of admissible wrenches along it (docs/planar.md section 7)."""
    w = np.einsum("nji,nj->i", A, F)
    return np.array([w[0], w[1], w[2] / (L * L)])


def _relaxation(A: np.ndarray, f: np.ndarray, inside: np.ndarray, centre: np.ndarray,
                half: np.ndarray, L: float) -> tuple[np.ndarray, float]:
    """The convex relaxation as the SOCP ``min |sum A_i^T F_i|`` (torque over ``L``) over the
    discs and circular segments; returns the forces and the residual."""
    import cvxpy as cp

    n = f.size
    F = cp.Variable((n, 2))
    t = cp.Variable()
    scale = np.array([1.0, 1.0, 1.0 / L])
    wrench = cp.hstack([cp.sum(F[:, 0]), cp.sum(F[:, 1]),
                        cp.sum(cp.multiply(A[:, 0, 2], F[:, 0]) + cp.multiply(A[:, 1, 2], F[:, 1]))])
    cons = [cp.SOC(f, F, axis=1)]
    out = np.flatnonzero(~inside)
    if out.size:
        cons.append(cp.sum(cp.multiply(F[out], centre[out]), axis=1) >= f[out] * np.cos(half[out]))
    first = cp.Problem(cp.Minimize(t), cons + [cp.SOC(t, cp.multiply(scale, wrench))])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        first.solve(solver="CLARABEL")
    if F.value is None:
        raise RuntimeError(f"status {first.status}")
    if out.size and float(t.value) <= 1e-9 * float(f.sum()):
        # Balanced: among the balancing forces take those furthest into the arcs (on the arc
        # for a slipping leg whenever the balance allows it).
        keep = np.asarray(F.value, dtype=float)
        second = cp.Problem(cp.Maximize(cp.sum(cp.multiply(F[out], centre[out]))),
                            cons + [wrench == 0])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                second.solve(solver="CLARABEL")
            except Exception:
                F.value = keep
        if F.value is None or second.status not in ("optimal", "optimal_inaccurate"):
            F.value = keep
    Fv = np.asarray(F.value, dtype=float)
    # Project onto the sets (the solver's tolerance) and measure the residual ourselves.
    norms = np.hypot(Fv[:, 0], Fv[:, 1])
    Fv *= np.minimum(1.0, f / np.maximum(norms, 1e-300))[:, None]
    w = np.einsum("nji,nj->i", A, Fv)
    residual = float(np.hypot(np.hypot(w[0], w[1]), w[2] / L))
    return Fv, residual


def _arc_polish(A: np.ndarray, f: np.ndarray, inside: np.ndarray, centre: np.ndarray,
                half: np.ndarray, F0: np.ndarray, time_limit: float) -> tuple[np.ndarray, bool]:
    """Forces with the slipping legs on their arcs (angles within their cones) and the
    sticking legs in their discs that balance: ipopt from the relaxation's forces."""
    import casadi as ca

    out = np.flatnonzero(~inside)
    stick = np.flatnonzero(inside & (f > 0))
    opti = ca.Opti()
    phi = opti.variable(out.size)
    G = opti.variable(stick.size, 2) if stick.size else None
    base = np.arctan2(centre[out, 1], centre[out, 0])
    start = np.arctan2(F0[out, 1], F0[out, 0]) - base
    start = (start + np.pi) % (2 * np.pi) - np.pi
    opti.set_initial(phi, np.clip(start, -half[out], half[out]))
    fx = f[out] * ca.cos(base + phi)
    fy = f[out] * ca.sin(base + phi)
    wx, wy = ca.sum1(fx), ca.sum1(fy)
    tq = ca.sum1(A[out, 0, 2] * fx + A[out, 1, 2] * fy)
    if stick.size:
        opti.set_initial(G, F0[stick])
        wx += ca.sum1(G[:, 0])
        wy += ca.sum1(G[:, 1])
        tq += ca.sum1(A[stick, 0, 2] * G[:, 0] + A[stick, 1, 2] * G[:, 1])
        opti.subject_to(G[:, 0] ** 2 + G[:, 1] ** 2 <= f[stick] ** 2)
    opti.subject_to(opti.bounded(-half[out], phi, half[out]))
    opti.minimize(wx ** 2 + wy ** 2 + tq ** 2)
    opti.solver("ipopt", {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                          "ipopt.max_wall_time": float(time_limit), "ipopt.tol": 1e-14,
                          "ipopt.max_iter": 500})
    try:
        sol = opti.solve()
    except RuntimeError:
        sol = opti.debug
    F = F0.copy()
    ang = base + np.asarray(sol.value(phi)).reshape(-1)
    F[out] = f[out, None] * np.c_[np.cos(ang), np.sin(ang)]
    if stick.size:
        Gv = np.asarray(sol.value(G)).reshape(-1, 2)
        norms = np.hypot(Gv[:, 0], Gv[:, 1])
        F[stick] = Gv * np.minimum(1.0, f[stick] / np.maximum(norms, 1e-300))[:, None]
    w = np.einsum("nji,nj->i", A, F)
    return F, bool(np.hypot(np.hypot(w[0], w[1]), w[2]) <= 1e-12 * f.sum())


def _realize(a: np.ndarray, vmax: np.ndarray, inside: np.ndarray, F: np.ndarray,
             f: np.ndarray) -> np.ndarray:
    """Velocities: sticking legs at their body-point velocity; a slipping leg along its force
    direction ``u`` from ``a_i``, at the nearest point of its speed disc (a hair inside)."""
    v = a.copy()
    out = np.flatnonzero(~inside)
    for i in out:
        u = F[i] / max(np.hypot(*F[i]), 1e-300)
        p = float(a[i] @ u)
        disc = p * p - float(a[i] @ a[i]) + vmax[i] ** 2
        root = math.sqrt(max(disc, 0.0))
        lo, hi = -p - root, -p + root
        lam = lo + 1e-9 * (hi - lo)
        v[i] = a[i] + lam * u
    return v


def _finish(pos, f, velocities, xt, L, scale_v, tol, slipping, method, started, message,
            approximate=False) -> PlanarAllocationResult:
    contacts = PlanarContactSet(pos, velocities, f)
    eq = solve_equilibrium(contacts)
    d = eq.twist - xt
    error = float(max(np.hypot(d[0], d[1]), abs(d[2]) * L))
    s = contacts.slips(xt[:2], xt[2])
    dissipation = float(f @ np.hypot(s[:, 0], s[:, 1]))
    realized = eq.certified and error <= tol * scale_v and not approximate
    status = PlanarAllocationStatus.REALIZED if realized else PlanarAllocationStatus.APPROXIMATE
    velocities = np.asarray(velocities, dtype=float)
    velocities.setflags(write=False)
    return PlanarAllocationResult(
        velocities=velocities, contacts=contacts, target=xt, equilibrium=eq, error=error,
        bound=0.0, gap=error, status=status, certificate=None, slipping=slipping,
        dissipation=dissipation, method=method, wall_time=time.perf_counter() - started,
        message=message)


def _failed(n: int, xt: np.ndarray, started: float, message: str) -> PlanarAllocationResult:
    return PlanarAllocationResult(
        velocities=np.full((n, 2), np.nan), contacts=None, target=xt, equilibrium=None,
        error=math.inf, bound=0.0, gap=math.inf, status=PlanarAllocationStatus.SOLVER_ERROR,
        certificate=None, slipping=np.zeros(n, bool), dissipation=math.nan, method="socp",
        wall_time=time.perf_counter() - started, message=message)


# -- resistance targets ------------------------------------------------------------------------
def allocate_resistance(positions: Any, forces: Any, speed_limits: Any, target: Any,
                        resistance: Any, *, starts: int = 8, seed: int = 0,
                        time_limit: float = 30.0) -> PlanarAllocationResult:
    """Leg velocities that make ``target`` the equilibrium twist with the local resistance
    ``-dW/dx`` there close to ``resistance`` (a symmetric positive semi-definite 3 x 3 matrix:
    N s/m, N s, N m s).

    Each slipping leg adds ``(f_i / |s_i|) w_i w_i^T`` with ``w_i = A_i^T n_i``, ``n_i``
    perpendicular to its slip (docs/planar.md section 7): ipopt over the slip angles and
    stiffnesses ``k_i = f_i / |s_i|`` from ``starts`` random starts, with the balance at the
    target and the speed limits as constraints. The error ``|R - R_t|_F / |R_t|_F`` and the
    equilibrium are measured on the achieved contacts; no lower bound is certified.
    """
    import casadi as ca

    owner = "allocate_resistance"
    started = time.perf_counter()
    pos, f, vmax, xt, _ = _inputs(positions, forces, speed_limits, target, owner)
    Rt = as_float_array(resistance, "resistance", owner, ndim=2)
    if Rt.shape != (3, 3) or not np.allclose(Rt, Rt.T, rtol=1e-12, atol=0):
        raise ParameterError(parameter_message("resistance", owner, "be a symmetric 3 x 3 matrix",
                                               f"an array of shape {Rt.shape}"))
    starts = as_int(starts, "starts", owner, low=1)
    n = pos.shape[0]
    A, a = _twist_arrays(pos, xt)
    L = _scale_length(pos, f)
    norm_t = float(np.linalg.norm(Rt)) or 1.0
    rng = np.random.default_rng(seed)
    best = None
    for trial in range(starts):
        opti = ca.Opti()
        phi = opti.variable(n)
        lg = opti.variable(n)                       # log stiffness: k = exp(lg) > 0
        k = ca.exp(lg)
        c, s = ca.cos(phi), ca.sin(phi)
        R = ca.MX.zeros(3, 3)
        wx, wy, tq = 0, 0, 0
        cons = []
        for i in range(n):
            if f[i] == 0:
                continue
            nvec = ca.vertcat(-s[i], c[i])
            w = ca.vertcat(nvec[0], nvec[1], A[i, 0, 2] * nvec[0] + A[i, 1, 2] * nvec[1])
            R = R + k[i] * (w @ w.T)
            wx += f[i] * c[i]
            wy += f[i] * s[i]
            tq += f[i] * (A[i, 0, 2] * c[i] + A[i, 1, 2] * s[i])
            slip = f[i] / k[i]
            vx, vy = a[i, 0] + slip * c[i], a[i, 1] + slip * s[i]
            cons.append(vx ** 2 + vy ** 2 <= vmax[i] ** 2)
        opti.subject_to(wx == 0)
        opti.subject_to(wy == 0)
        opti.subject_to(tq / L == 0)
        for con in cons:
            opti.subject_to(con)
        diff = (R - Rt) / norm_t
        opti.minimize(ca.sumsqr(diff))
        opti.set_initial(phi, rng.uniform(-np.pi, np.pi, n))
        opti.set_initial(lg, np.log(np.maximum(np.trace(Rt) / max(n, 1), 1e-9)) * np.ones(n))
        opti.solver("ipopt", {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                              "ipopt.max_wall_time": float(time_limit) / starts, "ipopt.max_iter": 1000,
                              "ipopt.tol": 1e-12})
        try:
            sol = opti.solve()
        except RuntimeError:
            sol = opti.debug
        ph = np.asarray(sol.value(phi)).reshape(-1)
        kk = np.exp(np.asarray(sol.value(lg)).reshape(-1))
        slips = (f / kk)[:, None] * np.c_[np.cos(ph), np.sin(ph)]
        v = a + slips
        over = np.hypot(v[:, 0], v[:, 1]) > vmax * (1 + 1e-9)
        if np.any(over):
            v[over] *= (vmax[over] / np.hypot(v[over, 0], v[over, 1]))[:, None]
        contacts = PlanarContactSet(pos, v, f)
        Ra = contacts.resistance(xt[:2], xt[2])
        err = float(np.linalg.norm(Ra - Rt) / norm_t) if np.all(np.isfinite(Ra)) else math.inf
        eq = solve_equilibrium(contacts)
        d = eq.twist - xt
        twist_err = float(max(np.hypot(d[0], d[1]), abs(d[2]) * L))
        score = err + twist_err / max(float(np.min(vmax)), 1e-300)
        if best is None or score < best[0]:
            best = (score, v, contacts, eq, err, twist_err)
    _, v, contacts, eq, err, twist_err = best
    s = contacts.slips(xt[:2], xt[2])
    scale_v = max(float(np.hypot(xt[0], xt[1])), abs(xt[2]) * L, float(np.min(vmax)))
    ok = eq.certified and twist_err <= 1e-9 * scale_v
    v.setflags(write=False)
    return PlanarAllocationResult(
        velocities=v, contacts=contacts, target=xt, equilibrium=eq, error=err, bound=0.0, gap=err,
        status=PlanarAllocationStatus.REALIZED if ok and err <= 1e-6 else PlanarAllocationStatus.APPROXIMATE,
        certificate=None, slipping=np.hypot(s[:, 0], s[:, 1]) > 0,
        dissipation=float(f @ np.hypot(s[:, 0], s[:, 1])), method="ipopt",
        wall_time=time.perf_counter() - started,
        message=(f"resistance error {err:.3g} (relative Frobenius), twist error {twist_err:.3g} m/s; "
                 f"best of {starts} starts; no certified lower bound"))
