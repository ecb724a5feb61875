"""Kernels of quantized lines (toolkit._compiled.lines): clipping, exact moments, and the
Bayesian identity their posterior satisfies. ``make test`` runs this file compiled and again
as Python under ``NUMBA_DISABLE_JIT=1`` (the same source)."""

import math

import numpy as np
import pytest

from toolkit._compiled import load

L = load("lines")
CAP = 32


def polygon(rows):
    p = np.zeros((CAP, 2))
    p[:len(rows)] = rows
    return p, len(rows)


def square():
    return polygon([(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)])


def clip(poly, n, a0, a1, lo, hi):
    out = np.zeros((CAP, 2))
    m = L.clip_strip(poly, n, a0, a1, lo, hi, 0.0, np.zeros((CAP, 2)), out)
    return out, m


def area(p, n):
    x, y = p[:n, 0], p[:n, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def test_clip_strip_of_a_square_by_hand():
    # -0.3 <= x + v / 2 <= 0.4 on [-1, 1]^2: at v = -1, x in [0.2, 0.9]; at v = 1, x in
    # [-0.8, -0.1]: a parallelogram of area 0.7 * 2 (counter-clockwise, positive area).
    p, n = square()
    out, m = clip(p, n, 1.0, 0.5, -0.3, 0.4)
    assert m == 4
    expected = {(0.2, -1.0), (0.9, -1.0), (-0.1, 1.0), (-0.8, 1.0)}
    got = {(round(x, 12), round(v, 12)) for x, v in out[:m]}
    assert got == expected
    assert area(out, m) == pytest.approx(1.4, rel=1e-14)


def test_clip_strip_empty_containing_and_capacity():
    p, n = square()
    assert clip(p, n, 1.0, 0.0, 2.0, 3.0)[1] == 0                 # strip beside the square
    out, m = clip(p, n, 1.0, 1.0, -5.0, 5.0)                       # strip holding it all
    assert m == 4 and area(out, m) == pytest.approx(4.0, rel=1e-15)
    small = np.zeros((3, 2))                                       # too few rows for a pentagon
    assert L.clip_strip(p, n, 1.0, 1.0, -5.0, 1.5, 0.0, np.zeros((CAP, 2)), small) == -1


def test_clip_strip_order_of_the_half_planes_does_not_matter():
    # Identity: the strip equals the two half-planes in either order (area to rounding).
    rng = np.random.default_rng(1)
    for _ in range(200):
        a0, a1 = rng.normal(size=2)
        lo = rng.uniform(-1.5, 0.5)
        hi = lo + rng.uniform(0.01, 1.5)
        p, n = square()
        out, m = clip(p, n, a0, a1, lo, hi)
        p2, n2 = clip(p, n, -a0, -a1, -hi, math.inf)               # a x <= hi ...
        p3, n3 = clip(p2, n2, a0, a1, lo, math.inf) if n2 > 0 else (p2, 0)   # ... then >= lo
        assert m == n3
        if m:
            assert area(out, m) == pytest.approx(area(p3, n3), rel=1e-12, abs=1e-15)


def test_moments_of_a_parallelogram_closed_form():
    # Uniform on the parallelogram above: v uniform on [-1, 1] (mean 0, var 1/3); given v,
    # x uniform on a width-0.7 slice centred at 0.05 - v / 2: var x = var(v) / 4 + 0.7^2 / 12,
    # cov = -var(v) / 2. Exact quadrature: rtol 1e-13 (rounding).
    p, n = square()
    out, m = clip(p, n, 1.0, 0.5, -0.3, 0.4)
    mom = np.zeros(5)
    weight = L.line_moments(out, m, out, 0, mom)
    assert weight == pytest.approx(1.4, rel=1e-14)
    np.testing.assert_allclose(mom, [0.05, 0.0, 1 / 12 + 0.49 / 12, -1 / 6, 1 / 3], rtol=1e-13, atol=1e-15)


def test_moments_weighted_by_a_second_polygon_closed_form():
    # Weight w(v) = v + 1 (the width of the triangle (0, -1), (1, 1), (-1, 1)) on the same
    # parallelogram: density of v proportional to v + 1 on [-1, 1], mean 1/3, var 2/9; x as
    # above given v. Exact quadrature (degree <= 4): rtol 1e-13.
    p, n = square()
    out, m = clip(p, n, 1.0, 0.5, -0.3, 0.4)
    tri, k = polygon([(0.0, -1.0), (1.0, 1.0), (-1.0, 1.0)])
    mom = np.zeros(5)
    weight = L.line_moments(out, m, tri, k, mom)
    assert weight == pytest.approx(0.7 * 2.0, rel=1e-13)          # int 0.7 (v + 1) dv
    np.testing.assert_allclose(mom, [0.05 - 1 / 6, 1 / 3, (2 / 9) / 4 + 0.49 / 12, -1 / 9, 2 / 9],
                               rtol=1e-13, atol=1e-15)
    # Polygons that share no speed: weight 0.
    far, j = polygon([(0.0, 2.0), (1.0, 3.0), (-1.0, 3.0)])
    assert L.line_moments(out, m, far, j, mom) == 0.0


def test_moments_keep_their_precision_on_a_tiny_polygon():
    # A parallelogram 1e-9 wide at (0.1, 0.2): the covariance is the scaled one of the
    # parallelogram above (two-pass central moments: no cancellation of 0.01-size raw
    # moments); rtol 1e-6 (slice widths are differences of 0.1-size numbers, 1e-16 / 1e-9
    # relative rounding each, over a few operations).
    s = 1e-9
    p, n = polygon([(0.1 + s * x, 0.2 + s * v) for x, v in [(0.2, -1), (0.9, -1), (-0.1, 1), (-0.8, 1)]])
    mom = np.zeros(5)
    L.line_moments(p, n, p, 0, mom)
    np.testing.assert_allclose(mom[:2], [0.1 + s * 0.05, 0.2], rtol=1e-14)
    np.testing.assert_allclose(mom[2:], np.array([1 / 12 + 0.49 / 12, -1 / 6, 1 / 3]) * s * s, rtol=1e-6)


def test_extend_lines_equals_clipping_each_polygon():
    # Identity: the batch kernel is clip_strip on each polygon with its own window start.
    rng = np.random.default_rng(2)
    n = 5
    polys = np.zeros((n, CAP, 2))
    for i in range(n):
        polys[i, :4] = square()[0][:4]
    counts = np.full(n, 4, dtype=np.int64)
    readings = rng.integers(-3, 3, n).astype(float)
    first = rng.integers(-3, 3, n).astype(float)
    starts = rng.uniform(0.0, 0.2, n)
    t, q = 0.3, 0.25
    expected = []
    for i in range(n):
        lo = (readings[i] - first[i]) * q
        expected.append(clip(polys[i], 4, 1.0, t - starts[i], lo, lo + q))
    L.extend_lines(polys, counts, t, starts, readings, first, q, 0.0, np.zeros((CAP, 2)),
                   np.zeros((CAP, 2)))
    for i, (out, m) in enumerate(expected):
        assert counts[i] == m
        np.testing.assert_array_equal(polys[i, :m], out[:m])


def test_reach_gaps_equal_the_vertices_positions():
    # Identity: the gap is the nearest vertex position x + tau v (a convex polygon's extreme
    # positions are at vertices) less the short cell's near edge, moving up (its top,
    # (reading - first) q) or down (its bottom, (reading + 1 - first) q); -inf for a dead line
    # or a still contact. Checked against NumPy over random polygons (rtol 1e-15: the same
    # sums; atol 1e-15 m for the near-zero differences).
    rng = np.random.default_rng(5)
    n = 7
    polys = rng.normal(0.0, 1.0, (n, CAP, 2))
    counts = np.array([3, 4, 6, 0, 5, 4, -1], dtype=np.int64)
    motion = np.array([1.0, -1.0, 1.0, 1.0, 0.0, -1.0, 1.0])
    readings = rng.integers(-3, 3, n).astype(float)
    first = rng.integers(-3, 3, n).astype(float)
    starts = rng.uniform(0.0, 0.2, n)
    t, q = 0.3, 0.25
    out = np.zeros(n)
    L.reach_gaps(polys, counts, t, starts, readings, first, q, motion, out)
    for i in range(n):
        if counts[i] <= 0 or motion[i] == 0.0:
            assert out[i] == -math.inf
            continue
        x = polys[i, :counts[i], 0] + (t - starts[i]) * polys[i, :counts[i], 1]
        gap = x.min() - (readings[i] - first[i]) * q if motion[i] > 0 else (readings[i] + 1 - first[i]) * q - x.max()
        np.testing.assert_allclose(out[i], gap, rtol=1e-15, atol=1e-15)
    # reach_seen: the same gaps, and per wheel old enough (t - start >= age) whether its gap
    # reaches each threshold: NumPy's masks, exactly (comparisons of the same numbers).
    gaps, seen, repairable = np.empty(n), np.empty(n, dtype=bool), np.empty(n, dtype=bool)
    age, seen_gap, repair_gap = 0.15, -0.5, -0.1
    L.reach_seen(polys, counts, t, starts, readings, first, q, motion, age, seen_gap, repair_gap, gaps, seen,
                 repairable)
    np.testing.assert_array_equal(gaps, out)
    aged = t - starts >= age
    np.testing.assert_array_equal(seen, aged & (out >= seen_gap))
    np.testing.assert_array_equal(repairable, aged & (out >= repair_gap))
    assert seen.any() and not seen.all() and repairable.any() and not (seen == repairable).all()
    # seen_steps: the steps read on the seen wheels whose lines live, |reading - last| summed,
    # the live others' added to unseen (whole counts: exact in any order).
    last = readings + rng.integers(-2, 3, n)
    unseen = np.arange(n, dtype=float)
    steps = L.seen_steps(readings, last, seen, counts, unseen)
    assert steps == float(np.abs(readings - last)[seen & (counts > 0)].sum())
    np.testing.assert_array_equal(unseen, np.arange(n) + np.where(~seen & (counts > 0), np.abs(readings - last), 0))
    assert (~seen & (counts > 0)).any() and (unseen != np.arange(n)).any()
    assert L.seen_steps(readings, last, np.zeros(n, dtype=bool), counts, unseen) == 0.0
    # behind, one polygon: its strip [lo, lo + q) at least gap counts behind every position
    # its lines reach, moving up or down: NumPy's extremes, exactly (the same sums).
    verdicts = set()
    for i in (0, 1, 2, 4):
        x = polys[i, :counts[i], 0] + (t - starts[i]) * polys[i, :counts[i], 1]
        for lo in (-3.0, -0.5, 0.0, 2.0):
            for direction in (1.0, -1.0):
                want = (x.min() - (lo + q) >= 0.25 * q) if direction > 0 else (lo - x.max() >= 0.25 * q)
                got = L.behind(polys[i], int(counts[i]), t - starts[i], lo, q, direction, 0.25)
                assert bool(got) == bool(want)
                verdicts.add(bool(want))
    assert verdicts == {True, False}


def test_a_tolerance_adds_no_sliver_vertices():
    # A strip whose bound passes within rounding of a vertex: exactly, the clip adds an
    # intersection a 1e-17 from it (a sliver edge); with a tolerance the vertex counts as
    # on the bound and the polygon keeps its four vertices.
    p, n = square()
    eps = 1e-17
    out, m = clip(p, n, 1.0, 0.0, -1.0 + eps, 5.0)
    tol = np.zeros((CAP, 2))
    m_tol = L.clip_strip(p, n, 1.0, 0.0, -1.0 + eps, 5.0, 1e-12, np.zeros((CAP, 2)), tol)
    assert m_tol == 4 and m >= 4
    assert area(tol, m_tol) == pytest.approx(4.0, rel=1e-15)


def test_a_line_run_keeps_at_most_eight_vertices():
    # A run of readings of one line allows at most a quadrilateral of lines (digital
    # straight segments); with the starting box's edges the polygon stays under 8 vertices
    # over 2000 readings at several speeds (tolerance 1e-8 of a count against rounding).
    q, h = 2.04e-4, 0.02
    rng = np.random.default_rng(5)
    for V in (0.194444, -0.0944444, 0.0123, 0.35):
        x0 = rng.uniform(0, q)
        p, n = square()
        p[:4] *= 1e3
        c0 = math.floor(x0 / q)
        worst = 0
        for k in range(2000):
            t = k * h
            lo = (math.floor((x0 + V * t) / q) - c0) * q
            out = np.zeros((CAP, 2))
            n = L.clip_strip(p, n, 1.0, t, lo, lo + q, 1e-8 * q, np.zeros((CAP, 2)), out)
            assert n > 0
            p = out
            worst = max(worst, n)
        assert worst <= 8, (V, worst)


def test_ride_moments_weighs_the_wheels_by_their_evidence():
    # Two wheels whose speed ranges both meet the body's polygon: the mixture of the two
    # line posteriors with weights proportional to weight / wheel area (closed form from
    # line_moments itself: an identity); a wheel whose speeds miss gets no evidence; none
    # meeting: total 0.
    p, n = square()
    body, m = clip(p, n, 1.0, 0.5, -0.3, 0.4)
    polys = np.zeros((3, CAP, 2))
    counts = np.array([3, 4, 4], dtype=np.int64)
    polys[0, :3] = [(0.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
    polys[1, :4] = [(-1.0, 0.0), (1.0, 0.0), (1.0, 0.5), (-1.0, 0.5)]
    polys[2, :4] = [(-1.0, 3.0), (1.0, 3.0), (1.0, 4.0), (-1.0, 4.0)]
    moments, evidence, out = np.zeros((3, 5)), np.zeros(3), np.zeros(5)
    total = L.ride_moments(body, m, polys, counts, np.ones(3), moments, evidence, out)
    single = [np.zeros(5), np.zeros(5)]
    w = [L.line_moments(body, m, polys[i], counts[i], single[i]) for i in range(2)]
    e = np.array([w[0] / 2.0, w[1] / 1.0])                     # areas 2 and 1
    np.testing.assert_allclose(evidence, [e[0], e[1], 0.0], rtol=1e-14)
    assert total == pytest.approx(e.sum(), rel=1e-14)
    p_ = e / e.sum()
    mean = p_[0] * single[0][:2] + p_[1] * single[1][:2]
    d = [single[i][:2] - mean for i in range(2)]
    cov = sum(p_[i] * (np.array([[single[i][2], single[i][3]], [single[i][3], single[i][4]]])
                       + np.outer(d[i], d[i])) for i in range(2))
    np.testing.assert_allclose(out, [mean[0], mean[1], cov[0, 0], cov[0, 1], cov[1, 1]], rtol=1e-12)
    counts[:2] = 0
    assert L.ride_moments(body, m, polys, counts, np.ones(3), moments, evidence, out) == 0.0


def _line_posterior(rng, V, K, q_c=2.04e-4, q_w=7.872e-5, h=0.02, ref=0.19):
    """Counts of a body and the wheel it rides at speed V, random grid phases; the truth
    (intercept offset, speed offset) and the posterior moments."""
    polys = []
    truth = None
    for q in (q_c, q_w):
        x0 = rng.uniform(0.0, q)
        c0 = math.floor(x0 / q)
        p, n = square()
        p[:4] *= 1e3
        for k in range(K):
            t = k * h
            lo = (math.floor((x0 + V * t) / q) - c0) * q - ref * t
            p, n = clip(p, n, 1.0, t, lo, lo + q)
            assert n > 0
            inside = lo <= (x0 - c0 * q) + t * (V - ref) <= lo + q       # the truth stays in
            assert inside
        polys.append((p, n))
        if truth is None:
            truth = np.array([x0 - c0 * q, V - ref])
    mom = np.zeros(5)
    assert L.line_moments(polys[0][0], polys[0][1], polys[1][0], polys[1][1], mom) > 0
    return truth, mom


@pytest.mark.parametrize("K", [5, 40])
def test_line_posterior_is_calibrated_over_its_prior(K):
    # The Bayesian identity: a posterior's NEES (error against its own mean and covariance)
    # averages the dimension, 2, over truths drawn from the prior, here grid phases uniform
    # on a count and V uniform on 0.18 .. 0.21 m/s. 600 draws: the NEES std measured ~1.6,
    # so the mean's std is ~0.065; tolerance 0.3 (4.6 sigma). (At one fixed V the mean
    # depends on V h / q's rational approximations: 2.48 at K = 5 for the cruise's V.)
    rng = np.random.default_rng(3 + K)
    nees = []
    for _ in range(600):
        V = rng.uniform(0.18, 0.21)
        e, mom = _line_posterior(rng, V, K)
        C = np.array([[mom[2], mom[3]], [mom[3], mom[4]]])
        d = e - mom[:2]
        nees.append(d @ np.linalg.solve(C, d))
    assert abs(np.mean(nees) - 2.0) < 0.3


def test_sharper_lines_take_the_lines_speed_where_it_is_sharper():
    # Three wheels, their polygons: a parallelogram whose speed is uniform on [-s, s] (mean 0,
    # variance s^2 / 3, closed form above, scaled) at three widths, listed out of order; a
    # wheel with fewer than three readings and one not listed keep their speeds. Where
    # s^2 / 3 < var[k] the contact's start and target become 0 and var[k] s^2 / 3 (1e-13
    # relative: exact quadrature, rounding).
    polys = np.zeros((5, CAP, 2))
    counts = np.zeros(5, dtype=np.int64)
    for k, s in ((0, 1e-3), (1, 1e-2), (2, 1e-4), (3, 1e-4), (4, 1e-4)):
        p, n = polygon([(-s, -s), (s, -s), (s, s), (-s, s)])
        out, m = clip(p, n, 1.0, 0.5, -0.3 * s, 0.4 * s)
        polys[k], counts[k] = out, m
    counts[3] = 2                                        # too few readings
    track = np.array([[0.1, 0.2, 0.3, 0.4, 0.5], [0.1, 0.25, 0.3, 0.4, 0.5]])
    var = np.array([1e-6, 1e-6, 1e-6, 1e-12, 1e-12])
    moments = np.zeros(5)
    L.sharper_lines(polys, counts, np.array([2, 0, 1, 3]), np.zeros((1, 2)), moments, track, var)
    # Wheel 0: 1e-6 / 3 < 1e-6, taken; wheel 1: 1e-4 / 3 > 1e-6, kept; wheel 2: 1e-8 / 3,
    # taken; wheel 3: two readings, kept; wheel 4: not listed, kept.
    np.testing.assert_allclose(track, [[0.0, 0.2, 0.0, 0.4, 0.5], [0.0, 0.25, 0.0, 0.4, 0.5]], rtol=0,
                               atol=1e-15)
    np.testing.assert_allclose(var, [1e-6 / 3, 1e-6, 1e-8 / 3, 1e-12, 1e-12], rtol=1e-13)
