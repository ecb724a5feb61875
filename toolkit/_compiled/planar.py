"""Kernels of the planar contact model: plain Python over arrays, one source.

:func:`wrench`: net force and torque of planar Coulomb contacts at many body twists (the law
of :mod:`toolkit.planar.contacts`), and :func:`dissipation`, the potential it is minus the
gradient of; :func:`newton`: damped Newton's method on the smoothed potential of the planar
equilibrium for 1 to 3 unknowns, and :func:`slide_forces`. The callers
(:mod:`toolkit.planar`) keep validation, scaling, certificates and results.
"""

from __future__ import annotations

import math

import numpy as np

KERNELS = {"slip": {"inline": "always"}, "wrench": {}, "dissipation": {}, "terms": {},
           "value": {}, "newton": {}, "solve_small": {}, "slide_forces": {}}


def slip(positions: np.ndarray, velocities: np.ndarray, dmat: np.ndarray, aniso: bool, i: int,
         Vx: float, Vy: float, w: float) -> tuple[float, float]:
    """``z_i = D_i^T s_i`` of contact ``i``, ``s_i = v_i - V - w J r_i`` (``D_i = I``
    unless ``aniso``)."""
    sx = velocities[i, 0] - Vx + w * positions[i, 1]
    sy = velocities[i, 1] - Vy - w * positions[i, 0]
    if aniso:
        return (dmat[i, 0, 0] * sx + dmat[i, 1, 0] * sy, dmat[i, 0, 1] * sx + dmat[i, 1, 1] * sy)
    return sx, sy


def wrench(positions: np.ndarray, velocities: np.ndarray, forces: np.ndarray, dmat: np.ndarray,
           V: np.ndarray, omega: np.ndarray, out_force: np.ndarray, out_torque: np.ndarray) -> None:
    """Net force ``out_force[m]`` (N) and torque ``out_torque[m]`` (N m, about the origin of
    ``positions``) of n contacts at M twists ``(V[m], omega[m])``.

    Contact ``i`` at ``r_i`` with velocity ``v_i`` slips by ``s_i = v_i - V - omega J r_i``
    (``J r = (-r_y, r_x)``) and pushes with ``f_i D_i z_i / |z_i|``, ``z_i = D_i^T s_i``
    (``D_i = I`` when ``dmat`` has no rows: isotropic). A contact with ``z_i = 0`` exactly
    contributes 0 (the centre of its set-valued force).
    """
    n = forces.size
    M = omega.size
    aniso = dmat.shape[0] == n and n > 0
    for m in range(M):
        Vx, Vy, w = V[m, 0], V[m, 1], omega[m]
        fx = 0.0
        fy = 0.0
        tq = 0.0
        for i in range(n):
            f = forces[i]
            if f == 0.0:
                continue
            rx, ry = positions[i, 0], positions[i, 1]
            zx, zy = slip(positions, velocities, dmat, aniso, i, Vx, Vy, w)
            rho = math.hypot(zx, zy)
            if rho == 0.0:
                continue
            ux, uy = zx / rho, zy / rho
            if aniso:
                gx = f * (dmat[i, 0, 0] * ux + dmat[i, 0, 1] * uy)
                gy = f * (dmat[i, 1, 0] * ux + dmat[i, 1, 1] * uy)
            else:
                gx, gy = f * ux, f * uy
            fx += gx
            fy += gy
            tq += rx * gy - ry * gx
        out_force[m, 0] = fx
        out_force[m, 1] = fy
        out_torque[m] = tq


def dissipation(positions: np.ndarray, velocities: np.ndarray, forces: np.ndarray,
                dmat: np.ndarray, V: np.ndarray, omega: np.ndarray, out: np.ndarray) -> None:
    """The dissipation potential ``out[m] = sum_i f_i |D_i^T s_i|`` (W) at M twists."""
    n = forces.size
    M = omega.size
    aniso = dmat.shape[0] == n and n > 0
    for m in range(M):
        Vx, Vy, w = V[m, 0], V[m, 1], omega[m]
        total = 0.0
        for i in range(n):
            f = forces[i]
            if f == 0.0:
                continue
            zx, zy = slip(positions, velocities, dmat, aniso, i, Vx, Vy, w)
            total += f * math.hypot(zx, zy)
        out[m] = total


