"""The convex program behind the planar equilibrium and the planar time step (private).

``P(x) = sum_i f_i |c_i - B_i x| + x^T Q x / 2 - b . x`` in scaled units; its dual variables
are the contact forces, and a dual-feasible point certifies the twist by its duality gap
(docs/planar.md section 2). :func:`solve_fast` (pseudo-Huber path following, an exact
polish, the certificate), :func:`solve_cvxpy` (the same as a second-order cone program) and
:func:`certify`."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from .._compiled import kernels

__all__ = ["NormSum", "Solution", "solve_fast", "solve_cvxpy", "certify"]

_EPS = float(np.finfo(float).eps)


@dataclass(frozen=True, eq=False)
class NormSum:
    """``P(x) = sum f_i |c_i - B_i x| + x^T Q x / 2 - b . x`` (scaled, see the module).

    Attributes
    ----------
    c : ndarray of shape (n, 2)
    B : ndarray of shape (n, 2, d)
    f : ndarray of shape (n,)
        Positive weights (lifted contacts are left out by the caller).
    Q : ndarray of shape (d, d) or None
    b : ndarray of shape (d,)
    """

    c: np.ndarray
    B: np.ndarray
    f: np.ndarray
    Q: np.ndarray | None
    b: np.ndarray

    @property
    def d(self) -> int:
        return int(self.B.shape[2])

    @property
    def n(self) -> int:
        return int(self.f.size)

    def _Qm(self) -> np.ndarray:
        return np.zeros((self.d, self.d)) if self.Q is None else self.Q

    def z(self, x: np.ndarray) -> np.ndarray:
        return self.c - (self.B.reshape(-1, self.d) @ x).reshape(-1, 2)

    def BT(self, g: np.ndarray) -> np.ndarray:
        """``sum_i B_i^T g_i``, shape (d,)."""
        return g.reshape(-1) @ self.B.reshape(-1, self.d)

    def gram(self) -> np.ndarray:
        """``sum_i f_i B_i^T B_i``, shape (d, d)."""
        flat = self.B.reshape(-1, self.d)
        return (flat * np.repeat(self.f, 2)[:, None]).T @ flat

    def Bx(self, x: np.ndarray) -> np.ndarray:
        """``B_i x`` of every contact, shape (n, 2)."""
        return (self.B.reshape(-1, self.d) @ x).reshape(-1, 2)

    def value(self, x: np.ndarray) -> float:
        z = self.z(x)
        total = float(np.sum(self.f * np.hypot(z[:, 0], z[:, 1])))
        if self.Q is not None:
            total += 0.5 * float(x @ self.Q @ x)
        return total - float(self.b @ x)

    def reduced(self, keep: np.ndarray, origin: np.ndarray, basis: np.ndarray) -> NormSum:
        """The problem in ``t`` on the affine set ``x = origin + basis t``, contacts ``keep``."""
        Bk = self.B[keep]
        c = self.c[keep] - (Bk.reshape(-1, self.d) @ origin).reshape(-1, 2)
        B = np.ascontiguousarray((Bk.reshape(-1, self.d) @ basis).reshape(Bk.shape[0], 2, -1))
        Q = None if self.Q is None else basis.T @ self.Q @ basis
        b = basis.T @ (self.b - (self._Qm() @ origin))
        return NormSum(np.ascontiguousarray(c), B, np.ascontiguousarray(self.f[keep]), Q, b)


@dataclass(frozen=True, eq=False)
class Solution:
    """A certified point of :class:`NormSum` (scaled units).

    Attributes
    ----------
    x : ndarray of shape (d,)
    g : ndarray of shape (n, 2)
        Dual-feasible contact forces (``|g_i| <= f_i``; balanced exactly when ``Q`` is None).
    gap : float
        ``P(x) - dual(g) >= 0``: ``x`` is within ``gap`` of the optimal value; with ``Q``,
        ``|x - x*|_Q <= sqrt(2 gap)``.
    residual : ndarray of shape (d,)
        Net wrench of the best admissible forces at ``x`` before the feasibility correction
        (0 exactly when ``x`` satisfies the set-valued optimality condition).
    stuck : ndarray of shape (n,), bool
        Contacts treated as sticking at ``x``.
    iterations : int
        Newton steps (or solver iterations).
    method : str
    """

    x: np.ndarray
    g: np.ndarray
    gap: float
    residual: np.ndarray
    stuck: np.ndarray
    iterations: int
    method: str


# -- the certificate ------------------------------------------------------------------------
def _stuck_forces(prob: NormSum, idx: np.ndarray, target: np.ndarray,
                  start: np.ndarray | None) -> np.ndarray:
    """Forces ``g_k`` (``|g_k| <= f_k``) of the sticking contacts ``idx`` whose wrench
    ``sum B_k^T g_k`` comes closest to ``target`` (least squares, then projected gradient
    when the least-squares forces leave their discs)."""
    Bk = prob.B[idx]                                     # (k, 2, d)
    fk = prob.f[idx]
    A = np.swapaxes(Bk, 1, 2).transpose(1, 0, 2).reshape(prob.d, -1)   # d x 2k: A g = sum B^T g
    g, *_ = np.linalg.lstsq(A, target, rcond=None)
    g = g.reshape(-1, 2)
    norms = np.hypot(g[:, 0], g[:, 1])
    if np.all(norms <= fk * (1 + 1e-12)):
        return g * np.minimum(1.0, fk / np.maximum(norms, 1e-300))[:, None]
    # Projected gradient (FISTA) on 0.5 |A g - target|^2 over the product of discs.
    lip = float(np.linalg.eigvalsh(A @ A.T)[-1]) or 1.0
    y = np.zeros_like(g) if start is None else start.copy()
    y *= np.minimum(1.0, fk / np.maximum(np.hypot(y[:, 0], y[:, 1]), 1e-300))[:, None]
    prev, tk = y.copy(), 1.0
    value = np.inf
    for _ in range(500):
        grad = (A.T @ (A @ y.ravel() - target)).reshape(-1, 2)
        new = y - grad / lip
        new *= np.minimum(1.0, fk / np.maximum(np.hypot(new[:, 0], new[:, 1]), 1e-300))[:, None]
        r = A @ new.ravel() - target
        new_value = float(r @ r)
        if new_value > value:                    # adaptive restart (O'Donoghue & Candes)
            tk = 1.0
        value = min(value, new_value)
        t_next = 0.5 * (1 + np.sqrt(1 + 4 * tk * tk))
        y = new + ((tk - 1) / t_next) * (new - prev)
        y *= np.minimum(1.0, fk / np.maximum(np.hypot(y[:, 0], y[:, 1]), 1e-300))[:, None]
        if np.max(np.abs(new - prev)) <= 1e-15 * max(1.0, float(np.max(fk))):
            prev = new
            break
        prev, tk = new, t_next
    return prev


def certify(prob: NormSum, x: np.ndarray, stuck: np.ndarray | None = None,
            g_hint: np.ndarray | None = None) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Duality gap of ``x`` with a dual-feasible ``g`` built from ``x``.

    Sliding contacts (not in ``stuck``, non-zero ``z_i``) get ``g_i = f_i z_i / |z_i|``;
    sticking ones the admissible forces that best balance the rest (:func:`_stuck_forces`).
    Without ``Q`` the balance ``sum B_i^T g_i = -b`` is then made exact by subtracting the
    least-norm distribution of the residual and shrinking into the discs (docs/planar.md
    section 2). Returns ``(gap, g, residual, stuck)``.
    """
    g = np.empty((prob.n, 2))
    stuck = np.zeros(prob.n, bool) if stuck is None else np.array(stuck, dtype=bool)
    # Sliding forces and the sum of the terms in one pass (a slip at the rounding of its own
    # terms counts as a stick: its direction is noise).
    point = np.ascontiguousarray(x, dtype=float)
    phi = float(kernels("planar", prob.n).slide_forces(prob.c, prob.B, prob.f, point, g, stuck))
    r_slide = prob.BT(g)
    if prob.Q is None:
        want = -prob.b
    else:
        want = prob.Q @ x - prob.b
    idx = np.flatnonzero(stuck)
    if idx.size:
        hint = None if g_hint is None else g_hint[idx]
        g[idx] = _stuck_forces(prob, idx, want - r_slide, hint)
    r = prob.BT(g)
    residual = r - want
    if prob.Q is None:
        gap, g = _balanced_gap(prob, x, g, residual, phi)
    else:
        rb = r + prob.b
        dual = float(g.ravel() @ prob.c.ravel()) - 0.5 * float(rb @ np.linalg.solve(prob.Q, rb))
        gap = phi + 0.5 * float(x @ prob.Q @ x) - float(prob.b @ x) - dual
    return max(gap, 0.0), g, residual, stuck


