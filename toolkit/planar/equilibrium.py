"""The equilibrium of planar contacts: the twist at which their forces and torques balance.

The equilibrium twist minimizes the convex dissipation potential
``Phi(V, omega) = sum f_i |D_i^T (v_i - V - omega J r_i)|``; with ``omega = 0`` fixed
(translation only) it is the weighted geometric median (Fermat-Weber point) of the contact
velocities. Every result carries a certificate: contact forces inside their limit sets that
balance exactly, and the duality gap between ``Phi`` at the returned twist and the power of
those forces (docs/planar.md section 2). When every contact and the motion lie on one line
the equilibrium is the 1-D weighted median of :meth:`toolkit.ContactSet.equilibrium`, and
may be a segment.
"""

from __future__ import annotations

import enum
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ParameterError, ParameterTypeError, as_float, check_option, parameter_message
from ._socp import NormSum, Solution, certify, solve_cvxpy, solve_fast

__all__ = ["EquilibriumStatus", "PlanarEquilibrium", "METHODS", "solve_equilibrium",
           "weiszfeld", "speed_scale", "twist_problem"]

#: Methods of :func:`solve_equilibrium`.
METHODS = ("auto", "newton", "cvxpy", "weiszfeld")

_EPS = float(np.finfo(float).eps)


class EquilibriumStatus(enum.Enum):
    """Outcome of :func:`solve_equilibrium`; the value is the message shown to users."""

    OPTIMAL = "certified: the duality gap is within the tolerance"
    SEGMENT = ("certified: the contacts and the motion lie on one line and the equilibria form "
               "a segment (a zero-force band, exactly as in the 1-D toolkit); 'velocity' is its "
               "midpoint, 'segment' its two ends")
    INACCURATE = ("not certified: the duality gap is above the tolerance; 'gap' bounds how far "
                  "the dissipation at the returned twist may be above the optimum")
    SOLVER_ERROR = "the numerical back end failed; see 'message'"


@dataclass(frozen=True, eq=False)
class PlanarEquilibrium:
    """The equilibrium twist of a :class:`PlanarContactSet`, with its certificate.

    Attributes
    ----------
    velocity : ndarray of shape (2,), m/s
        Body velocity at the reference point.
    omega : float, rad/s
        Angular velocity (0 for a translation-only equilibrium).
    status : EquilibriumStatus
    gap : float, W
        Duality gap: ``Phi(velocity, omega)`` minus the power ``sum F_i . v_i`` of the
        certificate's contact forces; ``Phi`` at the returned twist is within ``gap`` of its
        minimum.
    tolerance : float, W
        The gap asked for: ``tol * total_force * speed_scale``.
    total_force : float, N
        ``F_tot``.
    speed_scale : float, m/s
        ``sum f_i |v_i - v_mean| / F_tot`` (force-weighted mean deviation of the contact
        velocities), at least ``1e-9 max |v_i|`` (1 m/s when all are 0): the scale of the gap.
    dissipation : float, W
        ``Phi`` at the returned twist.
    contact_forces : ndarray of shape (n, 2), N
        The certificate: each inside its contact's friction disc or ellipse, equal to
        ``f_i`` times the slip direction for the sliding contacts, balancing exactly
        (net force and torque zero to rounding).
    residual_force : float, N
        ``|sum F_i|`` of the best admissible forces at the twist before they are made to
        balance: how far the set-valued optimality condition ``0 in dPhi`` is from holding
        (0 exactly at a minimizer).
    residual_torque : float, N m
        The torque part of that residual (0 for translation only).
    stuck : ndarray of shape (n,), bool
        Contacts that do not slip at the equilibrium.
    segment : ndarray of shape (2, 2) or None, m/s
        The two ends of a segment of equilibria (status SEGMENT), else None.
    unique : bool or None
        True when the equilibrium is certified unique (the sliding contacts make the
        dissipation strictly convex there, or every contact sticks and they fix the twist:
        docs/planar.md section 2), False when it is known not to be (a segment, or
        contacts all at one point, where only ``V + omega J r`` is fixed), None when not
        established.
    translation_only : bool
    method : str
    iterations : int
    wall_time : float, s
    message : str
    """

    velocity: np.ndarray
    omega: float
    status: EquilibriumStatus
    gap: float
    tolerance: float
    total_force: float
    speed_scale: float
    dissipation: float
    contact_forces: np.ndarray
    residual_force: float
    residual_torque: float
    stuck: np.ndarray
    segment: np.ndarray | None
    unique: bool | None
    translation_only: bool
    method: str
    iterations: int
    wall_time: float
    message: str = ""

    @property
    def twist(self) -> np.ndarray:
        """``(Vx, Vy, omega)``, shape (3,)."""
        return np.array([self.velocity[0], self.velocity[1], self.omega])

    @property
    def certified(self) -> bool:
        """True when the status is OPTIMAL or SEGMENT."""
        return self.status in (EquilibriumStatus.OPTIMAL, EquilibriumStatus.SEGMENT)

    @property
    def relative_gap(self) -> float:
        """``gap / (F_tot speed_scale)``: the gap in units of the contacts' power scale."""
        return self.gap / (self.total_force * self.speed_scale)


