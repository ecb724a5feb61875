"""Kernels of the event roots of the lagging-motor engine.

The earliest root of many functions ``alpha + beta s + gamma x(lam, s) + delta x(mu, s) +
D s exp(-mu s)`` (``x = expm1_ratio``): brackets on monotone pieces, bisection at any scale,
Newton's or Brent's method; and the event functions of a body sliding free or stuck to a contact.
"""

from __future__ import annotations

import math

import numpy as np

from .segments import EPS, INF, expm1_ratio, sign
from .tables import SMALL

ARITHMETIC_HALVINGS = 53     # bisection: arithmetic midpoints first, then scale-free ones
MAX_HALVINGS = ARITHMETIC_HALVINGS + 64
BRENT_RTOL = 4.0 * EPS       # Brent's method: relative tolerance (scipy.optimize.brentq's least)
BRENT_XTOL = 5e-324          # ... no absolute floor: the smallest subnormal (math.ulp(0.0))
BRENT_MAXITER = 500

_IEEE = {"error_model": "numpy"}   # IEEE division: x / 0 is inf or NaN (as NumPy), never raises
#: The kernels of this module and their numba options (toolkit._compiled.load compiles them).
KERNELS = {"event_value": _IEEE, "event_slope": _IEEE, "event_inflection": _IEEE, "midpoint": _IEEE,
           "bisect": _IEEE, "newton_root": _IEEE, "brent_root": _IEEE, "polish_root": _IEEE,
           "all_zero": {}, "first_root_all": _IEEE, "first_root": _IEEE,
           "free_first_root": _IEEE, "stuck_first_root": _IEEE}


def event_value(alpha: float, beta: float, gamma: float, delta: float, lam: float, mu: float,
                D: float, s: float) -> float:
    """``g(s)`` of one event function (a zero ``D`` term is left out: it could only turn a
    ``-0.0`` into ``0.0``)."""
    total = alpha + beta * s
    total = total + gamma * expm1_ratio(lam, s)
    total = total + delta * expm1_ratio(mu, s)
    if D != 0.0:
        total = total + D * s * math.exp(-mu * s)
    return total


def event_slope(beta: float, gamma: float, delta: float, lam: float, mu: float, D: float,
                s: float) -> float:
    """``g'(s) = beta + gamma exp(-lam s) + delta exp(-mu s) + D (1 - mu s) exp(-mu s)``
    (a zero ``D`` term left out)."""
    decay = math.exp(-mu * s)
    slope = beta + gamma * math.exp(-lam * s) + delta * decay
    if D != 0.0:
        slope = slope + D * (1.0 - mu * s) * decay
    return slope


def event_inflection(gamma: float, delta: float, lam: float, mu: float, D: float) -> float:
    """The root of ``g''`` (at most one), NaN where there is none.

    ``g''(s) = -gamma lam exp(-lam s) - delta mu exp(-mu s)`` vanishes where
    ``exp((mu - lam) s) = -(delta mu) / (gamma lam)``; the ratio is formed from logarithms
    because the products overflow with lag ~ 1e-300 (``mu = 1e300``), and an overflowed
    ratio would lose the knot that splits ``g'`` into monotone pieces. At resonance
    (``lam == mu``, ``D != 0``): ``s = 2 / mu + (gamma + delta) / (D mu)``.
    """
    if D != 0.0:
        return (2.0 + (gamma + delta) / D) / mu
    if lam > 0 and mu > 0 and lam != mu:
        if (gamma > 0 and delta < 0) or (gamma < 0 and delta > 0):    # the ratio is positive
            log_ratio = (math.log(abs(delta)) - math.log(abs(gamma))
                         + (math.log(mu) - math.log(lam)))
            return log_ratio / (mu - lam)
    return math.nan


