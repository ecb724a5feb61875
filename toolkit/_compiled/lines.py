"""Kernels of quantized straight lines: the exact set of lines a run of counts allows.

A body moving at one constant speed ``v`` passes ``x0 + v tau_j`` at the sample times, and an
ideal encoder of count ``q`` reads ``floor(position / q)``: each reading confines ``(x0, v)`` to
a strip, and together they confine it to a convex polygon (:func:`clip_strip`,
:func:`extend_lines`). The kernels keep those polygons for the estimators' holds, test which
speeds they allow and when a reading must come (:func:`reach_seen`, :func:`seen_steps`,
:func:`behind`), and give their moments (:func:`line_moments`, :func:`sharper_lines`).
"""

from __future__ import annotations

import math

import numpy as np

from ..laws import quantization_variance

_INLINE = {"inline": "always"}

KERNELS = {"quantization_variance": {"error_model": "numpy"}, "clip_half": _INLINE, "clip_strip": {}, "extend_lines": {}, "reach": _INLINE, "reach_gaps": {}, "reach_seen": {}, "seen_steps": {},
           "behind": {}, "slice_x": _INLINE,
           "line_moments": {}, "area": _INLINE, "ride_moments": {}, "sharper_lines": {}}

# 3-point Gauss-Legendre on [-1, 1]: exact for polynomials of degree <= 5.
_GL_X = np.array([-math.sqrt(0.6), 0.0, math.sqrt(0.6)])
_GL_W = np.array([5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0])


def clip_half(poly: np.ndarray, n: int, a0: float, a1: float, bound: float, tol: float,
              out: np.ndarray) -> int:
    """``poly[:n]`` intersected with ``a0 x + a1 v <= bound`` into ``out``; the new count
    (0 when empty or degenerate; ``-1`` when ``out`` is too small). A vertex within ``tol``
    of the boundary counts as on it (kept, and no intersection is added next to it)."""
    m = 0
    cap = out.shape[0]
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        fp = a0 * poly[i, 0] + a1 * poly[i, 1] - bound
        fq = a0 * poly[j, 0] + a1 * poly[j, 1] - bound
        if fp <= tol:
            if m == cap:
                return -1
            out[m, 0] = poly[i, 0]
            out[m, 1] = poly[i, 1]
            m += 1
        if (fp < -tol and fq > tol) or (fq < -tol and fp > tol):
            if m == cap:
                return -1
            s = fp / (fp - fq)
            out[m, 0] = poly[i, 0] + s * (poly[j, 0] - poly[i, 0])
            out[m, 1] = poly[i, 1] + s * (poly[j, 1] - poly[i, 1])
            m += 1
    return m if m >= 3 else 0


def clip_strip(poly: np.ndarray, n: int, a0: float, a1: float, lo: float, hi: float,
               tol: float, scratch: np.ndarray, out: np.ndarray) -> int:
    """``poly[:n]`` intersected with the strip ``lo <= a0 x + a1 v <= hi``, written to
    ``out`` (``scratch`` holds the intermediate polygon; neither may alias ``poly``);
    vertices within ``tol`` (in units of ``a0 x + a1 v``) of a bound count as on it.

    Returns
    -------
    int
        The result's vertex count: 0 when empty (or degenerate, fewer than 3 vertices),
        ``-1`` when ``out`` or ``scratch`` has too few rows.
    """
    m = clip_half(poly, n, a0, a1, hi, tol, scratch)
    if m <= 0:
        return m
    return clip_half(scratch, m, -a0, -a1, -lo, tol, out)