_EPS = float(np.finfo(float).eps)


def _canonical(e: np.ndarray) -> np.ndarray:
    """A unit direction with round-off components snapped to 0 and its first non-zero
    component positive (so the x axis is exactly (1, 0))."""
    e = np.where(np.abs(e) <= 4 * _EPS, 0.0, e)
    if e[0] < 0 or (e[0] == 0 and e[1] < 0):
        e = -e
    return e / np.hypot(e[0], e[1]) + 0.0


def speed_scale(contacts: Any) -> float:
    """``sum f_i |v_i - v_mean| / F_tot`` (m/s), with ``v_mean`` the force-weighted mean
    velocity, but at least ``1e-9 max |v_i|`` (1 when every velocity is 0): the scale of the
    equilibrium's gap."""
    f = contacts.forces
    mean = f @ contacts.velocities / contacts.total_force
    dev = contacts.velocities - mean
    scale = float(f @ np.hypot(dev[:, 0], dev[:, 1])) / contacts.total_force
    # A spread at the rounding of the velocities themselves is no spread (equal velocities).
    scale = max(scale, 1e-9 * float(np.max(np.abs(contacts.velocities))))
    return scale if scale > 0 else 1.0


def twist_problem(contacts: Any, translation_only: bool, centre: np.ndarray,
                  S: float, L: float, shift: np.ndarray | None = None) -> tuple[NormSum, np.ndarray]:
    """The scaled :class:`~toolkit.planar._socp.NormSum` of the equilibrium (``Q`` None).

    Unknowns ``x = ((Vc - shift) / S, omega L / S)`` with ``Vc`` the velocity at ``centre``
    and ``shift`` a velocity taken off every contact (the mean: a Galilean change of frame that
    keeps the scaled data of order 1); weights ``f_i / F_tot``. Returns the problem and the
    indices of the contacts it holds (``f_i > 0``).
    """
    active = np.flatnonzero(contacts.forces > 0)
    f = contacts.forces[active] / contacts.total_force
    n = active.size
    r = (contacts.positions[active] - centre) / L
    d = 2 if translation_only else 3
    A = np.zeros((n, 2, d))
    A[:, 0, 0] = A[:, 1, 1] = 1.0
    if not translation_only:
        A[:, 0, 2] = -r[:, 1]
        A[:, 1, 2] = r[:, 0]
    v = (contacts.velocities[active] - (0.0 if shift is None else shift)) / S
    dmat = contacts.limit_factors
    if dmat.shape[0]:
        Dt = np.swapaxes(dmat[active], 1, 2)
        B = Dt @ A
        c = np.einsum("nij,nj->ni", Dt, v)
    else:
        B, c = A, v
    return NormSum(np.ascontiguousarray(c), np.ascontiguousarray(B), f, None, np.zeros(d)), active


def _collinear(points: np.ndarray) -> np.ndarray | None:
    """The unit direction of a line through every point, or None; all points equal (within
    ``16 eps`` of the largest coordinate) gives (1, 0)."""
    scale = float(np.max(np.abs(points)))
    rel = points - points[0]
    spread = np.hypot(rel[:, 0], rel[:, 1])
    far = float(np.max(spread))
    if far <= 16 * _EPS * scale:
        return np.array([1.0, 0.0])
    e = _canonical(rel[int(np.argmax(spread))] / far)
    if np.max(np.abs(rel[:, 0] * e[1] - rel[:, 1] * e[0])) > 16 * _EPS * scale:
        return None
    return e