def midpoint(lo: float, hi: float, k: int, bits: np.ndarray, ibits: np.ndarray) -> float:
    """The midpoint of a bracket ``0 <= lo < hi`` (offsets, s) for the ``k``-th halving (from
    0); ``bits`` (2,) is scratch and ``ibits`` its int64 view.

    The first 53 halvings take the arithmetic midpoint, the fastest on a bracket on the scale
    of its root (the usual case): it ends on adjacent doubles within
    ``53 + log2(hi / root)`` halvings. A bracket still open after them is many binades wider
    than its root, e.g. a motor transient of ``tau = 1e-300`` s inside a bracket of 1.5 s,
    which arithmetic halving would reach only after about 1000 halvings. Later halvings are
    scale-free: the double halfway between the ends in the order of the doubles
    (non-negative doubles sort like their bit patterns), which ends on adjacent doubles within
    64 more halvings whatever the scale of the root.
    """
    if k < ARITHMETIC_HALVINGS:
        return 0.5 * (lo + hi)
    bits[0] = lo + 0.0                       # (+ 0.0 turns -0.0 into +0.0)
    bits[1] = hi
    a = ibits[0]
    ibits[0] = a + (ibits[1] - a) // 2
    return bits[0]


def bisect(alpha: float, beta: float, gamma: float, delta: float, lam: float, mu: float,
           D: float, lo: float, hi: float, derivative: bool, bits: np.ndarray,
           ibits: np.ndarray) -> float:
    """Bisection of ``g`` (``derivative``: of ``g'``) on a bracket ``[lo, hi]`` (a sign change,
    offsets ``>= 0``, s) to adjacent doubles at any scale (:func:`midpoint`); returns the
    upper end, which holds the new sign (or zero)."""
    if derivative:
        low = sign(event_slope(beta, gamma, delta, lam, mu, D, lo))
    else:
        low = sign(event_value(alpha, beta, gamma, delta, lam, mu, D, lo))
    for k in range(MAX_HALVINGS):
        mid = midpoint(lo, hi, k, bits, ibits)
        if not (mid > lo and mid < hi):
            break
        if derivative:
            here = sign(event_slope(beta, gamma, delta, lam, mu, D, mid))
        else:
            here = sign(event_value(alpha, beta, gamma, delta, lam, mu, D, mid))
        if here == low:
            lo = mid
        else:
            hi = mid
    return hi


def newton_root(alpha: float, beta: float, gamma: float, delta: float, lam: float, mu: float,
                lo: float, hi: float, g_lo: float, g_hi: float) -> tuple[float, bool]:
    """Newton's method for a root of a convex or concave ``g`` (``D = 0`` and one exponential
    term at most: ``g''`` keeps the sign of ``-(gamma lam + delta mu)``, not 0) in the
    sign-changing bracket ``[lo, hi]``, started from the end where ``g g'' > 0`` (Fourier's
    condition: the iterates then approach the root monotonically, quadratically near it,
    without leaving the bracket). Returns ``(root, True)`` to a few ulp, or ``(nan, False)``
    when the iteration does not settle (the caller then uses Brent's method)."""
    curvature = -(gamma * lam + delta * mu)
    if g_hi * curvature > 0:
        x, gx = hi, g_hi
    else:
        x, gx = lo, g_lo
    for _ in range(60):
        d = event_slope(beta, gamma, delta, lam, mu, 0.0, x)
        if d == 0.0 or not math.isfinite(d):
            return math.nan, False
        x_new = x - gx / d
        if not (lo <= x_new and x_new <= hi):
            return math.nan, False
        if abs(x_new - x) <= 4.0 * EPS * abs(x_new):
            return x_new, True
        x = x_new
        gx = event_value(alpha, beta, gamma, delta, lam, mu, 0.0, x)
        if gx == 0.0:
            return x, True
    return math.nan, False