def _balanced_gap(prob: NormSum, x: np.ndarray, g: np.ndarray, residual: np.ndarray,
                  phi: float) -> tuple[float, np.ndarray]:
    """Make ``sum B^T g = -b`` exact: ``g' = (g - f B G^{-1} residual) / (1 + theta)``."""
    G = prob.gram()
    try:
        lam = np.linalg.solve(G, residual)
    except np.linalg.LinAlgError:
        lam = np.linalg.lstsq(G, residual, rcond=None)[0]
    Bl = prob.Bx(lam)
    theta = float(np.max(np.hypot(Bl[:, 0], Bl[:, 1])))
    g2 = (g - prob.f[:, None] * Bl) / (1.0 + theta)
    dual = float(g2.ravel() @ prob.c.ravel())
    # P(x) - dual: with b = 0 the dual objective is sum g . c.
    return phi - float(prob.b @ x) - dual, g2


# -- the fast solver ---------------------------------------------------------------------------
def _start(prob: NormSum) -> np.ndarray:
    """Least-squares start: minimizes ``sum f_i |c_i - B_i x|^2 + x^T Q x - 2 b x``."""
    G = prob.gram()
    rhs = prob.BT(prob.f[:, None] * prob.c)
    if prob.Q is not None:
        G = G + prob.Q
        rhs = rhs + prob.b
    return np.linalg.lstsq(G, rhs, rcond=None)[0]