def extend_lines(polys: np.ndarray, counts: np.ndarray, t: float, starts: np.ndarray,
                 readings: np.ndarray, first: np.ndarray, q: float, tol: float,
                 scratch: np.ndarray, out: np.ndarray) -> None:
    """Clip polygon ``i`` (``polys[i, :counts[i]]``; its line starts at ``starts[i]`` s with
    reading ``first[i]``) by reading ``readings[i]`` at ``t`` (s): the strip ``lo <= x + tau
    v <= lo + q``, ``tau = t - starts[i]``, ``lo = (readings[i] - first[i]) q``, in place, for
    every ``i`` with ``counts[i] > 0``; ``counts[i]`` becomes the new vertex count (0: no
    line fits the readings; -1: out of capacity).

    ``scratch`` and ``out`` have the shape of one polygon."""
    for i in range(polys.shape[0]):
        n = counts[i]
        if n <= 0:
            continue
        lo = (readings[i] - first[i]) * q
        m = clip_strip(polys[i], n, 1.0, t - starts[i], lo, lo + q, tol, scratch, out)
        counts[i] = m
        for r in range(max(m, 0)):
            polys[i, r, 0] = out[r, 0]
            polys[i, r, 1] = out[r, 1]


def reach_gaps(polys: np.ndarray, counts: np.ndarray, t: float, starts: np.ndarray,
               readings: np.ndarray, first: np.ndarray, q: float, motion: np.ndarray,
               out: np.ndarray) -> None:
    """For each polygon ``i`` with ``counts[i] > 0`` and ``motion[i] != 0``: the distance
    (m) from the cell one count short of ``readings[i]`` (against ``motion[i]``'s sign) to
    the nearest position ``x + tau v`` its lines reach at ``t`` (``tau = t - starts[i]``;
    positions less ``first[i] q``): ``min(x + tau v) - (readings[i] - first[i]) q`` moving
    up, ``(readings[i] + 1 - first[i]) q - max(x + tau v)`` moving down; ``-inf`` for the
    others. Into ``out`` (shape (n,))."""
    for i in range(polys.shape[0]):
        n = counts[i]
        if n <= 0 or motion[i] == 0.0:
            out[i] = -math.inf
            continue
        low, high = reach(polys[i], n, t - starts[i])
        if motion[i] > 0.0:
            out[i] = low - (readings[i] - first[i]) * q
        else:
            out[i] = (readings[i] + 1.0 - first[i]) * q - high


def reach(poly: np.ndarray, n: int, tau: float) -> tuple[float, float]:
    """The lowest and highest position ``x + tau v`` the polygon's lines reach at ``tau`` (a
    convex polygon's extremes are at its vertices)."""
    low, high = math.inf, -math.inf
    for r in range(n):
        x = poly[r, 0] + tau * poly[r, 1]
        low = min(low, x)
        high = max(high, x)
    return low, high


def behind(poly: np.ndarray, n: int, tau: float, lo: float, q: float, direction: float, gap: float) -> bool:
    """The strip ``[lo, lo + q)`` lies at least ``gap`` counts behind (against
    ``direction``) every position the polygon's lines reach at ``tau`` (:func:`reach`)."""
    low, high = reach(poly, n, tau)
    if direction > 0:
        return low - (lo + q) >= gap * q
    return lo - high >= gap * q


def reach_seen(polys: np.ndarray, counts: np.ndarray, t: float, starts: np.ndarray, readings: np.ndarray,
               first: np.ndarray, q: float, motion: np.ndarray, age: float, seen_gap: float, repair_gap: float,
               gaps: np.ndarray, seen: np.ndarray, repairable: np.ndarray) -> None:
    """:func:`reach_gaps` into ``gaps``, then per polygon whose window is at least ``age``
    old at ``t`` (``t - starts[i] >= age``): ``seen[i]`` where its gap is at least
    ``seen_gap``, ``repairable[i]`` where at least ``repair_gap`` (False for the younger)."""
    reach_gaps(polys, counts, t, starts, readings, first, q, motion, gaps)
    for i in range(polys.shape[0]):
        aged = t - starts[i] >= age
        seen[i] = aged and gaps[i] >= seen_gap
        repairable[i] = aged and gaps[i] >= repair_gap


def seen_steps(readings: np.ndarray, last: np.ndarray, seen: np.ndarray, counts: np.ndarray,
               unseen: np.ndarray) -> float:
    """``sum |readings[i] - last[i]|`` over the wheels ``seen`` whose line lives (``counts[i]
    > 0``): the transitions read there (counts); the live wheels' others are added to
    ``unseen[i]`` (in place: where a loss would have been absorbed)."""
    total = 0.0
    for i in range(readings.shape[0]):
        if counts[i] > 0:
            step = abs(readings[i] - last[i])
            if seen[i]:
                total += step
            else:
                unseen[i] += step
    return total


