"""The adaptive filter's compiled IMM arithmetic (toolkit._compiled.imm) against filterpy,
its reference: mixing and combination against IMMEstimator, the sparse prediction against the
dense ``F P F^T + Q``, the update against KalmanFilter.update, the wheels' bank against a
plain 2-state Kalman filter. ``make test`` runs this file compiled and again as Python under
``NUMBA_DISABLE_JIT=1`` (the same source)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from toolkit._compiled import load

K = load("imm")
filterpy = pytest.importorskip("filterpy.kalman")


def _spd(rng: np.random.Generator, d: int, scale: float = 1.0) -> np.ndarray:
    A = rng.normal(size=(d, d)) * scale
    return A @ A.T + np.eye(d) * scale * scale * 0.1


def _filters(rng: np.random.Generator, m: int, d: int) -> list:
    out = []
    for _ in range(m):
        kf = filterpy.KalmanFilter(dim_x=d, dim_z=1)
        kf.x = rng.normal(size=d)
        kf.P = _spd(rng, d)
        kf.H = np.zeros((1, d))
        kf.H[0, 0] = 1.0
        out.append(kf)
    return out


def _mixed_modes(rng: np.random.Generator, d: int, mu: np.ndarray, M: np.ndarray, scale: float = 1.0) -> tuple:
    """Three random modes (states and covariances scaled by ``scale``), mixed by the kernel,
    and random transition rows (row 0 starting with 1), predicted means and process noises."""
    m = mu.size
    filters = _filters(rng, m, d)
    for f in filters:
        f.x *= scale
        f.P *= scale * scale
    xs = np.array([f.x.copy() for f in filters])
    Ps = np.array([f.P.copy() for f in filters])
    xs0, Ps0, cbar = np.empty_like(xs), np.empty_like(Ps), np.empty(m)
    K.mix(mu, M, xs, Ps, xs0, Ps0, cbar)
    rows0, rows1 = rng.normal(size=(m, d)), rng.normal(size=(m, d))
    rows0[:, 0] = 1.0
    means = rng.normal(size=(m, d)) * scale
    Qs = np.array([_spd(rng, 2, 0.1 * scale) for _ in range(m)])
    return filters, xs, Ps, xs0, Ps0, cbar, rows0, rows1, means, Qs


def _filterpy_predicted(filters: list, mu: np.ndarray, M: np.ndarray, xs0: np.ndarray, rows0: np.ndarray,
                        rows1: np.ndarray, means: np.ndarray, Qs: np.ndarray, qtheta: float, R: float) -> Any:
    """filterpy's IMMEstimator over ``filters`` after its predict: each filter's transition
    (the identity but for rows 0 and 1), process noise, measurement noise ``R`` and the input
    that makes ``F x0 + B u`` the mode's predicted mean from its mixed state ``x0``."""
    d = xs0.shape[1]
    for j, f in enumerate(filters):
        F = np.eye(d)
        F[0], F[1] = rows0[j], rows1[j]
        f.F = F
        f.Q = np.eye(d) * qtheta
        f.Q[:2, :2] = Qs[j]
        f.B = (means[j] - F @ xs0[j])[:, None]
        f.R = np.array([[R]])
    imm = filterpy.IMMEstimator(filters, mu.copy(), M)
    imm.predict(u=np.array([1.0]))
    return imm