def _newton(prob: NormSum, x: np.ndarray, mu: float, tol: float, max_iter: int,
            floor: float = 1e-12) -> int:
    """The kernel's damped Newton on ``prob`` (scaled data of order 1: a slip below
    ``floor`` gets the curvature of ``floor`` in the exact Hessian, the polish handles
    contacts that stick)."""
    Q = prob._Qm()
    return int(kernels("planar", prob.n * max(max_iter, 1)).newton(
        prob.c, prob.B, prob.f, Q, prob.b, x, mu, tol, max_iter, floor))


def _polish(prob: NormSum, x_bar: np.ndarray, stuck: np.ndarray) -> tuple[np.ndarray, int] | None:
    """Exact minimizer on the affine set where the contacts ``stuck`` do not slip (None when
    that set is empty)."""
    idx = np.flatnonzero(stuck)
    if idx.size == 0:
        x = x_bar.copy()
        return x, abs(_newton(prob, x, 0.0, 1e-30, 50))
    A = prob.B[idx].reshape(-1, prob.d)                 # B_K x = c_K
    rhs = prob.c[idx].reshape(-1)
    origin, *_ = np.linalg.lstsq(A, rhs, rcond=None)
    scale = max(1.0, float(np.max(np.abs(rhs))), float(np.max(np.abs(A))) * float(np.max(np.abs(origin))))
    if np.max(np.abs(A @ origin - rhs)) > 1e-11 * scale:
        return None
    _, sv, vt = np.linalg.svd(A, full_matrices=A.shape[0] < A.shape[1])     # vt: d x d
    rank = int(np.sum(sv > 1e-12 * sv[0])) if sv.size else 0
    basis = vt[rank:].T
    if basis.shape[1] == 0:
        return origin, 0
    keep = ~stuck
    if not np.any(keep):
        # Only the quadratic term is left on the affine set.
        if prob.Q is None:
            return origin, 0
        Qr = basis.T @ prob.Q @ basis
        t = np.linalg.solve(Qr, basis.T @ (prob.b - prob.Q @ origin))
        return origin + basis @ t, 0
    red = prob.reduced(keep, origin, basis)
    t = basis.T @ (x_bar - origin)
    steps = abs(_newton(red, t, 0.0, 1e-30, 50))
    return origin + basis @ t, steps