def brent_root(alpha: float, beta: float, gamma: float, delta: float, lam: float, mu: float,
               D: float, lo: float, hi: float) -> tuple[float, bool]:
    """Brent's method (inverse quadratic extrapolation, secant and bisection steps: Brent
    1973, in the variant of ``scipy.optimize.brentq``) for the root of ``g`` in ``[lo, hi]``
    (a sign change): ``(root, converged)``. Tolerance ``BRENT_XTOL + BRENT_RTOL |x|``: no
    absolute floor, so the relative tolerance sets the precision at every scale (with lag
    1e-300 s the roots lie near 1e-300 s). Not converged after ``BRENT_MAXITER`` iterations,
    or a NaN value: ``(last iterate, False)``."""
    x_pre, x_cur = lo, hi
    f_pre = event_value(alpha, beta, gamma, delta, lam, mu, D, x_pre)
    f_cur = event_value(alpha, beta, gamma, delta, lam, mu, D, x_cur)
    if f_pre == 0.0:
        return x_pre, True
    if f_cur == 0.0:
        return x_cur, True
    if not (f_pre == f_pre and f_cur == f_cur):
        return x_cur, False
    if (math.copysign(1.0, f_pre) < 0) == (math.copysign(1.0, f_cur) < 0):
        return x_cur, False                                   # no sign change
    x_blk = f_blk = s_pre = s_cur = 0.0
    for _ in range(BRENT_MAXITER):
        if f_pre != 0.0 and f_cur != 0.0 and \
                (math.copysign(1.0, f_pre) < 0) != (math.copysign(1.0, f_cur) < 0):
            x_blk, f_blk = x_pre, f_pre                       # the bracket's other end
            s_pre = s_cur = x_cur - x_pre
        if abs(f_blk) < abs(f_cur):                           # x_cur: the best estimate
            x_pre, x_cur, x_blk = x_cur, x_blk, x_cur
            f_pre, f_cur, f_blk = f_cur, f_blk, f_cur
        tol = 0.5 * (BRENT_XTOL + BRENT_RTOL * abs(x_cur))
        s_bis = 0.5 * (x_blk - x_cur)
        if f_cur == 0.0 or abs(s_bis) < tol:
            return x_cur, True
        step = s_bis                                          # bisect, unless:
        if abs(s_pre) > tol and abs(f_cur) < abs(f_pre):
            if x_pre == x_blk:                                # secant
                s_try = -f_cur * (x_cur - x_pre) / (f_cur - f_pre)
            else:                                             # inverse quadratic
                d_pre = (f_pre - f_cur) / (x_pre - x_cur)
                d_blk = (f_blk - f_cur) / (x_blk - x_cur)
                s_try = -f_cur * (f_blk * d_blk - f_pre * d_pre) / (d_blk * d_pre * (f_blk - f_pre))
            limit = 3.0 * abs(s_bis) - tol
            if abs(s_pre) < limit:
                limit = abs(s_pre)
            if 2.0 * abs(s_try) < limit:
                step = s_try                                  # a good short step
                s_pre = s_cur
            else:
                s_pre = s_bis
        else:
            s_pre = s_bis
        s_cur = step
        x_pre, f_pre = x_cur, f_cur
        if abs(s_cur) > tol:
            x_cur += s_cur
        else:
            x_cur += tol if s_bis > 0 else -tol
        f_cur = event_value(alpha, beta, gamma, delta, lam, mu, D, x_cur)
        if f_cur != f_cur:
            return x_cur, False
    return x_cur, False


def polish_root(alpha: float, beta: float, gamma: float, delta: float, lam: float, mu: float,
                D: float, lo: float, hi: float, bits: np.ndarray, ibits: np.ndarray) -> float:
    """The root of ``g`` in the sign-changing bracket ``(lo, hi]`` to a few ulp: Newton's
    method when ``g`` is convex or concave (:func:`newton_root`), else or when Newton's does
    not settle Brent's method (:func:`brent_root`); if that does not converge either (a
    bracket spanning many binades, a stiff closed form without knots near its root), its
    last iterate may be far from the root: then bisection (:func:`bisect`), which ends on
    adjacent doubles at any scale."""
    g_lo = event_value(alpha, beta, gamma, delta, lam, mu, D, lo)
    g_hi = event_value(alpha, beta, gamma, delta, lam, mu, D, hi)
    if g_hi == 0.0 or g_lo * g_hi > 0.0:
        return hi          # (no sign change left at the ends: rounding of g; hi is a root)
    if D == 0.0 and (lam == 0.0 or mu == 0.0 or gamma == 0.0 or delta == 0.0) \
            and gamma * lam + delta * mu != 0.0:
        root, settled = newton_root(alpha, beta, gamma, delta, lam, mu, lo, hi, g_lo, g_hi)
        if settled:
            return root
    root, converged = brent_root(alpha, beta, gamma, delta, lam, mu, D, lo, hi)
    if converged:
        return root
    return bisect(alpha, beta, gamma, delta, lam, mu, D, lo, hi, False, bits, ibits)