def value(c: np.ndarray, B: np.ndarray, f: np.ndarray, Q: np.ndarray, b: np.ndarray,
          x: np.ndarray, mu: float) -> float:
    """``P(x)`` (see the module docstring): smoothed with ``mu > 0``, exact with ``mu = 0``."""
    n = f.size
    d = x.size
    total = 0.0
    for i in range(n):
        z0 = c[i, 0]
        z1 = c[i, 1]
        for k in range(d):
            z0 -= B[i, 0, k] * x[k]
            z1 -= B[i, 1, k] * x[k]
        fr2 = f[i] * f[i] * (z0 * z0 + z1 * z1)
        if mu > 0.0:
            total += math.sqrt(mu * mu + fr2) - mu
        else:
            total += math.sqrt(fr2)
    for j in range(d):
        q = 0.0
        for k in range(d):
            q += Q[j, k] * x[k]
        total += 0.5 * q * x[j] - b[j] * x[j]
    return total


def terms(c: np.ndarray, B: np.ndarray, f: np.ndarray, Q: np.ndarray, b: np.ndarray,
          x: np.ndarray, mu: float, floor: float, grad: np.ndarray, hess: np.ndarray) -> float:
    """``P(x)``, its gradient (into ``grad``, shape (d,)) and Hessian (into ``hess``, (d, d)).

    With ``mu = 0`` a term with ``z_i = 0`` contributes nothing to the gradient (the
    subgradient 0) and the Hessian of a term uses ``max(|z_i|, floor)``.
    """
    n = f.size
    d = x.size
    total = 0.0
    for j in range(d):
        grad[j] = 0.0
        for k in range(d):
            hess[j, k] = 0.0
    for i in range(n):
        fi = f[i]
        if fi == 0.0:
            continue
        z0 = c[i, 0]
        z1 = c[i, 1]
        for k in range(d):
            z0 -= B[i, 0, k] * x[k]
            z1 -= B[i, 1, k] * x[k]
        rho2 = z0 * z0 + z1 * z1
        rho = math.sqrt(rho2)
        if mu > 0.0:
            q = math.sqrt(mu * mu + fi * fi * rho2)
            total += q - mu
            ga = fi * fi / q                      # gradient in z: ga z
            ha = ga                               # Hessian in z: ha I - e z z^T
            e = ga * fi * fi / (q * q)
        else:
            total += fi * rho
            if rho == 0.0:
                continue
            r = max(rho, floor)
            ga = fi / rho
            ha = fi / r
            e = fi / (r * rho2)
        g0 = ga * z0
        g1 = ga * z1
        h00 = ha - e * z0 * z0
        h01 = -e * z0 * z1
        h11 = ha - e * z1 * z1
        for j in range(d):
            bj0 = B[i, 0, j]
            bj1 = B[i, 1, j]
            grad[j] -= bj0 * g0 + bj1 * g1
            t0 = h00 * bj0 + h01 * bj1
            t1 = h01 * bj0 + h11 * bj1
            for k in range(j, d):
                hess[j, k] += t0 * B[i, 0, k] + t1 * B[i, 1, k]
    for j in range(d):
        q = 0.0
        for k in range(d):
            q += Q[j, k] * x[k]
        total += 0.5 * q * x[j] - b[j] * x[j]
        grad[j] += q - b[j]
        for k in range(j, d):
            hess[j, k] += Q[j, k]
    for j in range(d):
        for k in range(j):
            hess[j, k] = hess[k, j]
    return total


def solve_small(A: np.ndarray, r: np.ndarray, out: np.ndarray) -> bool:
    """Solve the symmetric positive semi-definite system ``A out = r`` (d <= 3) by Cholesky,
    a pivot at or below ``1e-14 trace(A)`` (lost to rounding) replaced by that shift; False
    when ``A`` is zero or not finite."""
    d = r.size
    L = np.zeros((d, d))
    scale = 0.0
    for j in range(d):
        scale += abs(A[j, j])
    if not (scale > 0.0) or not math.isfinite(scale):
        return False
    shift = 1e-14 * scale
    for j in range(d):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > shift:               # a pivot lost to rounding (or NaN): the shift itself
            s = shift
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, d):
            t = A[i, j]
            for k in range(j):
                t -= L[i, k] * L[j, k]
            L[i, j] = t / L[j, j]
    y = np.zeros(d)
    for i in range(d):
        t = r[i]
        for k in range(i):
            t -= L[i, k] * y[k]
        y[i] = t / L[i, i]
    for i in range(d - 1, -1, -1):
        t = y[i]
        for k in range(i + 1, d):
            t -= L[k, i] * out[k]
        out[i] = t / L[i, i]
    return True