def slice_x(poly: np.ndarray, n: int, v: float) -> tuple[float, float]:
    """The polygon's ``x`` range at speed ``v`` (empty: ``lo > hi``)."""
    lo = math.inf
    hi = -math.inf
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        v0 = poly[i, 1]
        v1 = poly[j, 1]
        if v0 == v1:
            if v0 == v:
                lo = min(lo, poly[i, 0], poly[j, 0])
                hi = max(hi, poly[i, 0], poly[j, 0])
            continue
        if (v0 - v) * (v1 - v) <= 0.0:
            x = poly[i, 0] + (poly[j, 0] - poly[i, 0]) * ((v - v0) / (v1 - v0))
            lo = min(lo, x)
            hi = max(hi, x)
    return lo, hi


def line_moments(pc: np.ndarray, nc: int, pw: np.ndarray, nw: int, out: np.ndarray) -> float:
    """Moments of ``(x, v)`` with density proportional to ``1[(x, v) in pc] w(v)``, ``w`` the
    ``x``-width of ``pw`` at ``v`` (``nw = 0``: ``w = 1``).

    Writes ``out[:5] = (mean x, mean v, var x, cov xv, var v)`` and returns the total weight
    (``int w(v) width_pc(v) dv``; 0 when the two polygons share no speed, ``out`` then
    untouched). Central moments are summed about the mean of a first pass (no cancellation
    of large raw moments).
    """
    vlo = math.inf
    vhi = -math.inf
    for i in range(nc):
        vlo = min(vlo, pc[i, 1])
        vhi = max(vhi, pc[i, 1])
    if nw > 0:
        wlo = math.inf
        whi = -math.inf
        for i in range(nw):
            wlo = min(wlo, pw[i, 1])
            whi = max(whi, pw[i, 1])
        vlo = max(vlo, wlo)
        vhi = min(vhi, whi)
    if not vlo < vhi:
        return 0.0
    # Breakpoints: every vertex speed inside (vlo, vhi), sorted.
    br = np.empty(nc + nw + 2)
    nb = 0
    br[nb] = vlo
    nb += 1
    br[nb] = vhi
    nb += 1
    for i in range(nc):
        if vlo < pc[i, 1] < vhi:
            br[nb] = pc[i, 1]
            nb += 1
    for i in range(nw):
        if vlo < pw[i, 1] < vhi:
            br[nb] = pw[i, 1]
            nb += 1
    b = np.sort(br[:nb])
    total = 0.0
    sv = 0.0
    sx = 0.0
    # Pass 1: weight and means; pass 2: central second moments.
    for sweep in range(2):
        mv = sv / total if sweep == 1 else 0.0
        mx = sx / total if sweep == 1 else 0.0
        vxx = 0.0
        vxv = 0.0
        vvv = 0.0
        for k in range(nb - 1):
            a = b[k]
            c = b[k + 1]
            if not a < c:
                continue
            half = 0.5 * (c - a)
            mid = 0.5 * (a + c)
            for g in range(3):
                v = mid + half * _GL_X[g]
                lo, hi = slice_x(pc, nc, v)
                wc = hi - lo
                if not wc > 0.0:
                    continue
                ww = 1.0
                if nw > 0:
                    l2, h2 = slice_x(pw, nw, v)
                    ww = h2 - l2
                    if not ww > 0.0:
                        continue
                rho = half * _GL_W[g] * wc * ww
                xm = 0.5 * (lo + hi)
                if sweep == 0:
                    total += rho
                    sv += rho * v
                    sx += rho * xm
                else:
                    dv = v - mv
                    dx = xm - mx
                    # (the second size given, as imm's kernels give it: one compiled version)
                    vxx += rho * (dx * dx + quantization_variance(wc, 0.0))
                    vxv += rho * dx * dv
                    vvv += rho * dv * dv
        if sweep == 0 and not total > 0.0:
            return 0.0
        if sweep == 1:
            out[0] = mx
            out[1] = mv
            out[2] = vxx / total
            out[3] = vxv / total
            out[4] = vvv / total
    return total