def test_mixing_and_combination_equal_filterpy_imm():
    # Random modes, unequal mode probabilities, a row-stochastic M with unequal rows: the
    # kernel's mixed states (filterpy computes them inside IMMEstimator.predict, just before
    # each filter's own predict, so an identity transition exposes them) and its
    # combination equal filterpy's to rounding (1e-12 relative).
    rng = np.random.default_rng(3)
    m, d = 3, 7
    filters = _filters(rng, m, d)
    mu = np.array([0.7, 0.25, 0.05])
    M = np.array([[0.9, 0.08, 0.02], [0.1, 0.85, 0.05], [0.3, 0.2, 0.5]])
    xs = np.array([f.x.copy() for f in filters])
    Ps = np.array([f.P.copy() for f in filters])
    imm = filterpy.IMMEstimator(filters, mu.copy(), M)
    for f in filters:
        f.F = np.eye(d)
        f.Q = np.zeros((d, d))
    imm.predict()
    xs0, Ps0, cbar = np.empty_like(xs), np.empty_like(Ps), np.empty(m)
    K.mix(mu, M, xs, Ps, xs0, Ps0, cbar)
    np.testing.assert_allclose(cbar, mu @ M, rtol=1e-14)
    for j, f in enumerate(filters):
        np.testing.assert_allclose(xs0[j], f.x, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(Ps0[j], f.P, rtol=1e-12, atol=1e-14)
    x, P = np.empty(d), np.empty((d, d))
    K.combine(mu, xs0, Ps0, x, P)
    np.testing.assert_allclose(x, imm.x, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(P, imm.P, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sparse_prediction_equals_the_dense_product(seed):
    # A transition that is the identity but for its first two rows (the body's (X, V) over
    # the augmented state): the kernel's A P A^T + Q equals numpy's dense product (1e-12
    # relative), symmetric exactly.
    rng = np.random.default_rng(seed)
    d = 13
    P = _spd(rng, d, 1e-3)
    A = np.eye(d)
    A[0] = rng.normal(size=d)
    A[1] = rng.normal(size=d)
    Q2 = _spd(rng, 2, 1e-4)
    qtheta = 1e-6
    out = np.empty((d, d))
    K.predict_rows(P, A[0].copy(), A[1].copy(), Q2, qtheta, out)
    Q = np.eye(d) * qtheta
    Q[:2, :2] = Q2
    expected = A @ P @ A.T + Q
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    assert np.array_equal(out, out.T)


def test_update_equals_filterpy_update():
    # A scalar measurement of the first state: the kernel's Joseph-form update equals
    # filterpy's (state and covariance to 1e-12 relative); its likelihood is filterpy's
    # (Gaussian density of the innovation, 1e-12 relative) and its NIS y^2 / S.
    rng = np.random.default_rng(4)
    d = 9
    kf = _filters(rng, 1, d)[0]
    kf.R = np.array([[0.37]])
    x, P = kf.x.copy(), kf.P.copy()
    z = 1.3
    kf.update(np.array([z]))
    likelihood, nis = K.update_first(x, P, z, 0.37)
    np.testing.assert_allclose(x, kf.x, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(P, kf.P, rtol=1e-12, atol=1e-14)
    assert likelihood == pytest.approx(kf.likelihood, rel=1e-12)
    assert nis == pytest.approx(kf.y.item() ** 2 / kf.S.item(), rel=1e-12)
    # An innovation far in the tail: filterpy floors the likelihood at the smallest normal
    # float, and so does the kernel (the mode then keeps a vanishing, not zero, weight).
    x2, P2 = np.zeros(d), np.eye(d) * 1e-6
    assert K.update_first(x2, P2, 1.0, 1e-6)[0] == 2.2250738585072014e-308


def test_cycle_equals_filterpy_predict_and_update():
    # One whole step: mixing, each mode's prediction (transition rows, process noise, and the
    # input that makes F x0 + B u its mean), the update, the mode probabilities and the
    # combination, against IMMEstimator.predict(u) / update(z) (1e-10 relative).
    rng = np.random.default_rng(5)
    m, d = 3, 6
    mu = np.array([0.5, 0.3, 0.2])
    M = np.array([[0.97, 0.02, 0.01], [0.02, 0.97, 0.01], [0.01, 0.01, 0.98]])
    filters, xs, Ps, xs0, Ps0, cbar, rows0, rows1, means, Qs = _mixed_modes(rng, d, mu, M)
    qtheta, z, R = 1e-4, 0.4, 0.25
    imm = _filterpy_predicted(filters, mu, M, xs0, rows0, rows1, means, Qs, qtheta, R)
    imm.update(np.array([z]))
    xs_out, Ps_out, mu_out, x, P, nis = (np.empty_like(xs), np.empty_like(Ps), np.empty(m), np.empty(d),
                                         np.empty((d, d)), np.empty(m))
    K.cycle(Ps0, means, rows0, rows1, Qs, qtheta, cbar, z, R, xs_out, Ps_out, mu_out, x, P, nis)
    np.testing.assert_allclose(mu_out, imm.mu, rtol=1e-10)
    for j, f in enumerate(filters):
        np.testing.assert_allclose(xs_out[j], f.x, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(Ps_out[j], f.P, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(x, imm.x, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(P, imm.P, rtol=1e-10, atol=1e-12)


def test_bank_step_equals_a_plain_kalman_filter():
    # Every (hypothesis, wheel) filter is the 2-state constant-speed filter with the
    # hypothesis's random-walk noise: the kernel equals filterpy's KalmanFilter on each
    # (1e-12 relative), and each hypothesis's log-weight gains its log-likelihood sum. A
    # wheel standing in its gearbox play (not seen) is predicted and not updated.
    rng = np.random.default_rng(6)
    H, n, h = 3, 4, 0.02
    drifts = np.array([0.0, 1e-3, 1e-2])
    Q = np.array([[d * d * h ** 3 / 3, d * d * h * h / 2, d * d * h] for d in drifts])
    x = rng.normal(size=(H, n, 2)) * [1e-3, 0.1]
    P = np.empty((H, n, 3))
    P[..., 0], P[..., 1], P[..., 2] = 1e-8, 1e-9, 1e-6
    z = rng.normal(size=n) * 1e-3
    noise = np.full(n, 5e-10) * (1 + np.arange(n))
    logw = np.array([0.0, -1.0, 2.0])
    expected_logw = 0.99 * logw.copy()
    ref = []
    for a in range(H):
        for i in range(n):
            kf = filterpy.KalmanFilter(dim_x=2, dim_z=1)
            kf.x = x[a, i].copy()
            kf.P = np.array([[P[a, i, 0], P[a, i, 1]], [P[a, i, 1], P[a, i, 2]]])
            kf.F = np.array([[1.0, h], [0.0, 1.0]])
            kf.Q = np.array([[Q[a, 0], Q[a, 1]], [Q[a, 1], Q[a, 2]]])
            kf.H = np.array([[1.0, 0.0]])
            kf.R = np.array([[noise[i]]])
            kf.predict()
            S = kf.P[0, 0] + noise[i]
            y = z[i] - kf.x[0]
            expected_logw[a] -= 0.5 * (y * y / S + math.log(S))
            kf.update(np.array([z[i]]))
            ref.append((a, i, kf.x.copy(), kf.P.copy()))
    # Held contacts (the law moves nothing: cx = 0), the play engaged (seen, no shift):
    # x + h o, o is the constant-speed transition.
    zero, one = np.zeros(n), np.ones(n)
    K.bank_step(x, P, Q, zero, h * one, zero, zero, one, z, noise, logw, 0.99)
    for a, i, xr, Pr in ref:
        np.testing.assert_allclose(x[a, i], xr, rtol=1e-12, atol=1e-16)
        np.testing.assert_allclose(P[a, i], [Pr[0, 0], Pr[0, 1], Pr[1, 1]], rtol=1e-10, atol=1e-20)
    np.testing.assert_allclose(logw, expected_logw, rtol=1e-12)


def test_bank_step_skips_a_wheel_in_its_play():
    # seen = 0: the prediction only (x + cx + g o, P grown by the transition and noise), no
    # log-likelihood term.
    x = np.array([[[1.0, 0.5]]])
    P = np.array([[[1e-6, 1e-7, 1e-4]]])
    Q = np.array([[1e-9, 2e-9, 3e-8]])
    logw = np.zeros(1)
    g = 0.02
    K.bank_step(x, P, Q, np.array([0.003]), np.array([g]), np.array([1e-6]), np.zeros(1), np.zeros(1),
                np.array([9.0]), np.array([1e-8]), logw, 0.5)
    np.testing.assert_allclose(x[0, 0], [1.0 + 0.003 + g * 0.5, 0.5], rtol=1e-15)
    np.testing.assert_allclose(P[0, 0], [1e-6 + 2 * g * 1e-7 + g * g * 1e-4 + 1e-9, 1e-7 + g * 1e-4 + 2e-9,
                                         1e-4 + 3e-8 + 1e-6], rtol=1e-14)
    assert logw[0] == 0.0


def test_bank_moments_are_the_mixture_of_the_hypotheses():
    # Against NumPy's weighted moments (1e-13 relative: sums of six terms): the weights are the
    # softmax of the log-likelihoods (shifted to a maximum 0 in place), the offset's mixture
    # variance is the within- plus the between-hypotheses part.
    rng = np.random.default_rng(8)
    H, n = 6, 5
    x = rng.normal(size=(H, n, 2)) * [1e-3, 1e-3]
    P = np.abs(rng.normal(size=(H, n, 3))) * 1e-7
    logw = rng.normal(size=H) * 3.0 - 40.0
    drifts = np.array([0.0, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3])
    w = np.exp(logw - logw.max())
    w /= w.sum()
    mean = w @ x[:, :, 1]
    var = w @ (P[:, :, 2] + (x[:, :, 1] - mean) ** 2)
    expected_logw = logw - logw.max()
    o, v = np.empty(n), np.empty(n)
    drift = K.bank_moments(x, P, logw, drifts, o, v)
    np.testing.assert_allclose(drift, w @ drifts, rtol=1e-13)
    np.testing.assert_allclose(o, mean, rtol=1e-13, atol=1e-20)
    np.testing.assert_allclose(v, var, rtol=1e-13)
    np.testing.assert_allclose(logw, expected_logw, rtol=0, atol=1e-14)


def test_predicted_first_is_the_mixture_prediction():
    # Mode j's predicted variance of the first state is (A_j P0_j A_j^T + Q_j)[0, 0] with
    # A_j's first row r_j: against the dense NumPy product (1e-12 relative), plus the
    # modes' spread about the mixture mean.
    rng = np.random.default_rng(9)
    m, d = 3, 7
    cbar = np.array([0.7, 0.2, 0.1])
    means = rng.normal(size=(m, d))
    rows0 = rng.normal(size=(m, d))
    rows0[1, 3:] = 0.0                       # zero entries are skipped: the same sum
    Ps0 = np.array([_spd(rng, d) for _ in range(m)])
    Qs = np.array([_spd(rng, 2) for _ in range(m)])
    x0 = cbar @ means[:, 0]
    var = sum(cbar[j] * (rows0[j] @ Ps0[j] @ rows0[j] + Qs[j, 0, 0] + (means[j, 0] - x0) ** 2)
              for j in range(m))
    got = K.predicted_first(cbar, means, rows0, Ps0, Qs)
    np.testing.assert_allclose(got, (x0, var, cbar @ means[:, 1]), rtol=1e-12)


def test_play_loaded_is_the_play_operators_fixed_point():
    # Loaded: the encoder sits the play's half width behind a contact whose speed keeps its
    # sign over the period; a reversal, a shift short of the half width, or an encoder ahead
    # of its contact are not. Without play every wheel is loaded.
    half = 4e-4
    shift = np.array([-half, -half, -half, -0.5 * half, half, half])
    start = np.array([0.1, 0.1, 0.1, 0.1, -0.1, 0.1])
    end = np.array([0.2, -0.05, 0.1, 0.1, -0.2, 0.1])
    o = np.zeros(6)
    loaded = np.empty(6)
    missing = K.play_loaded(shift, start, end, o, half, loaded)
    np.testing.assert_array_equal(loaded, [1.0, 0.0, 1.0, 0.0, 1.0, 0.0])
    assert missing == 3
    assert K.play_loaded(shift, start, end, o, 0.0, loaded) == 0 and loaded.all()


@pytest.mark.parametrize("scale", [1e-4, 1e-2, 1.0])
def test_bank_push_is_its_three_kernels_in_one(scale):
    # Every play loaded: bank_push is play_loaded, bank_step (the readings (counts + 0.5) q,
    # law error (0.3 (end - start))^2, the law's displacement cx) and bank_moments in one
    # call, the encoders' side moved to the best hypothesis's position plus its shift, the
    # speeds the law's end speeds plus the offsets: the same operations in the same order, so
    # equal to the bit (several scales, unequal hypothesis weights and wheel noises).
    rng = np.random.default_rng(11)
    H, n, h, half = 6, 4, 0.02, 4e-4 * scale
    drifts = np.array([0.0, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3])
    Q = np.array([[d * d * h ** 3 / 3, d * d * h * h / 2, d * d * h] for d in drifts])
    x = rng.normal(size=(H, n, 2)) * [scale, 1e-3]
    x[:, :, 1] = np.abs(x[:, :, 1])
    P = np.abs(rng.normal(size=(H, n, 3))) * 1e-8 * scale
    logw = rng.normal(size=H) * 2.0
    best = int(np.argmax(logw))
    y = x[best, :, 0] - half                   # engaged behind contacts moving forwards
    start, end = np.full(n, 0.1) + 0.01 * np.arange(n), np.full(n, 0.12)
    cx, gx = h * end, np.full(n, h)
    q = 1e-5 * scale                           # the wheels' count (m): readings in counts
    wheels = np.floor((x[best, :, 0] + rng.normal(size=n) * 1e-4 * scale) / q).astype(np.int64)
    z = (wheels + 0.5) * q
    noise = 1e-9 * scale * scale * (1.0 + np.arange(n))
    ref = [a.copy() for a in (x, P, logw, y)]
    shift, loaded, speeds, var = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    drift = K.bank_push(x, P, Q, start, end, cx, gx, 0.3, y, wheels, q, noise, logw, 0.99, half, drifts, shift,
                        loaded, speeds, var)
    xr, Pr, lr, yr = ref
    sr, ldr, o_r, vr = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    sr[:] = yr - xr[best, :, 0]
    assert K.play_loaded(sr, start, end, xr[best, :, 1].copy(), half, ldr) == 0
    K.bank_step(xr, Pr, Q, cx, gx, (0.3 * (end - start)) ** 2, sr, ldr, z, noise, lr, 0.99)
    drift_r = K.bank_moments(xr, Pr, lr, drifts, o_r, vr)
    for got, want in ((x, xr), (P, Pr), (logw, lr), (y, xr[best, :, 0] + sr), (speeds, end + o_r), (var, vr),
                      (shift, sr)):
        np.testing.assert_array_equal(got, want)
    assert drift == drift_r and loaded.all()
    # One wheel reversing over the period walks its play: -1, nothing changed but shift and
    # loaded.
    end2 = end.copy()
    end2[2] = -0.05
    x[:, :, 1] = 1e-3                          # (the update moved the offsets: small again)
    before = [a.copy() for a in (x, P, logw, y)]
    y[:] = x[int(np.argmax(logw)), :, 0] - half
    before[3] = y.copy()
    assert K.bank_push(x, P, Q, start, end2, cx, gx, 0.3, y, wheels, q, noise, logw, 0.99, half, drifts, shift,
                       loaded, speeds, var) == -1.0
    for got, want in zip((x, P, logw, y), before):
        np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(loaded, [1.0, 1.0, 0.0, 1.0])


@pytest.mark.parametrize("h", [1e-3, 0.02, 0.5])
def test_held_and_walk_predictions_are_their_transitions(h):
    # The stuck mode on a held contact and the free-form mode: the kernels' means and
    # covariances F P F^T + Q (through predict_rows) against the dense transition written out
    # (the identity but for rows 0 and 1) and the white-noise acceleration model's Q
    # (1e-12 relative: sums of a few products), over unequal contact speeds and three
    # periods; the nearest contact is the first of equals.
    rng = np.random.default_rng(12)
    d = 7
    x = rng.normal(size=d)
    x[1] = 0.12
    start = np.array([0.3, 0.1, 0.14, 0.1])
    var = np.array([1e-6, 4e-6, 2e-6, 9e-6])
    drift2 = (3e-4) ** 2
    mean, row0, row1, Q = np.empty(d), np.empty(d), np.empty(d), np.empty((2, 2))
    assert K.predict_held(x, start, start, var, -1, h, h ** 3, drift2, mean, row0, row1, Q) == 1
    F = np.eye(d)
    F[0], F[1] = 0.0, 0.0
    F[0, 0] = 1.0
    np.testing.assert_array_equal(row0, F[0])
    np.testing.assert_array_equal(row1, F[1])
    expected = x.copy()
    expected[0], expected[1] = x[0] + 0.1 * h, 0.1
    np.testing.assert_allclose(mean, expected, rtol=1e-15)
    walk = np.array([[h ** 3 / 3, h * h / 2], [h * h / 2, h]])
    Q_held = var[1] * np.array([[h * h, h], [h, 1.0]]) + drift2 * walk
    np.testing.assert_allclose(Q, Q_held, rtol=1e-12)
    P = _spd(rng, d, 1e-2)
    out = np.empty((d, d))
    K.predict_rows(P, row0, row1, Q, 0.0, out)
    Qd = np.zeros((d, d))
    Qd[:2, :2] = Q_held
    np.testing.assert_allclose(out, F @ P @ F.T + Qd, rtol=1e-12, atol=1e-14 * np.abs(P).max())
    # Contact 2 given, moving: nothing written, -1 - k returned.
    target = start.copy()
    target[2] = 0.2
    mean[:] = 7.0
    assert K.predict_held(x, start, target, var, 2, h, h ** 3, drift2, mean, row0, row1, Q) == -3
    assert (mean == 7.0).all()
    # The free-form mode: constant speed, random walk of intensity s2.
    s2 = (2e-3) ** 2
    K.predict_walk(x, h, np.array([h ** 3 / 3.0, h * h / 2.0, h]), s2, mean, row0, row1, Q)
    F = np.eye(d)
    F[0, 1] = h
    np.testing.assert_array_equal(row0, F[0])
    np.testing.assert_array_equal(row1, F[1])
    np.testing.assert_allclose(mean, F @ x, rtol=1e-15)
    np.testing.assert_allclose(Q, s2 * walk, rtol=1e-15)


@pytest.mark.parametrize("scale", [1e-4, 1.0, 1e3])
def test_measure_cycle_equals_filterpy_with_the_matched_noise(scale):
    # The adaptive filter's update per sample: the mixture's predicted first state (its
    # variance and the predicted speed V), the measurement noise R0 + max(a + b V^2, c + d V^2)
    # (matched from the innovations, and from the wheels), and the IMM step, against
    # filterpy's IMMEstimator with that R (its predict(u) / update(z)), at three scales of the
    # state (positions, speeds and covariances scaled together; unequal mode probabilities and
    # an unequal row-stochastic M). Tolerance 1e-13 relative (1e-13 of the largest entry
    # absolute): the same products summed in another order (numpy's dense F P F^T and Joseph
    # form against the kernels' sparse loops), measured at most 1e-15 (a few rounding units).
    rng = np.random.default_rng(13)
    m, d = 3, 8
    mu = np.array([0.6, 0.3, 0.1])
    M = np.array([[0.96, 0.03, 0.01], [0.02, 0.97, 0.01], [0.01, 0.01, 0.98]])
    filters, xs, Ps, xs0, Ps0, cbar, rows0, rows1, means, Qs = _mixed_modes(rng, d, mu, M, scale)
    rows0[2, 2:] = 0.0
    qtheta, R0 = 1e-4 * scale * scale, 0.05 * scale * scale
    noise = np.array([0.01 * scale * scale, 0.3, 0.02 * scale * scale, 0.1])
    z = float(means[0, 0] + 0.3 * scale)
    # The noise from the mixture's predicted speed, as filterpy's user computes it.
    V = float(cbar @ means[:, 1])
    R = R0 + max(noise[0] + noise[1] * V * V, noise[2] + noise[3] * V * V)
    imm = _filterpy_predicted(filters, mu, M, xs0, rows0, rows1, means, Qs, qtheta, R)
    x0_ref = float(imm.cbar @ np.array([f.x[0] for f in filters]))
    var_ref = float(sum(imm.cbar[j] * (filters[j].P[0, 0] + (filters[j].x[0] - x0_ref) ** 2) for j in range(m)))
    imm.update(np.array([z]))
    nis_ref = float(imm.mu @ np.array([f.y.item() ** 2 / f.S.item() for f in filters]))
    xs_out, Ps_out, mu_out, x, P, nis = (np.empty_like(xs), np.empty_like(Ps), np.empty(m), np.empty(d),
                                         np.empty((d, d)), np.empty(m))
    x0, var, speed, nis_mean = K.measure_cycle(Ps0, means, rows0, rows1, Qs, qtheta, cbar, z, R0, noise,
                                               xs_out, Ps_out, mu_out, x, P, nis)
    rtol = 1e-13
    assert speed == pytest.approx(V, rel=1e-14)
    assert x0 == pytest.approx(x0_ref, rel=rtol)
    assert var == pytest.approx(var_ref, rel=rtol)
    assert nis_mean == pytest.approx(nis_ref, rel=rtol)
    np.testing.assert_allclose(mu_out, imm.mu, rtol=rtol)
    for j, f in enumerate(filters):
        np.testing.assert_allclose(xs_out[j], f.x, rtol=rtol, atol=rtol * np.abs(f.x).max())
        np.testing.assert_allclose(Ps_out[j], f.P, rtol=rtol, atol=rtol * np.abs(f.P).max())
    np.testing.assert_allclose(x, imm.x, rtol=rtol, atol=rtol * np.abs(imm.x).max())
    np.testing.assert_allclose(P, imm.P, rtol=rtol, atol=rtol * np.abs(imm.P).max())


@pytest.mark.parametrize("scale", [1e-4, 1.0])
def test_ride_step_is_the_gaussian_likelihood_of_a_level_that_walks(scale):
    # The check's level filters (one per rate p of a grid) against the closed form: readings
    # y_1..y_n of a level d that walks by steps of variance p j_k (k >= 2) under white noise
    # R, the level's prior N(y_1, R) (a flat prior updated by y_1). Given y_1, y_k - y_1 =
    # W_k + e_k - e_1, so y_2..y_n ~ N(y_1, R (I + 1 1^T) + min-matrix of the cumulative
    # p j); scipy's multivariate normal log-density. rtol 1e-10: n = 12 sums of rounding.
    from scipy.stats import multivariate_normal

    rng = np.random.default_rng(5)
    n, R = 12, 0.3 * scale * scale
    grid = np.array([1e-9, 1e-4, 3e-3, 0.5, 4.0])
    jumps = rng.uniform(0.2, 2.0, n) * scale * scale
    y = rng.normal(size=n) * scale + 7.0 * scale
    level, var, loglik = np.full(grid.size, y[0]), np.full(grid.size, R), np.zeros(grid.size)
    for k in range(1, n):
        K.ride_step(level, var, grid, y[k], R, jumps[k], loglik)
    for g, p in enumerate(grid):
        walk = np.cumsum(p * jumps[1:])
        cov = R * (np.eye(n - 1) + 1.0) + np.minimum.outer(walk, walk)
        expected = multivariate_normal(np.full(n - 1, y[0]), cov).logpdf(y[1:])
        np.testing.assert_allclose(loglik[g], expected, rtol=1e-10)
    # Where the walk is negligible (p j = 1e-9 of R per step) the level is a constant's least
    # squares: the readings' mean, variance R / n (rtol 1e-6: the walk adds about n p j / R, 1.3e-7).
    np.testing.assert_allclose([level[0], var[0]], [y.mean(), R / n], rtol=1e-6)


@pytest.mark.parametrize(("shape", "events", "exposure"), [(0.5, 3, 2e3), (3.0, 12, 1e4), (0.5, 2000, 2e6),
                                                          (1.0, 40, 4e4)])
def test_rate_moments_are_the_gamma_posteriors(shape, events, exposure):
    # The check's log-likelihood of Poisson evidence (events lost over exposure transitions,
    # k log p - E p) times the Gamma(shape, rate) prior is Gamma(shape + k, rate + E): mean
    # a / b, variance a / b^2, here truncated to the grid [1e-10, 1e-2] (scipy's regularized
    # incomplete gamma: E[p^m] on [lo, hi] = Gamma(a + m) / (Gamma(a) b^m) times the ratio of
    # its masses there). Broad posteriors (trapezoid sums in log p, 20 a decade): rtol 1e-8
    # (the sums' error for a log-width above the spacing is below 1e-8). The sharp one (2000
    # events: log-width 0.022 against a spacing of 0.115): the Gamma through the three points
    # about its peak, untruncated (the grid's ends are 30 widths away), exact up to the
    # rounding of log-likelihoods near -1e4 (rtol 1e-8).
    from scipy.special import gammainc

    from toolkit.estimation import MissedCountRate

    grid, log_grid = MissedCountRate.GRID, MissedCountRate.LOG_GRID
    rate = shape / 1e-3
    out = np.empty(2)
    K.rate_moments(grid, log_grid, events * log_grid - exposure * grid, shape, rate, out)
    a, b = shape + events, rate + exposure
    lo, hi = grid[0], grid[-1]

    def mass(s: float) -> float:
        return gammainc(s, b * hi) - gammainc(s, b * lo)

    mean = a / b * mass(a + 1) / mass(a)
    second = a * (a + 1) / b ** 2 * mass(a + 2) / mass(a)
    # Where the posterior reaches the grid's top the sums' last interval errs by about the
    # integrand there (p^(a + 1) e^(-b p), relative to its peak; 3e-6 for the first case):
    # tolerance ten times that, at least 1e-8.
    edge = math.exp((a + 1) * math.log(hi / (a / b)) - b * hi + a)
    np.testing.assert_allclose(out, [mean, second - mean * mean], rtol=max(1e-8, 10.0 * edge))


def test_ride_push_opens_only_on_a_level_difference_with_read_noise():
    # The check's window (RideCheck's rules, imm.ride_push): a difference that stays level
    # under read noise opens it at the window's last reading and is checked on every reading
    # after; one that moves at 11 mm/s (a contact the body does not ride) or one read with the
    # quantizations' noise alone (no read noise) never is.
    from toolkit.estimation import MissedCountRate, RideCheck

    qc, qw, h, n = 2.04e-4, 7.87e-5, 0.02, RideCheck.WINDOW
    rng = np.random.default_rng(2)

    def checked(slope: float, noise: float) -> list[int]:
        state, ring = np.zeros(8), np.zeros(n)
        G = MissedCountRate.GRID
        level, var, loglik = np.empty(G.size), np.empty(G.size), np.zeros(G.size)
        out = []
        for k in range(80):
            y = slope * k * h + noise * (qc * rng.normal() - qw * rng.normal())
            out.append(K.ride_push(state, ring, level, var, G, loglik, y, 0.2 * h, qc, qw, h, RideCheck.SLOPE,
                                   RideCheck.NOISE_OVER, 1e-3))
        return out

    level = checked(0.0, 0.6)
    assert level[:n] == [0] * n and all(level[n:]), level
    assert not any(checked(0.011, 0.6))
    assert not any(checked(0.0, 0.0))


@pytest.mark.parametrize("width", [0.03, 0.06, 0.1])
def test_rate_moments_of_a_sharp_posterior_that_is_not_gamma(width):
    # A check's likelihood that is lognormal in p times the default Gamma prior. Log-widths
    # 0.03 and 0.06 (below 0.7 of the grid's spacing of 0.115): the three points about the peak
    # fit a Gamma that is not the posterior; 0.1: the trapezoid sums. Against the posterior's
    # moments by adaptive quadrature (scipy.integrate.quad over log p): the mean within 2e-3,
    # the std within 5e-2 (measured: mean 1.2e-3 and 1.1e-4, std 1.5e-2 and 1.7e-2 for the
    # fit; the sums' error at 0.1 is below 1e-6).
    from scipy.integrate import quad

    from toolkit.estimation import MissedCountRate

    grid, log_grid = MissedCountRate.GRID, MissedCountRate.LOG_GRID
    shape, rate, centre = 0.5, 500.0, math.log(1.3e-3)

    def log_post(u: float) -> float:
        return shape * u - rate * math.exp(u) - 0.5 * ((u - centre) / width) ** 2

    top = log_post(centre)
    span = (centre - 12 * width, centre + 12 * width)
    m = [quad(lambda u, k=k: math.exp(log_post(u) - top + k * u), *span, epsabs=0, epsrel=1e-12)[0]
         for k in range(3)]
    mean, std = m[1] / m[0], math.sqrt(m[2] / m[0] - (m[1] / m[0]) ** 2)
    out = np.empty(2)
    K.rate_moments(grid, log_grid, -0.5 * ((log_grid - centre) / width) ** 2, shape, rate, out)
    assert abs(out[0] / mean - 1.0) <= 2e-3, (out[0], mean)
    assert abs(math.sqrt(out[1]) / std - 1.0) <= 5e-2, (math.sqrt(out[1]), std)