def solve_equilibrium(contacts: Any, translation_only: bool = False, *,
                      method: str = "auto", tol: float = 1e-10) -> PlanarEquilibrium:
    """The equilibrium twist (or velocity) of planar contacts, certified.

    Parameters
    ----------
    contacts : PlanarContactSet
    translation_only : bool
        Fix ``omega = 0``: the weighted geometric median of the contact velocities (in the
        norms of the limit surfaces when anisotropic); positions do not matter.
    method : {"auto", "newton", "cvxpy", "weiszfeld"}
        ``"newton"``: Newton's method on the exact potential, then (if that is not
        certified) pseudo-Huber path following and an exact polish on the contacts that
        stick (a generalized Vardi-Zhang test); ``"cvxpy"``: the second-order cone program
        (Clarabel); ``"weiszfeld"``: Weiszfeld's iteration with the Vardi-Zhang step at data
        points (translation only, isotropic); ``"auto"``: the exact 1-D reduction when it
        applies, else ``"newton"``, then ``"cvxpy"`` if that is not certified.
    tol : float
        Certify when ``gap <= tol * F_tot * speed_scale`` (``> 0``).

    Returns
    -------
    PlanarEquilibrium
    """
    owner = "PlanarContactSet.equilibrium"
    if not all(hasattr(contacts, name) for name in ("velocities", "forces", "limit_factors", "line_reduction")):
        raise ParameterTypeError(parameter_message("contacts", owner, "be a PlanarContactSet", contacts))
    if not isinstance(translation_only, (bool, np.bool_)):
        raise ParameterTypeError(parameter_message("translation_only", owner, "be a bool", translation_only))
    check_option(method, "method", owner, METHODS)
    tol = as_float(tol, "tol", owner, low=0.0, low_open=True)
    if method == "weiszfeld" and not translation_only:
        raise ParameterError(parameter_message(
            "method", owner, "be 'weiszfeld' only with translation_only=True (the geometric "
            "median)", method))
    if method == "weiszfeld" and not contacts.isotropic:
        raise ParameterError(parameter_message(
            "method", owner, "be 'weiszfeld' only for isotropic contacts", method))
    started = time.perf_counter()
    S = speed_scale(contacts)
    if method == "auto":
        reduced = _reduce_1d(contacts, bool(translation_only), S, tol, started)
        if reduced is not None:
            return reduced
    centre = contacts.forces @ contacts.positions / contacts.total_force
    rel = contacts.positions - centre
    L = float(np.max(np.hypot(rel[:, 0], rel[:, 1]))) or 1.0
    mean = contacts.forces @ contacts.velocities / contacts.total_force
    prob, active = twist_problem(contacts, bool(translation_only), centre, S, L, mean)
    scaled_tol = tol
    message = ""
    try:
        if method == "weiszfeld":
            sol = _weiszfeld_solution(prob)
        elif method == "cvxpy":
            sol = solve_cvxpy(prob, scaled_tol)
        else:
            sol = solve_fast(prob, scaled_tol)
            if method == "auto" and sol.gap > scaled_tol:
                other = solve_cvxpy(prob, scaled_tol)
                if other.gap < sol.gap:
                    sol = other
    except Exception as error:          # a back end that fails: a status, not a traceback
        return _failed(contacts, translation_only, S, tol, method, started, str(error))
    return _result(contacts, bool(translation_only), prob, active, sol, centre, S, L, tol,
                   started, message, shift=mean)