def area(poly: np.ndarray, n: int) -> float:
    """Area of the counter-clockwise polygon ``poly[:n]`` (shoelace, about its first vertex)."""
    total = 0.0
    x0 = poly[0, 0]
    v0 = poly[0, 1]
    for i in range(1, n - 1):
        total += (poly[i, 0] - x0) * (poly[i + 1, 1] - v0) - (poly[i + 1, 0] - x0) * (poly[i, 1] - v0)
    return 0.5 * total


def ride_moments(pc: np.ndarray, nc: int, polys: np.ndarray, counts: np.ndarray,
                 prior: np.ndarray, moments: np.ndarray, evidence: np.ndarray,
                 out: np.ndarray) -> float:
    """The body's line ``pc[:nc]`` riding one of the wheels ``polys[i, :counts[i]]``, which one
    unknown (prior odds ``prior[i]``): the mixture of :func:`line_moments` over the wheels,
    each weighted by its prior times its evidence, the central polygon's width averaged over
    that wheel's uniform posterior of the speed (``line_moments``' weight over the wheel
    polygon's area: the likelihood of the central counts when the body rides that wheel).

    Writes each wheel's moments to ``moments[i]`` and posterior weight (prior times evidence)
    to ``evidence[i]`` (0 where its speeds miss the body's), the mixture's ``(mean x, mean v,
    var x, cov xv, var v)`` to ``out``; returns the total weight (0: the body rides none of
    them, ``out`` untouched).
    """
    vlo = math.inf
    vhi = -math.inf
    for i in range(nc):
        vlo = min(vlo, pc[i, 1])
        vhi = max(vhi, pc[i, 1])
    total = 0.0
    for i in range(polys.shape[0]):
        evidence[i] = 0.0
        n = counts[i]
        if n < 3 or not prior[i] > 0.0:
            continue
        wlo = math.inf
        whi = -math.inf
        for r in range(n):
            wlo = min(wlo, polys[i, r, 1])
            whi = max(whi, polys[i, r, 1])
        if not (wlo < vhi and vlo < whi):
            continue
        a = area(polys[i], n)
        if not a > 0.0:
            continue
        w = line_moments(pc, nc, polys[i], n, moments[i])
        if w > 0.0:
            evidence[i] = prior[i] * (w / a)
            total += evidence[i]
    if not total > 0.0:
        return 0.0
    mx = 0.0
    mv = 0.0
    for i in range(polys.shape[0]):
        if evidence[i] > 0.0:
            p = evidence[i] / total
            mx += p * moments[i, 0]
            mv += p * moments[i, 1]
    vxx = 0.0
    vxv = 0.0
    vvv = 0.0
    for i in range(polys.shape[0]):
        if evidence[i] > 0.0:
            p = evidence[i] / total
            dx = moments[i, 0] - mx
            dv = moments[i, 1] - mv
            vxx += p * (moments[i, 2] + dx * dx)
            vxv += p * (moments[i, 3] + dx * dv)
            vvv += p * (moments[i, 4] + dv * dv)
    out[0] = mx
    out[1] = mv
    out[2] = vxx
    out[3] = vxv
    out[4] = vvv
    return total


def sharper_lines(polys, counts, which, empty, out, track, var):  # noqa: ANN001, ANN201 (numba kernel)
    """For each wheel ``k`` of ``which`` (in order) whose window holds three readings or more
    and whose polygon ``polys[k]`` (``counts[k]`` vertices) has a positive area: the speed's
    uniform posterior over it (:func:`line_moments`, into ``out``); where its variance is below
    ``var[k]``, the contact's ``track[:, k]`` (start and target, m/s) becomes its mean and
    ``var[k]`` its variance (in place). ``empty`` a ``(1, 2)`` array (no second polygon)."""
    for a in range(which.shape[0]):
        k = which[a]
        if counts[k] >= 3 and line_moments(polys[k], counts[k], empty, 0, out) > 0.0:
            v = out[1]
            w = out[4]
            if w < var[k]:
                track[0, k] = v
                track[1, k] = v
                var[k] = w