def _candidates(power: np.ndarray, zone_cut: float) -> list[np.ndarray]:
    """Candidate sets of sticking contacts from the terms ``f_i |z_i|`` at a point: those below
    ``zone_cut``, those small against the total at a few levels, the smallest one, none."""
    total = float(np.sum(power))
    candidates: list[np.ndarray] = []
    one = np.zeros(power.size, bool)
    one[int(np.argmin(power))] = True
    cuts = [zone_cut * total / max(total, 1e-300)] if zone_cut > 0 else []
    for zone in ([power <= c for c in cuts + [1e-12 * total, 1e-9 * total, 1e-6 * total,
                                             1e-3 * total]] + [one, np.zeros(power.size, bool)]):
        if not any(np.array_equal(zone, c) for c in candidates):
            candidates.append(zone)
    return candidates


def _polish_best(prob: NormSum, x: np.ndarray, candidates: list[np.ndarray], tol: float,
                 best: tuple, g_hint: np.ndarray | None) -> tuple[tuple, int]:
    """Polish on each candidate set, keep the smallest certified gap; stop once it is at
    the rounding level (``1e-3 tol``)."""
    steps_total = 0
    for stuck in candidates:
        polished = _polish(prob, x, stuck)
        if polished is None:
            continue
        xp, steps = polished
        steps_total += steps
        gap, g, res, st = certify(prob, xp, stuck, g_hint)
        if gap <= best[0]:
            best = (gap, xp, g, res, st)
        if gap <= 1e-3 * tol:
            break
    return best, steps_total


def solve_fast(prob: NormSum, tol: float, x0: np.ndarray | None = None) -> Solution:
    """Certified minimizer of ``P``: exact Newton, then exact polish on the contacts that
    stick, then (if still not certified) pseudo-Huber path following and the polish again.

    Parameters
    ----------
    prob : NormSum
    tol : float
        Wanted duality gap (scaled units: a fraction of ``F_tot`` times the speed scale).
    x0 : ndarray of shape (d,), optional
        Warm start (the previous time step); default the least-squares start.
    """
    x = _start(prob) if x0 is None else np.array(x0, dtype=float)
    fmean = float(np.mean(prob.f))
    # Exact Newton first (the optimum is usually a smooth point); accept when certified.
    trial = x.copy()
    iterations = abs(_newton(prob, trial, 0.0, 1e-30, 50))
    gap, g, res, st = certify(prob, trial)
    best = (gap, trial, g, res, st)
    if gap <= tol:
        return Solution(trial, g, gap, res, st, iterations, "newton")
    # Newton stalls at a kink: polish on the contacts that (nearly) stick there.
    z = prob.z(trial)
    best, steps = _polish_best(prob, trial, _candidates(prob.f * np.hypot(z[:, 0], z[:, 1]), 0.0),
                               tol, best, None)
    iterations += steps
    if best[0] <= tol:
        gap, x, g, res, st = best
        return Solution(x, g, gap, res, st, iterations, "newton")
    mu = 0.1 * fmean
    mu_end = max(0.05 * tol / prob.n, 1e-14 * fmean)
    while True:
        iterations += abs(_newton(prob, x, mu, 1e-3 * mu * prob.n if mu > mu_end else 1e-6 * mu, 50))
        z = prob.z(x)
        rho = np.hypot(z[:, 0], z[:, 1])
        q = np.hypot(mu, prob.f * rho)
        g_bar = ((prob.f * prob.f / q)[:, None]) * z                 # |g_i| < f_i: feasible
        if mu <= mu_end:
            break
        mu = max(0.1 * mu, mu_end)
    gap, g, res = _certify_given(prob, x, g_bar)
    if gap < best[0]:
        best = (gap, x.copy(), g, res, np.zeros(prob.n, bool))
    best, steps = _polish_best(prob, x, _candidates(prob.f * rho, 100.0 * mu), tol, best, g_bar)
    gap, x, g, res, st = best
    return Solution(x, g, gap, res, st, iterations + steps, "newton")