def _result(contacts: Any, translation_only: bool, prob: NormSum, active: np.ndarray,
            sol: Solution, centre: np.ndarray, S: float, L: float, tol: float, started: float,
            message: str, segment: np.ndarray | None = None, unique: bool | None = None,
            velocity: np.ndarray | None = None, shift: np.ndarray | None = None) -> PlanarEquilibrium:
    F = contacts.total_force
    x = sol.x
    if velocity is None:
        omega = 0.0 if translation_only else float(x[2] * S / L)
        Vc = x[:2] * S + shift                       # (given whenever velocity is not)
        # Velocity at the reference point: V = Vc - omega J centre.
        velocity = np.array([Vc[0] + omega * centre[1], Vc[1] - omega * centre[0]])
    else:
        omega = 0.0
    if translation_only and np.any(sol.stuck):
        # A contact that does not slip fixes the velocity: its own, exactly (a data point).
        velocity = np.array(contacts.velocities[active[np.flatnonzero(sol.stuck)[0]]])
    forces = np.zeros((contacts.n, 2))
    dmat = contacts.limit_factors
    g = sol.g * F
    forces[active] = np.einsum("nij,nj->ni", dmat[active], g) if dmat.shape[0] else g
    stuck = np.zeros(contacts.n, bool)
    stuck[active] = sol.stuck
    res = sol.residual
    residual_force = float(np.hypot(res[0], res[1]) * F)
    residual_torque = 0.0 if translation_only else float(abs(res[2]) * F * L)
    gap = float(sol.gap * F * S)
    tolerance = tol * F * S
    if unique is None and segment is None:
        unique = _unique(prob, sol)
    status = (EquilibriumStatus.SEGMENT if segment is not None else
              EquilibriumStatus.OPTIMAL if gap <= tolerance else EquilibriumStatus.INACCURATE)
    velocity = np.array(velocity)                   # (a copy, made read-only below)
    velocity.setflags(write=False)
    forces.setflags(write=False)
    stuck.setflags(write=False)
    return PlanarEquilibrium(
        velocity=velocity, omega=omega, status=status, gap=gap, tolerance=tolerance,
        total_force=F, speed_scale=S, dissipation=float(contacts.dissipation(velocity, omega)),
        contact_forces=forces, residual_force=residual_force, residual_torque=residual_torque,
        stuck=stuck, segment=segment, unique=unique, translation_only=translation_only,
        method=sol.method, iterations=sol.iterations, wall_time=time.perf_counter() - started,
        message=message)


def _unique(prob: NormSum, sol: Solution) -> bool | None:
    """True when the Hessian of the sliding contacts' terms is positive definite at the
    solution (two minimizers would make every sliding term affine on the segment between
    them, i.e. that Hessian singular along it); None otherwise."""
    z = prob.z(sol.x)
    rho = np.hypot(z[:, 0], z[:, 1])
    slide = ~sol.stuck & (rho > 0)
    if not np.any(slide):
        # Every contact sticks (Phi = 0): another minimizer would make them all stick too,
        # so the twist is unique exactly when the stuck contacts fix it (B of full column
        # rank); otherwise every twist along B's null space is a minimizer too (known False).
        flat = prob.B.reshape(-1, prob.d)
        return bool(np.linalg.matrix_rank(flat) == prob.d)
    u = z[slide] / rho[slide, None]
    perp = np.stack((-u[:, 1], u[:, 0]), axis=1)                 # I - u u^T = perp perp^T
    rows = np.einsum("ni,nij->nj", perp, prob.B[slide]) * np.sqrt(prob.f[slide] / rho[slide])[:, None]
    H = rows.T @ rows
    eig = np.linalg.eigvalsh(H)
    return bool(eig[0] > 1e-9 * eig[-1]) or None


def _failed(contacts: Any, translation_only: bool, S: float, tol: float,
            method: str, started: float, message: str) -> PlanarEquilibrium:
    nan2 = np.full(2, np.nan)
    return PlanarEquilibrium(
        velocity=nan2, omega=math.nan, status=EquilibriumStatus.SOLVER_ERROR,
        gap=math.inf, tolerance=tol * contacts.total_force * S,
        total_force=contacts.total_force, speed_scale=S,
        dissipation=math.nan, contact_forces=np.full((contacts.n, 2), np.nan),
        residual_force=math.nan, residual_torque=math.nan,
        stuck=np.zeros(contacts.n, bool), segment=None, unique=None,
        translation_only=bool(translation_only), method=method, iterations=0,
        wall_time=time.perf_counter() - started, message=message)


