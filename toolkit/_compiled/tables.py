"""Kernels of the contact tables: staircases, prefix sums, the Coulomb force and the median.

The friction law evaluated from the prefix sums that :class:`toolkit.model.ContactSet` builds
(net force = magnitude above - magnitude below, snapped within the tie tolerance), a set's
staircase sorted into a table, and the weighted median of one or many sets.
"""

from __future__ import annotations

import math

import numpy as np

from ..laws import tie_tolerance
from .segments import INF, pairwise_sum

#: Contacts up to which the lowest index at a level is found by a scan (else one sort).
SMALL = 64

_IEEE = {"error_model": "numpy"}   # IEEE division: x / 0 is inf or NaN (as NumPy), never raises
#: The kernels of this module and their numba options (toolkit._compiled.load compiles them).
KERNELS = {"net_force": {}, "coulomb_force": {}, "lowest_contact": {}, "sorted_landscape": {},
           "contact_table": {}, "sorted_steps": {}, "staircase_sums": {},
           "staircase_median": {}, "median_row": {}, "median_edges": {}, "tie_tolerance": _IEEE}


def net_force(above: float, below: float, tol: float) -> float:
    """The net Coulomb force ``above - below`` (N: the magnitudes of the contacts faster and
    slower than the body), exactly 0 within ``tol`` (:attr:`ContactSet.tie_tolerance`)."""
    force = above - below
    return force if abs(force) > tol else 0.0


def coulomb_force(levels: np.ndarray, below: np.ndarray, above: np.ndarray, tol: float,
                  query: np.ndarray, out: np.ndarray) -> None:
    """``out[i] = F(query[i])`` (N) from a :class:`ContactSet`'s sorted distinct speeds
    ``levels`` (K,) and prefix sums ``below``, ``above`` (K + 1,); query speeds not NaN.

    ``left`` (the first level ``>= V``) is found through a bucket index: ``K`` equal buckets
    over ``[levels[0], levels[-1]]``, each holding the first level of its bucket or above, so
    a search is a binary search inside one bucket (``O(1)`` expected, ``O(log K)`` at worst).
    The bucket of a speed is a non-decreasing function of the speed, so the bucket bounds are
    exact bounds on ``left`` whatever the rounding. Few queries: plain binary search.
    """
    K = levels.size
    M = query.size
    lo, hi = levels[0], levels[K - 1]
    buckets = K if M * 8 >= K and K > 16 and hi > lo else 0
    start = np.empty(buckets + 2, dtype=np.int64)
    scale = buckets / (hi - lo) if buckets else 0.0
    if buckets:
        b = 0
        start[0] = 0
        for i in range(K):
            bi = min(int((levels[i] - lo) * scale), buckets - 1)
            while b < bi:
                b += 1
                start[b] = i
        while b <= buckets:
            b += 1
            start[b] = K
    for m in range(M):
        V = query[m]
        if not V >= lo:
            left = 0
        elif V > hi:
            left = K
        else:
            if buckets:
                bq = min(int((V - lo) * scale), buckets - 1)
                a, z = start[bq], start[bq + 1]
            else:
                a, z = 0, K
            while a < z:                     # first level >= V in [a, z)
                mid = (a + z) >> 1
                if levels[mid] < V:
                    a = mid + 1
                else:
                    z = mid
            left = a
        right = left + 1 if left < K and levels[left] == V else left
        out[m] = net_force(above[right], below[left], tol)


def lowest_contact(land: np.ndarray, speeds: np.ndarray, forces: np.ndarray,
                   first: np.ndarray, k: int) -> int:
    """The lowest index of the touching contacts (``f > 0``) at level ``land[0, k]``, kept in
    ``first`` (``-1``: not known yet; an empty ``first`` keeps nothing). Few contacts: a
    scan; many: one stable sort fills every level's entry, so a run of many events stays
    ``O(N log N)``."""
    if k < first.size and first[k] >= 0:
        return first[k]
    n = speeds.size
    if n <= SMALL:
        x = land[0, k]
        for i in range(n):
            if speeds[i] == x and forces[i] > 0:
                if k < first.size:
                    first[k] = i
                return i
    order = np.argsort(speeds, kind="mergesort")          # stable: lower indices first
    kk = 0
    for p in range(n):
        i = order[p]
        if forces[i] > 0:
            while land[0, kk] < speeds[i]:
                kk += 1
            if first[kk] < 0:
                first[kk] = i
    return first[k]


def sorted_landscape(speeds: np.ndarray, forces: np.ndarray, s: int, order: np.ndarray,
                     land: np.ndarray, first: np.ndarray) -> int:
    """The staircase of scene ``s`` (row ``s`` of ``speeds``, ``forces``) into the rows
    ``xs``, ``below``, ``above`` of ``land`` as :class:`ContactSet` builds them (the distinct
    speeds of the touching contacts ascending, the magnitude at each summed in index order,
    prefix sums from below and from above), and ``first``: the lowest contact index at each
    level; ``order`` (n,) is scratch. Returns ``K``."""
    K = sorted_steps(speeds, forces, s, order, land, first)
    staircase_sums(land, K)
    return K


def contact_table(speeds: np.ndarray, forces: np.ndarray, order: np.ndarray, land: np.ndarray,
                  first: np.ndarray) -> tuple[int, float]:
    """:class:`ContactSet`'s staircase of one set (``speeds``, ``forces`` of shape (1, n)) into
    ``land`` (3, n + 1) as :func:`sorted_landscape`, and the sum of its steps as NumPy sums
    them (:func:`pairwise_sum`: the set's ``F_tot``). Returns ``(K, F_tot)``; ``(-1, 0)``
    where touching contacts sit at both ``0.0`` and ``-0.0`` (equal speeds whose level NumPy's
    sort may take from either: the caller's NumPy way decides)."""
    zeros = 0
    for i in range(speeds.shape[1]):
        if forces[0, i] > 0 and speeds[0, i] == 0.0:
            zeros |= 2 if math.copysign(1.0, speeds[0, i]) < 0 else 1
    if zeros == 3:
        return -1, 0.0
    K = sorted_steps(speeds, forces, 0, order, land, first)
    total = pairwise_sum(land[2], 0, K)
    staircase_sums(land, K)
    return K, total