def _certify_given(prob: NormSum, x: np.ndarray, g: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Gap of ``x`` with given feasible forces ``g`` (the smoothed problem's)."""
    z = prob.z(x)
    phi = float(np.sum(prob.f * np.hypot(z[:, 0], z[:, 1])))
    r = prob.BT(g)
    if prob.Q is None:
        residual = r + prob.b
        gap, g2 = _balanced_gap(prob, x, g, residual, phi)
        return max(gap, 0.0), g2, residual
    want = prob.Q @ x - prob.b
    rb = r + prob.b
    dual = float(np.sum(g * prob.c)) - 0.5 * float(rb @ np.linalg.solve(prob.Q, rb))
    gap = phi + 0.5 * float(x @ prob.Q @ x) - float(prob.b @ x) - dual
    return max(gap, 0.0), g, r - want


# -- cvxpy ---------------------------------------------------------------------------------------
def solve_cvxpy(prob: NormSum, tol: float) -> Solution:
    """The second-order cone program in cvxpy (Clarabel, tight tolerances), certified by
    :func:`certify` from its primal ``x`` and its dual contact forces."""
    import cvxpy as cp

    n, d = prob.n, prob.d
    x = cp.Variable(d)
    t = cp.Variable(n)
    Z = prob.c - cp.reshape(prob.B.reshape(2 * n, d) @ x, (n, 2), order="C")
    cone = cp.SOC(t, Z, axis=1)
    objective = prob.f @ t - prob.b @ x
    if prob.Q is not None:
        objective = objective + 0.5 * cp.quad_form(x, cp.psd_wrap(prob.Q))
    problem = cp.Problem(cp.Minimize(objective), [cone])
    with warnings.catch_warnings():   # "may be inaccurate": the gap is certified below, not trusted
        warnings.simplefilter("ignore", UserWarning)
        problem.solve(solver="CLARABEL", tol_gap_abs=1e-13, tol_gap_rel=1e-13, tol_feas=1e-13,
                      tol_ktratio=1e-10, max_iter=200)
    if x.value is None:
        raise RuntimeError(f"cvxpy/Clarabel returned no solution (status {problem.status})")
    xv = np.asarray(x.value, dtype=float)
    dual = cone.dual_value
    g = -np.asarray(dual[1], dtype=float) if dual is not None else np.zeros((n, 2))
    norms = np.hypot(g[:, 0], g[:, 1])
    g = g * np.minimum(1.0, prob.f / np.maximum(norms, 1e-300))[:, None]
    gap, g2, res = _certify_given(prob, xv, g)
    iters = int(problem.solver_stats.num_iters or 0) if problem.solver_stats else 0
    z = prob.z(xv)
    stuck = prob.f * np.hypot(z[:, 0], z[:, 1]) <= 1e-9 * float(np.sum(prob.f))
    return Solution(xv, g2, gap, res, stuck, iters, "cvxpy")