def all_zero(values: np.ndarray, rows: np.ndarray, n: int) -> bool:
    """Whether ``values[rows[r]] == 0`` for every ``r < n``."""
    for r in range(n):
        if values[rows[r]] != 0.0:
            return False
    return True


def first_root_all(alpha: np.ndarray, beta: np.ndarray, gamma: np.ndarray, delta: np.ndarray,
                   lam: float, mu: float, D: float, horizon: float, rows: np.ndarray,
                   bits: np.ndarray, ibits: np.ndarray) -> tuple[float, int]:
    """:func:`first_root` over the functions ``rows`` (no prefilter): ``(s, p)`` with ``p``
    the position in ``rows`` of the function with the earliest root (``(inf, -1)``: none).

    ``g`` has at most one inflection, so ``g'`` is monotone on at most two pieces and ``g``
    on at most three: bracket on those pieces (knots ``0``, the inflection, the roots of
    ``g'``, ``horizon``) and take each function's first sign change. The candidates are
    halved together (:func:`midpoint`) until one can hold the earliest root, which is then
    polished on its own (:func:`polish_root`). A function with ``g(0) == 0`` (a contact tied
    at the start) has no root at 0 by construction.
    """
    n = rows.size
    # g' = base + amp exp(-rate s) for every function (no drag or compliance: lam = 0; ideal
    # motors: mu = 0; or one of the two terms absent): g is convex or concave, g' monotone.
    single = 0
    if D == 0.0:
        if lam == 0.0 or all_zero(gamma, rows, n):
            single = 1
        elif mu == 0.0 or all_zero(delta, rows, n):
            single = 2
    cand = np.empty(n, dtype=np.int64)          # candidates: position, bracket, sign at lo
    c_lo = np.empty(n)
    c_hi = np.empty(n)
    knots = np.empty(4)
    m = 0
    for r in range(n):
        i = rows[r]
        a, b, g, d = alpha[i], beta[i], gamma[i], delta[i]
        knots[0] = 0.0
        knots[1] = horizon
        knots[2] = horizon
        knots[3] = horizon
        if single != 0:
            if single == 1:
                base, amp, rate = b + (g if lam == 0.0 else 0.0), d, mu
            else:
                base, amp, rate = b + (d if mu == 0.0 else 0.0), g, lam
            if rate > 0 and (base > 0 or base < 0):
                ratio = amp / -base
                if ratio > 0:                        # g' = 0 at log(ratio) / rate
                    root = math.log(ratio) / rate
                    if root > 0 and root < horizon:
                        knots[2] = root
        else:
            infl = event_inflection(g, d, lam, mu, D)
            if infl > 0 and infl < horizon:
                knots[1] = infl
            # Roots of g' on [0, infl] and [infl, horizon].
            for col in range(2, 4):
                left = knots[0] if col == 2 else knots[1]
                right = knots[1] if col == 2 else horizon
                d_lo = event_slope(b, g, d, lam, mu, D, left)
                d_hi = event_slope(b, g, d, lam, mu, D, right)
                if d_lo * d_hi < 0:
                    knots[col] = bisect(a, b, g, d, lam, mu, D, left, right, True, bits, ibits)
        for p in range(1, 4):                         # sort the knots (insertion)
            x = knots[p]
            q = p
            while q > 0 and knots[q - 1] > x:
                knots[q] = knots[q - 1]
                q -= 1
            knots[q] = x
        v_lo = a                                      # exact g(0)
        for p in range(3):
            v_hi = event_value(a, b, g, d, lam, mu, D, knots[p + 1])
            if ((v_lo * v_hi < 0) or (v_hi == 0 and v_lo != 0)) and knots[p + 1] > knots[p]:
                cand[m] = r
                c_lo[m] = knots[p]
                c_hi[m] = knots[p + 1]
                m += 1
                break
            v_lo = v_hi
    if m == 0:
        return INF, -1
    # Halve the brackets together until one candidate can hold the earliest root.
    c_sign = np.empty(m)
    c_mid = np.empty(m)
    for c in range(m):
        i = rows[cand[c]]
        c_sign[c] = sign(event_value(alpha[i], beta[i], gamma[i], delta[i], lam, mu, D, c_lo[c]))
    k = 0
    while True:
        top = c_hi[0]
        for c in range(1, m):
            top = min(top, c_hi[c])
        kept = 0
        for c in range(m):                            # keep lo <= min(hi), in order
            if c_lo[c] <= top:
                cand[kept], c_lo[kept], c_hi[kept], c_sign[kept] = cand[c], c_lo[c], c_hi[c], \
                    c_sign[c]
                kept += 1
        m = kept
        if m == 1:
            break
        moving = False
        for c in range(m):
            c_mid[c] = midpoint(c_lo[c], c_hi[c], k, bits, ibits)
            moving = moving or (c_mid[c] > c_lo[c] and c_mid[c] < c_hi[c])
        k += 1
        if not moving:                                # adjacent doubles: the first lowest hi
            best = 0
            for c in range(1, m):
                if c_hi[c] < c_hi[best]:
                    best = c
            return c_hi[best], cand[best]
        for c in range(m):
            i = rows[cand[c]]
            here = sign(event_value(alpha[i], beta[i], gamma[i], delta[i], lam, mu, D, c_mid[c]))
            if here != c_sign[c]:
                c_hi[c] = c_mid[c]
            else:
                c_lo[c] = c_mid[c]
                c_sign[c] = here
    i = rows[cand[0]]
    root = polish_root(alpha[i], beta[i], gamma[i], delta[i], lam, mu, D, c_lo[0], c_hi[0],
                       bits, ibits)
    return root, cand[0]