# -- the exact 1-D reduction ------------------------------------------------------------------
def _reduce_1d(contacts: Any, translation_only: bool, S: float, tol: float,
               started: float) -> PlanarEquilibrium | None:
    """The equilibrium through :meth:`toolkit.ContactSet.equilibrium` when the problem is 1-D.

    Translation only: the velocities lie on one line ``p + u e`` (and each limit surface has
    ``e`` as an axis). Full twist: :meth:`PlanarContactSet.line_reduction` holds (positions
    on a line, velocities along it) with at least two distinct positions, so ``omega = 0``.
    The ends of the equilibrium set are contact velocities, returned exactly.
    """
    from ..model import ContactSet

    active = np.flatnonzero(contacts.forces > 0)
    if translation_only:
        e = _collinear(contacts.velocities[active])
        if e is None:
            return None
        weights = contacts.line_weights(e)
        if weights is None:
            return None
        speeds = contacts.velocities @ e
        line1d = ContactSet(speeds, weights)
    else:
        reduction = contacts.line_reduction()
        if reduction is None:
            return None
        rel = contacts.positions[active] - contacts.positions[active[0]]
        if not np.max(np.hypot(rel[:, 0], rel[:, 1])) > 0:
            return None                          # one point: rotation free, solved in general
        line1d = reduction.contacts
        e = reduction.direction
        speeds = line1d.speeds
    lo, hi = line1d.equilibrium()
    ends = []
    for value in (lo, hi):
        k = int(np.flatnonzero((speeds == value) & (contacts.forces > 0))[0])
        ends.append(np.array(contacts.velocities[k]) if translation_only
                    else value * e + 0.0)
    segment = np.array(ends) if hi > lo else None
    velocity = ends[0] if hi == lo else 0.5 * (ends[0] + ends[1])
    # The certificate of the general problem at the 1-D answer (exact: gap 0 to rounding).
    centre = contacts.forces @ contacts.positions / contacts.total_force
    rel = contacts.positions - centre
    L = float(np.max(np.hypot(rel[:, 0], rel[:, 1]))) or 1.0
    mean = contacts.forces @ contacts.velocities / contacts.total_force
    prob, act = twist_problem(contacts, translation_only, centre, S, L, mean)
    Vc = (velocity - mean) / S                                # omega = 0: Vc = V
    x = Vc if translation_only else np.array([Vc[0], Vc[1], 0.0])
    gap, g, residual, stuck = certify(prob, x)
    sol = Solution(x, g, gap, residual, stuck, 0, "median-1d")
    return _result(contacts, translation_only, prob, act, sol, centre, S, L, tol, started,
                   "contacts and motion on one line: the 1-D weighted median", segment=segment,
                   unique=segment is None, velocity=velocity)


# -- Weiszfeld ---------------------------------------------------------------------------------
def weiszfeld(points: Any, weights: Any = None, *, tol: float = 1e-13,
              max_iter: int = 100_000) -> tuple[np.ndarray, int]:
    """Weighted geometric median by Weiszfeld's iteration with Vardi and Zhang's step at data
    points (Vardi & Zhang, PNAS 97, 1423 (2000)).

    Parameters
    ----------
    points : array_like of shape (n, 2)
    weights : array_like of shape (n,), positive, optional (default 1)
    tol : float
        Stop when a step moves less than ``tol`` times the points' spread.
    max_iter : int

    Returns
    -------
    (median, iterations) : ndarray of shape (2,), int
        The iteration converges linearly (sublinearly towards a data point that is not the
        median): a baseline and a second method, not the fast path.
    """
    P = np.asarray(points)                  # (integers as well: every step below is in floats)
    w = np.ones(len(P)) if weights is None else np.asarray(weights)
    if P.ndim != 2 or P.shape[1] != 2 or w.shape != (P.shape[0],) or np.any(w <= 0):
        raise ParameterError(parameter_message(
            "points", "weiszfeld", "have shape (n, 2) with n positive weights",
            f"shapes {P.shape} and {w.shape}"))
    spread = float(np.max(np.ptp(P, axis=0)))            # (0: every point is y, returned at once)
    y = w @ P / w.sum()
    for it in range(1, max_iter + 1):
        diff = P - y
        dist = np.hypot(diff[:, 0], diff[:, 1])
        at = dist == 0.0
        eta = float(w[at].sum())
        with np.errstate(divide="ignore"):
            inv = np.where(at, 0.0, w / dist)
        R = inv @ diff                                  # sum_{p_i != y} w_i (p_i - y)/|p_i - y|
        r = float(np.hypot(R[0], R[1]))
        if r <= eta:
            return y, it                                 # y is the median (a data point, or R = 0)
        T = inv @ P / inv.sum()                          # (some point is away from y here)
        new = (1 - eta / r) * T + (eta / r) * y          # (Weiszfeld's T when y is no data point)
        if np.max(np.abs(new - y)) <= tol * spread:
            return new, it
        y = new
    return y, max_iter


def _weiszfeld_solution(prob: NormSum) -> Solution:
    y, iterations = weiszfeld(prob.c, prob.f, tol=1e-15)
    gap, g, residual, stuck = certify(prob, y)
    return Solution(y, g, gap, residual, stuck, iterations, "weiszfeld")