def newton(c: np.ndarray, B: np.ndarray, f: np.ndarray, Q: np.ndarray, b: np.ndarray,
           x: np.ndarray, mu: float, tol: float, max_iter: int, floor: float) -> int:
    """Damped Newton's method on ``P`` from ``x`` (updated in place) at smoothing ``mu``.

    Stops when the Newton decrement ``-grad . step`` is at most ``tol``, when the step is
    below rounding (``4 eps max(1, |x|)``), after three full steps taken once the decrement
    is below the rounding of ``P`` (``8 eps |P|``, where backtracking cannot measure a
    decrease), when backtracking finds no decrease (40 halvings), or after ``max_iter``
    steps; returns the number of steps
    taken (negative when the last system could not be solved). The kernels use
    ``sqrt(z0^2 + z1^2)``: the callers scale the data to order 1.
    """
    d = x.size
    grad = np.zeros(d)
    hess = np.zeros((d, d))
    step = np.zeros(d)
    trial = np.zeros(d)
    blind = 0
    for it in range(max_iter):
        current = terms(c, B, f, Q, b, x, mu, floor, grad, hess)
        for j in range(d):
            grad[j] = -grad[j]
        if not solve_small(hess, grad, step):
            return -(it + 1)
        decrement = 0.0
        size = 0.0
        big = 1.0
        for j in range(d):
            decrement += grad[j] * step[j]
            size = max(size, abs(step[j]))
            big = max(big, abs(x[j]))
        if not decrement > tol:
            return it
        if size <= 4.0 * 2.220446049250313e-16 * big:
            return it
        if decrement <= 8.0 * 2.220446049250313e-16 * abs(current):
            # Below the rounding of P no decrease can be measured: full steps (the
            # quadratic region), at most three, then stop.
            for j in range(d):
                x[j] += step[j]
            blind += 1
            if blind >= 3:
                return it + 1
            continue
        s = 1.0
        accepted = False
        for _ in range(40):
            for j in range(d):
                trial[j] = x[j] + s * step[j]
            if value(c, B, f, Q, b, trial, mu) <= current - 0.25 * s * decrement:
                accepted = True
                break
            s *= 0.5
        if not accepted:
            return it
        for j in range(d):
            x[j] = trial[j]
    return max_iter


def slide_forces(c: np.ndarray, B: np.ndarray, f: np.ndarray, x: np.ndarray, g: np.ndarray,
                 stuck: np.ndarray) -> float:
    """The certificate's forces of the sliding contacts at ``x``: ``g_i = f_i z_i / |z_i|``
    (into ``g``, shape (n, 2)), ``stuck[i]`` set where ``|z_i|`` is at the rounding of its own
    terms (``64 eps (max |c_i| + max |B_i| max |x|)``: the direction is noise) with ``g_i = 0``
    there; returns ``sum f_i |z_i|``."""
    n = f.size
    d = x.size
    xmax = 0.0
    for k in range(d):
        xmax = max(xmax, abs(x[k]))
    total = 0.0
    for i in range(n):
        z0 = c[i, 0]
        z1 = c[i, 1]
        bmax = 0.0
        for k in range(d):
            z0 -= B[i, 0, k] * x[k]
            z1 -= B[i, 1, k] * x[k]
            bmax = max(bmax, abs(B[i, 0, k]), abs(B[i, 1, k]))
        rho = math.hypot(z0, z1)
        total += f[i] * rho
        size = max(abs(c[i, 0]), abs(c[i, 1])) + bmax * xmax
        if stuck[i] or rho <= 64.0 * 2.220446049250313e-16 * size:
            stuck[i] = True
            g[i, 0] = 0.0
            g[i, 1] = 0.0
        else:
            g[i, 0] = f[i] * z0 / rho
            g[i, 1] = f[i] * z1 / rho
    return total