def first_root(alpha: np.ndarray, beta: np.ndarray, gamma: np.ndarray, delta: np.ndarray,
               lam: float, mu: float, D: float, horizon: float) -> tuple[float, int]:
    """Earliest ``s`` in ``(0, horizon]`` (s) at which some event function ``g_i`` (rows of
    ``alpha``, ``beta``, ``gamma``, ``delta``, shape (n,)) changes sign or reaches zero, and
    the index ``i`` (``(inf, -1)`` when none does): :func:`first_root_all`, to a few ulp.

    With many functions, a cheap bound first: ``|g_i'| <= |beta| + |gamma| + |delta| + |D|``
    on ``s >= 0``, so ``g_i`` keeps its sign before ``|g_i(0)| / bound``. Only the functions
    whose bound falls inside a window are searched; the window doubles until a root is found
    inside it (then no other function can have an earlier one) or it covers the horizon.
    """
    n = alpha.size
    bits = np.zeros(2)
    ibits = bits.view(np.int64)
    if n <= SMALL:
        return first_root_all(alpha, beta, gamma, delta, lam, mu, D, horizon,
                              np.arange(n), bits, ibits)
    earliest = np.empty(n)
    lowest = np.empty(SMALL + 1)           # the SMALL + 1 lowest bounds, ascending
    count = 0
    for i in range(n):
        bound = abs(beta[i]) + abs(gamma[i]) + abs(delta[i]) + abs(D)
        if bound > 0:
            x = abs(alpha[i]) / bound
        else:
            x = 0.0 if alpha[i] == 0 else INF
        earliest[i] = x
        if x == x and (count <= SMALL or x < lowest[SMALL]):
            p = count if count <= SMALL else SMALL       # insert x, dropping the highest
            while p > 0 and lowest[p - 1] > x:
                lowest[p] = lowest[p - 1]
                p -= 1
            lowest[p] = x
            count = min(count + 1, SMALL + 1)
    window = lowest[SMALL] if count > SMALL else math.nan     # (NaN bounds sort last)
    rows = np.empty(n, dtype=np.int64)
    while True:
        picked = 0
        for i in range(n):
            if earliest[i] <= window:
                rows[picked] = i
                picked += 1
        s, p = first_root_all(alpha, beta, gamma, delta, lam, mu, D,
                              window if window < horizon else horizon, rows[:picked], bits,
                              ibits)
        if p >= 0:
            return s, rows[p]
        later = INF
        found = False
        for i in range(n):
            if earliest[i] > window:
                later = earliest[i] if not found else min(later, earliest[i])
                found = True
        if window >= horizon or not found:
            return INF, -1
        window = later if later > 2.0 * window else 2.0 * window