def sorted_steps(speeds: np.ndarray, forces: np.ndarray, s: int, order: np.ndarray,
                 land: np.ndarray, first: np.ndarray) -> int:
    """:func:`sorted_landscape`'s levels into ``land[0]`` and the magnitude at each (its
    steps, summed in index order) into ``land[2]``, ``first`` as there. Returns ``K``."""
    xs, above = land[0], land[2]
    n = speeds.shape[1]
    m = 0
    for i in range(n):                     # insertion sort of the touching contacts (stable)
        if forces[s, i] > 0:
            v = speeds[s, i]
            p = m
            while p > 0 and xs[p - 1] > v:
                xs[p] = xs[p - 1]
                order[p] = order[p - 1]
                p -= 1
            xs[p] = v
            order[p] = i
            m += 1
    K = 0
    for p in range(m):
        i = order[p]
        v = xs[p]
        if K == 0 or v != xs[K - 1]:
            xs[K] = v
            first[K] = i
            above[K] = forces[s, i]        # (the step at level K, summed below)
            K += 1
        else:
            above[K - 1] += forces[s, i]
    return K


def staircase_sums(land: np.ndarray, K: int) -> None:
    """The prefix sums of the steps ``land[2, :K]`` (:func:`sorted_steps`) from below into
    ``land[1, :K + 1]`` and from above into ``land[2, :K + 1]`` (``np.cumsum``'s order)."""
    below, above = land[1], land[2]
    below[0] = 0.0
    for k in range(K):                     # np.cumsum of the steps
        below[k + 1] = below[k] + above[k]
    acc = 0.0
    above[K] = 0.0
    for k in range(K - 1, -1, -1):         # np.cumsum of the reversed steps
        acc += above[k]
        above[k] = acc


def staircase_median(levels: np.ndarray, below: np.ndarray, above: np.ndarray, K: int,
                     tol: float) -> tuple[float, float]:
    """The weighted median ``(lo, hi)`` (m/s) of a staircase as :class:`ContactSet` holds it
    (``K >= 1`` distinct ``levels`` ascending, prefix sums ``below`` from below and ``above``
    from above): the set ``{V : 0 in F(V)}``. A plateau ``above[k] - below[k]`` within
    ``tol`` (:attr:`ContactSet.tie_tolerance`) is a zero-force band ``[levels[k-1],
    levels[k]]``; otherwise the force jumps over zero at one level ``(v, v)``. The one
    weighted median of the toolkit (docs/physics.md section 3)."""
    for k in range(1, K):
        if abs(above[k] - below[k]) <= tol:
            return levels[k - 1], levels[k]
    for k in range(K):
        if above[k + 1] - below[k + 1] < -tol:
            return levels[k], levels[k]
    return levels[K - 1], levels[K - 1]             # (not reached: plateau K is -F_tot)


def median_row(speeds: np.ndarray, forces: np.ndarray, F: float, row_s: np.ndarray,
               row_f: np.ndarray, order: np.ndarray, first: np.ndarray,
               land: np.ndarray) -> tuple[float, float]:
    """The weighted median ``(lo, hi)`` of one set of ``speeds`` (n,) (m/s) with magnitudes
    ``forces`` (n,) (N) and an outside force ``F`` (N) as a contact of magnitude ``|F|`` at
    ``sign(F) inf`` (a zero force changes nothing): the staircase built as
    :class:`ContactSet` builds it (:func:`sorted_landscape`) and read by
    :func:`staircase_median` with the tie tolerance ``4 (K + 1) eps F_tot``. Without any
    positive magnitude, the slowest speed twice. ``row_s``, ``row_f`` (1, n + 1), ``order``,
    ``first`` (n + 1,) and ``land`` (3, n + 2) are scratch."""
    n = speeds.shape[0]
    slowest = INF
    for i in range(n):
        row_s[0, i] = speeds[i]
        row_f[0, i] = forces[i]
        if speeds[i] < slowest:
            slowest = speeds[i]
    row_s[0, n] = INF if F >= 0.0 else -INF
    row_f[0, n] = abs(F)
    K = sorted_landscape(row_s, row_f, 0, order, land, first)
    if K == 0:
        return slowest, slowest
    return staircase_median(land[0], land[1], land[2], K, tie_tolerance(K, land[1, K]))


def median_edges(speeds: np.ndarray, forces: np.ndarray, outside: np.ndarray,
                 out: np.ndarray) -> None:
    """``out[r] = (lo, hi)``: :func:`median_row` of each row of ``speeds`` (R, n) (m/s) with
    magnitudes ``forces`` (n,) (N) and the outside force ``outside[r]`` (N); ``+-inf`` edges
    when ``|F|`` exceeds the contacts' total."""
    n = speeds.shape[1]
    row_s = np.empty((1, n + 1))
    row_f = np.empty((1, n + 1))
    order = np.empty(n + 1, dtype=np.int64)
    first = np.empty(n + 1, dtype=np.int64)
    land = np.empty((3, n + 2))
    for r in range(speeds.shape[0]):
        lo, hi = median_row(speeds[r], forces, outside[r], row_s, row_f, order, first, land)
        out[r, 0] = lo
        out[r, 1] = hi
