"""Tests of the mixed-integer allocation (toolkit/allocation/_milp.py).

The second method is a brute force written from the definition of the sup error: enumerate
every ordered grouping of the (active) contacts, and for each decide by bisection the
smallest ``t`` for which speeds exist. For a fixed grouping and ``t``, plateau ``k`` (force
``P_k``) must stay within ``t`` of the target on the open interval between its two groups
(inside the band); that is a set of one-sided bounds on the group speeds, and a feasible
choice exists on a finite set of candidate speeds (a dynamic program over the groups).
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator

import numpy as np
import pytest

from toolkit import ContactSet
from toolkit.allocation import (
    AllocationStatus,
    EquilibriumSpeed,
    ForceCurve,
    FrictionFraction,
    Viscosity,
    allocate,
)
from toolkit.allocation._evaluate import failure_margin

V_MAX = 0.35


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(4)


# -- brute force ---------------------------------------------------------------------------------
def _ordered_partitions(items: list[int]) -> Iterator[list[list[int]]]:
    if not items:
        yield []
        return
    first, rest = items[0], items[1:]
    for part in _ordered_partitions(rest):
        for k in range(len(part)):                      # join an existing group
            yield part[:k] + [[first, *part[k]]] + part[k + 1:]
        for k in range(len(part) + 1):                  # or open a new group
            yield part[:k] + [[first]] + part[k:]


def _acceptable(xs: np.ndarray, ys: np.ndarray, level: float, t: float) -> tuple[float, float]:
    """``[alpha, beta]``: the speeds of the band where the target is within ``t`` of ``level``
    (the target is piecewise linear and non-increasing; a repeated speed is an interval).
    Found by scanning the segments; ``(inf, -inf)`` when empty."""
    up, down = level + t, level - t
    alpha = beta = None
    for x0, x1, y0, y1 in zip(xs[:-1], xs[1:], ys[:-1], ys[1:]):
        if alpha is None and min(y0, y1) <= up:
            alpha = x0 if y0 <= up else x0 + (y0 - up) / (y0 - y1) * (x1 - x0)
        if max(y0, y1) >= down:
            beta = x1 if y1 >= down else x0 + (y0 - down) / (y0 - y1) * (x1 - x0)
    if alpha is None or beta is None or alpha > beta:
        return np.inf, -np.inf
    return alpha, beta


def _feasible(groups: list[tuple[float, float, float]], f_act: float, xs: np.ndarray,
              ys: np.ndarray, t: float) -> bool:
    lo, hi = xs[0], xs[-1]
    plateaus = f_act - 2 * np.concatenate(([0.0], np.cumsum([w for w, _, _ in groups])))
    spans = [_acceptable(xs, ys, p, t) for p in plateaus]
    consts = {lo, hi, *[c for s in spans for c in s if np.isfinite(c)],
              *[c for _, a, b in groups for c in (a, b) if np.isfinite(c)]}
    cand = np.array(sorted(consts))
    cand = np.concatenate(([cand[0] - 1.0], cand, [cand[-1] + 1.0]))

    def ok(k: int, left: float, right: float) -> bool:
        if not (left < right and left < hi and right > lo):
            return True                                     # plateau k is outside the band
        alpha, beta = spans[k]
        return max(left, lo) >= alpha and min(right, hi) <= beta

    reach = np.array([ok(0, -np.inf, c) for c in cand])
    for k, (_, a, b) in enumerate(groups):
        inside = (cand >= a) & (cand <= b)
        reach = inside & reach
        if k + 1 < len(groups):
            nxt = np.zeros_like(reach)
            for j, c in enumerate(cand):
                nxt[j] = any(reach[i] and cand[i] <= c and ok(k + 1, cand[i], c)
                             for i in range(j + 1))
            reach = nxt
    return any(reach[i] and ok(len(groups), cand[i], np.inf) for i in range(cand.size))


def brute_force(curve: ForceCurve, forces: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray,
                can_lift: np.ndarray) -> float:
    """Optimal sup error by enumeration (tiny n only)."""
    xs, ys = curve.speeds, curve.forces
    n = forces.size
    best = np.inf
    liftable = [i for i in range(n) if can_lift[i]]
    for r in range(len(liftable) + 1):
        for lifted in itertools.combinations(liftable, r):
            active = [i for i in range(n) if i not in lifted]
            if not active:
                continue
            f_act = float(forces[active].sum())
            for part in _ordered_partitions(active):
                groups = [(float(forces[g].sum()), float(box_lo[g].max()), float(box_hi[g].min()))
                          for g in part]
                if any(a > b for _, a, b in groups):
                    continue
                top = 2 * forces.sum() + 1
                if not _feasible(groups, f_act, xs, ys, min(best, top)):
                    continue
                low, high = 0.0, min(best, top)
                for _ in range(40):
                    mid = 0.5 * (low + high)
                    low, high = (low, mid) if _feasible(groups, f_act, xs, ys, mid) else (mid, high)
                best = min(best, high)
    return best


def test_brute_force_reproduces_closed_forms() -> None:
    # Checks of the checker: equal contacts on a full-range line give F_tot / N, and the
    # paper's friction fraction 0.4 with 5 contacts (F = 5) is the level 5 - 2k nearest -2.
    curve = ForceCurve([-V_MAX, V_MAX], [3.0, -3.0])
    inf = np.full(3, np.inf)
    assert brute_force(curve, np.ones(3), -inf, inf, np.zeros(3, bool)) == pytest.approx(
        1.0, abs=1e-9)
    flat = ForceCurve([-V_MAX, V_MAX], [-1.0, -1.0])       # levels 4 - 2k: nearest 0 or -2
    assert brute_force(flat, np.ones(4), -inf[:1].repeat(4), inf[:1].repeat(4),
                       np.zeros(4, bool)) == pytest.approx(1.0, abs=1e-9)


# -- the MILP against brute force (tiny instances) -------------------------------------------------
def _assert_valid_tight_bound(bound: float, optimum: float, total: float) -> None:
    """``bound`` is a lower bound of the brute-force ``optimum`` and within tolerance of it.

    Upper side: brute-force bisection resolves the optimum to 2 F_tot / 2^40 < 1e-11 N, so a
    valid bound is <= optimum + 1e-9. Lower side: HiGHS closes to 1e-9 F_tot and the reported
    bound is lowered by BOUND_ALLOWANCE F_tot (1e-8), so it is >= optimum - 1e-7 F_tot.
    """
    assert bound <= optimum + 1e-9
    assert bound >= optimum - 1e-7 * total


def _random_curve(rng: np.random.Generator, total: float) -> ForceCurve:
    xs = np.sort(rng.uniform(-0.3, 0.3, 3))
    return ForceCurve(xs, np.sort(rng.uniform(-total, total, 3))[::-1])


@pytest.mark.parametrize("seed", range(6))
def test_milp_matches_brute_force_with_free_speeds(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 4
    forces = rng.uniform(0.5, 2.0, n)
    curve = _random_curve(rng, forces.sum())
    result = allocate(curve, ContactSet(np.zeros(n), forces), speed_limits=(-V_MAX, V_MAX),
                      method="milp")
    expected = brute_force(curve, forces, np.full(n, -V_MAX), np.full(n, V_MAX),
                           np.zeros(n, bool))
    # Bisection resolves to 2 F_tot / 2^40 ~ 1e-11; HiGHS tolerances are 1e-9 of F_tot.
    assert result.error_sup == pytest.approx(expected, abs=1e-7)
    _assert_valid_tight_bound(result.bound, expected, forces.sum())
    assert result.status is AllocationStatus.OPTIMAL


@pytest.mark.parametrize("seed", range(4))
def test_subset_sum_split_matches_brute_force(seed: int) -> None:
    rng = np.random.default_rng(50 + seed)
    n = 4
    forces = rng.uniform(0.5, 2.0, n)
    target = FrictionFraction(rng.uniform(-1, 1), V_MAX)
    result = allocate(target, ContactSet(np.zeros(n), forces), speed_limits=(-V_MAX, V_MAX))
    curve = result.curve
    expected = brute_force(curve, forces, np.full(n, -V_MAX), np.full(n, V_MAX),
                           np.zeros(n, bool))
    assert result.error_sup == pytest.approx(expected, abs=1e-9)      # bisection 1e-11
    assert result.bound == pytest.approx(expected, abs=1e-9)
    assert result.extra["formulation"] in ("subset-sum", "partition")


@pytest.mark.parametrize("seed", range(4))
def test_milp_matches_brute_force_with_boxes_lifts_and_fixed(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    n = 4
    forces = rng.uniform(0.5, 2.0, n)
    v0 = rng.uniform(-0.3, 0.3, n)
    curve = _random_curve(rng, forces.sum())
    fixed = np.array([True, False, False, False])
    liftable = np.array([False, False, True, True])
    result = allocate(curve, ContactSet(v0, forces), speed_limits=(-V_MAX, V_MAX),
                      rate_limit=1.0, dt=0.15, fixed=fixed, liftable=liftable, method="milp")
    lo = np.maximum(-V_MAX, v0 - 0.15)
    hi = np.minimum(V_MAX, v0 + 0.15)
    lo[fixed], hi[fixed] = v0[fixed], v0[fixed]
    expected = brute_force(curve, forces, lo, hi, liftable)
    assert result.extra["formulation"] == "pairwise"
    assert result.error_sup == pytest.approx(expected, abs=1e-7)
    _assert_valid_tight_bound(result.bound, expected, forces.sum())
    assert result.speeds[0] == v0[0]                                    # fixed stays
    assert np.all(np.abs(result.speeds - v0) <= 0.15 + 1e-15)           # rate limit
    assert np.all(result.active[~liftable])


def test_partition_and_pairwise_formulations_agree(rng: np.random.Generator) -> None:
    # The same free-speed problem through both formulations (a per-contact box that equals
    # the shared one but is given through fixed=[] forces nothing; a failed contact at a
    # speed outside the band does not matter either, so we compare via a tiny rate limit
    # that does not bind).
    n = 6
    forces = rng.uniform(0.5, 2.0, n)
    curve = _random_curve(rng, forces.sum())
    contacts = ContactSet(np.zeros(n), forces)
    shared = allocate(curve, contacts, speed_limits=(-V_MAX, V_MAX), method="milp")
    per_contact = allocate(curve, contacts, speed_limits=(np.full(n, -V_MAX),
                                                          np.r_[V_MAX, np.full(n - 1, 0.34999)]),
                           method="milp")
    assert shared.extra["formulation"] == "partition"
    assert per_contact.extra["formulation"] == "pairwise"
    # Lowering one limit by 1e-5 m/s changes the optimum by at most slope * 1e-5.
    slope = float(np.max(np.abs(np.diff(curve.forces) / np.diff(curve.speeds))))
    assert per_contact.error_sup == pytest.approx(shared.error_sup, abs=slope * 1e-5 + 1e-7)


# -- random unequal instances up to N = 30 ----------------------------------------------------------
@pytest.mark.parametrize("n", [5, 10, 20, 30])
def test_random_unequal_instances_have_a_tiny_certified_gap(n: int) -> None:
    rng = np.random.default_rng(n)
    forces = rng.uniform(0.2, 3.0, n)
    total = forces.sum()
    contacts = ContactSet(rng.uniform(-0.3, 0.3, n), forces)
    targets = [Viscosity(0.8 * total / V_MAX, 0.02, V_MAX),
               ForceCurve([-0.3, -0.1, 0.0, 0.25], [0.9 * total, 0.2 * total, 0.0, -0.7 * total]),
               FrictionFraction(0.5, V_MAX)]
    for target in targets:
        result = allocate(target, contacts, speed_limits=(-V_MAX, V_MAX), method="milp",
                          time_limit=8.0)
        # Second method for the error: the achieved staircase sampled on a dense grid.
        sampled, allowance = _dense_sup(result.curve, result.contacts)
        assert sampled <= result.error_sup + 1e-12               # rounding of force()
        assert result.error_sup <= sampled + allowance + 1e-12
        assert result.gap <= 1e-6
        assert result.status is AllocationStatus.OPTIMAL


def test_subset_sum_friction_fraction_with_unequal_loads() -> None:
    # Loads 1, 2, 3, 4 (F_tot = 10): fraction 0.2 needs w(below) - w(above) = 2, e.g. {1, 2, 3}
    # against {4}: exactly realizable. Fraction 0.1 needs a difference of 1: impossible with
    # these loads (every subset difference is even), the best is 1 N off.
    contacts = ContactSet(np.zeros(4), [1.0, 2.0, 3.0, 4.0])
    exact = allocate(FrictionFraction(0.2, V_MAX), contacts, speed_limits=(-V_MAX, V_MAX))
    assert exact.method == "milp" and exact.error_sup == 0.0
    below = exact.contacts.forces[exact.speeds == -V_MAX].sum()
    assert below - (10.0 - below) == pytest.approx(2.0, abs=1e-12)
    odd = allocate(FrictionFraction(0.1, V_MAX), contacts, speed_limits=(-V_MAX, V_MAX))
    assert odd.error_sup == pytest.approx(1.0, abs=1e-9)
    assert odd.bound == pytest.approx(1.0, abs=1e-7)


def test_lifting_realizes_an_odd_fraction() -> None:
    # With contact 0 (1 N) liftable, fraction 0.1 of F_tot = 10 (force -1 N) becomes exact:
    # lift it and put {2, 3} below against {4} above... -(2+3) + 4 = -1.
    contacts = ContactSet(np.zeros(4), [1.0, 2.0, 3.0, 4.0])
    result = allocate(FrictionFraction(0.1, V_MAX), contacts, speed_limits=(-V_MAX, V_MAX),
                      liftable=[0])
    assert result.error_sup == pytest.approx(0.0, abs=1e-9)
    assert not result.active[0] and result.contacts.forces[0] == 0.0


def test_failed_contacts_keep_their_speed_and_push() -> None:
    # Ten equal contacts, two failed at +v_max: friction fraction 1 (all below) is impossible;
    # the best is 8 below and the failed two above: force 2 - 8 = -6 vs -10, error 4.
    contacts = ContactSet([V_MAX, V_MAX] + [0.0] * 8)
    result = allocate(FrictionFraction(1.0, V_MAX), contacts, speed_limits=(-V_MAX, V_MAX),
                      failed=[0, 1])
    assert result.method == "milp"
    np.testing.assert_array_equal(result.speeds[:2], [V_MAX, V_MAX])
    assert result.error_sup == pytest.approx(4.0, abs=1e-9)
    assert result.bound == pytest.approx(4.0, abs=1e-6)


def test_equilibrium_margin_with_unequal_loads() -> None:
    # Loads 3, 1, 1, 1, 1, 1 with contact 0 (3 N) rate-limited far from 0.1: the others must
    # carry the equilibrium. Margin 1 asks W >= |U - L| + 2 * 3 (the heaviest may fail).
    forces = np.array([3.0, 1, 1, 1, 1, 1])
    v0 = np.array([-0.3, 0.1, 0.1, 0.05, 0.1, 0.12])
    result = allocate(EquilibriumSpeed(0.1, margin=1), ContactSet(v0, forces),
                      speed_limits=(-V_MAX, V_MAX), rate_limit=1.0, dt=0.1, method="milp")
    # Contact 0 reaches at most -0.2 < 0.1: L >= 3 so W >= 3 + 6 would be needed; only 5 N can
    # be at 0.1. Infeasible, said as such.
    assert result.status is AllocationStatus.INFEASIBLE
    ok = allocate(EquilibriumSpeed(0.1, margin=1), ContactSet(v0, np.ones(6)),
                  speed_limits=(-V_MAX, V_MAX), rate_limit=1.0, dt=0.1, method="milp")
    assert ok.status is AllocationStatus.OPTIMAL
    assert failure_margin(ok.contacts, 0.1) >= 1


def _dense_sup(curve: ForceCurve, contacts: ContactSet, points: int = 200_001) -> tuple[float, float]:
    """Second method for error_sup: sample the achieved staircase against the target on a
    uniform grid of the band (continuous targets only: no vertical steps). Returns the sampled max and the sampling allowance: on each
    flat piece the difference is linear with the target's slope, so a grid of spacing h
    misses at most max|slope| * h of the sup (attained as a one-sided limit at a step)."""
    lo, hi = curve.band
    V = np.linspace(lo, hi, points)
    # At a contact speed the achieved force is the interval force_bounds (stiction).
    low, high = contacts.force_bounds(V)
    target = curve.value_right(V)
    sampled = float(np.max(np.maximum(0.0, np.maximum(low - target, target - high))))
    wide = np.diff(curve.speeds) > 0
    slope = float(np.max(np.abs(np.diff(curve.forces)[wide] / np.diff(curve.speeds)[wide]),
                         initial=0.0))
    return sampled, slope * (V[1] - V[0])


def test_time_limit_is_reported_with_a_valid_bound() -> None:
    # A budget already spent when HiGHS starts (1e-9 s): HiGHS gets time_limit 0 and stops
    # at once, deterministically. The status says TIME_LIMIT, the allocation is the
    # heuristic's, and the bound is still a valid lower bound: <= the brute-force optimum.
    rng = np.random.default_rng(3)
    forces, v0 = rng.uniform(0.5, 2, 4), rng.uniform(-0.3, 0.3, 4)
    result = allocate(FrictionFraction(0.3, 0.3), ContactSet(v0, forces),
                      speed_limits=(-V_MAX, V_MAX), rate_limit=1.0, dt=0.2, time_limit=1e-9)
    assert result.method == "milp"
    assert result.status is AllocationStatus.TIME_LIMIT
    lo, hi = np.maximum(-V_MAX, v0 - 0.2), np.minimum(V_MAX, v0 + 0.2)
    optimum = brute_force(result.curve, forces, lo, hi, np.zeros(4, bool))
    assert result.bound <= optimum + 1e-9                    # bisection resolves 1e-11
    assert result.error_sup >= optimum - 1e-9                # nothing beats the optimum
    sampled, allowance = _dense_sup(result.curve, result.contacts)
    assert sampled <= result.error_sup + 1e-12 <= sampled + allowance + 2e-12
    assert np.all(np.abs(result.speeds - v0) <= 0.2 + 1e-12)  # rate limit (rounding of v0 +- 0.2)


@pytest.mark.parametrize("upper", [V_MAX, (V_MAX, V_MAX, 0.3)])
def test_every_contact_liftable_keeps_one_down(upper) -> None:
    # Target 0 with loads 1, 2, 3.5 all liftable: lifting all would give F = 0 (no contact
    # set at all). With one contact at least down the best is {1, 2} against {3.5}: 0.5 N.
    # A shared box goes through the partition MILP, per-contact boxes through the pairwise.
    forces = np.array([1.0, 2.0, 3.5])
    result = allocate(FrictionFraction(0.0, V_MAX), ContactSet(np.zeros(3), forces),
                      liftable=[0, 1, 2], speed_limits=(-V_MAX, upper))
    hi = np.broadcast_to(np.asarray(upper, dtype=float), (3,))
    expected = brute_force(result.curve, forces, np.full(3, -V_MAX), hi, np.ones(3, bool))
    assert expected == pytest.approx(0.5, abs=1e-9)           # closed form above; bisection
    assert result.error_sup == pytest.approx(expected, abs=1e-7)   # HiGHS tol 1e-9 F_tot
    assert result.bound <= expected + 1e-9                     # a valid lower bound
    assert result.contacts.total_force > 0
    assert result.extra["formulation"] == ("partition" if upper == V_MAX else "pairwise")


def test_milp_bound_is_conservative_by_the_stated_allowance() -> None:
    # Ten unit contacts, two failed at 0 m/s, equilibrium asked at 0.1 m/s (margin 3): the
    # failed pair is below 0.1 on (0, 0.1), where the force is at most 10 - 2 * 2 = 6 N
    # against the target's 10 N: the optimum is 4 N (closed form). HiGHS's floating dual
    # bound alone gave gaps of -3.6e-15 here; the reported bound is lowered by the stated
    # allowance, so it lies in [4 - 2 * allowance, 4] and the gap is >= 0.
    from toolkit.allocation._milp import BOUND_ALLOWANCE

    result = allocate(EquilibriumSpeed(0.1, 3), ContactSet(np.zeros(10)), failed=[0, 1],
                      speed_limits=(-V_MAX, V_MAX))
    allowance = BOUND_ALLOWANCE * 10.0
    assert result.error_sup == pytest.approx(4.0, abs=1e-9)      # exact staircase levels
    assert 4.0 - 2 * allowance <= result.bound <= 4.0
    assert result.gap >= 0.0
    assert result.extra["bound_allowance"] == pytest.approx(allowance, rel=1e-15)