def free_first_root(v: np.ndarray, q: np.ndarray, e: np.ndarray, tied: np.ndarray, V: float,
                    r0: float, acc: float, lam: float, mu: float,
                    horizon: float) -> tuple[float, int]:
    """The first crossing of a body sliding free of every contact: :func:`first_root` of
    ``g_i(s) = V(s) - v_i(s)`` over ``(0, horizon]`` (s), the body's closed form
    ``V(s) = V + r0 x(lam, s)`` (m/s, ``r0`` m/s^2, ``lam`` 1/s) against contact ``i``'s
    ``v_i(s) = v_i + q_i s + e_i x(mu, s)`` (shape (n,): m/s, m/s^2, m/s^2), so
    ``alpha = V - v_i`` (0 where ``tied``: the body is on that contact now), ``beta = -q_i``,
    ``gamma = r0``, ``delta = -e_i``. A tied contact whose rate ``q_i + e_i`` is the body's
    acceleration ``acc`` (within ``1e-9`` relative) is grazed: ``beta = e_i - r0``, so that
    ``g_i'(0) = 0`` exactly."""
    n = v.size
    alpha = np.empty(n)
    beta = np.empty(n)
    gamma = np.empty(n)
    delta = np.empty(n)
    for i in range(n):
        alpha[i] = 0.0 if tied[i] else V - v[i]
        rate = q[i] + e[i]
        if tied[i] and abs(acc - rate) <= 1e-9 * (abs(acc) + abs(rate)):
            beta[i] = -(r0 - e[i])
        else:
            beta[i] = -q[i]
        gamma[i] = r0
        delta[i] = -e[i]
    return first_root(alpha, beta, gamma, delta, lam, mu, 0.0, horizon)


def stuck_first_root(v: np.ndarray, q: np.ndarray, e: np.ndarray, tied: np.ndarray,
                     group: np.ndarray, stuck: int, W: float, tol: float, h0: float, c: float,
                     m: float, mu: float, horizon: float) -> tuple[float, int, float]:
    """The first event of a body stuck to contact ``stuck`` (with the contacts of ``group``,
    which move with it): :func:`first_root` over ``(0, horizon]`` (s) of the crossings
    ``v_k(s) - v_i(s)`` of every other contact ``i`` (contact speeds
    ``v_i(s) = v_i + q_i s + e_i x(mu, s)``, shape (n,); ``alpha = 0`` where ``tied``) and of
    the stiction margins ``W + tol -+ h(s)``, with ``h(s) = h0 + c q_k s
    + e_k (c - m mu) x(mu, s)`` the force (N) the group must hold against (drag ``c`` N s/m,
    mass ``m`` kg), ``W`` (N) its stiction and ``tol`` (N) the tie tolerance.

    Returns ``(s, i, releasing)``: the time of the event, the contact crossed (or -1), and
    +1 / -1 when the body leaves the group upward / downward (``h`` exceeds ``W + tol`` / falls
    below ``-(W + tol)``; else 0); ``(inf, -1, 0.0)`` when nothing happens before ``horizon``.
    """
    n = v.size
    others = 0
    for i in range(n):
        if not group[i]:
            others += 1
    alpha = np.empty(others + 2)
    beta = np.empty(others + 2)
    gamma = np.zeros(others + 2)
    delta = np.empty(others + 2)
    rows = np.empty(others, dtype=np.int64)
    vc, qc, ec = v[stuck], q[stuck], e[stuck]
    k = 0
    for i in range(n):
        if not group[i]:
            alpha[k] = 0.0 if tied[i] else vc - v[i]
            beta[k] = qc - q[i]
            delta[k] = ec - e[i]
            rows[k] = i
            k += 1
    alpha[k] = W + tol - h0                       # h reaches +(W + tol): released upward
    beta[k] = c * qc
    delta[k] = ec * (c - m * mu)
    alpha[k + 1] = h0 + W + tol                   # h reaches -(W + tol): released downward
    beta[k + 1] = -c * qc
    delta[k + 1] = ec * (m * mu - c)
    s, p = first_root(alpha, beta, gamma, delta, 0.0, mu, 0.0, horizon)
    if p < 0:
        return s, -1, 0.0
    if p >= others:
        return s, -1, (1.0 if p == others else -1.0)
    return s, rows[p], 0.0
