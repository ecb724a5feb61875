"""Kernels of the adaptive filter's interacting multiple model: plain Python over arrays.

The arithmetic of filterpy's ``IMMEstimator`` over ``KalmanFilter`` objects (the tests run both
on the same steps), with the modes' states in arrays: mixing (:func:`mix`), prediction with an
identity transition but for the body's rows (:func:`predict_rows`), the scalar update
(:func:`update_first`), the mixture (:func:`combine`), one whole step (:func:`cycle`,
:func:`measure_cycle`), the stuck and free-form modes' predictions (:func:`predict_held`,
:func:`predict_walk`), the wheels' filter bank (:func:`bank_step`, :func:`bank_moments`,
:func:`bank_push`, :func:`play_loaded`) and the missed-count rate's evidence
(:func:`ride_push`, :func:`ride_step`, :func:`read_variance`, :func:`rate_moments`).
"""

from __future__ import annotations

import math

import numpy as np

from ..laws import cell_centre, quantization_variance

KERNELS = {"cell_centre": {"error_model": "numpy"}, "quantization_variance": {"error_model": "numpy"}, "mix": {}, "predict_rows": {}, "update_first": {}, "combine": {}, "bank_step": {}, "cycle": {}, "measure_cycle": {}, "predict_held": {}, "held_noise": {}, "predict_walk": {},
           "bank_moments": {}, "bank_push": {}, "play_loaded": {}, "sign_of": {},
           "predicted_first": {}, "ride_step": {}, "ride_push": {}, "read_variance": {},
           "rate_moments": {}}


def mix(mu, M, xs, Ps, xs0, Ps0, cbar):  # noqa: ANN001, ANN201 (numba kernel)
    """IMM mixing of ``m`` modes: ``cbar[j] = sum_i mu[i] M[i, j]`` and mode ``j``'s mixed
    state and covariance, :func:`combine` of the modes with weights ``mu[i] M[i, j] /
    cbar[j]``."""
    m = xs.shape[0]
    w = np.empty(m)
    for j in range(m):
        c = 0.0
        for i in range(m):
            c += mu[i] * M[i, j]
        cbar[j] = c
        for i in range(m):
            w[i] = mu[i] * M[i, j] / c
        combine(w, xs, Ps, xs0[j], Ps0[j])


def predict_rows(P, row0, row1, Q, qtheta, out):  # noqa: ANN001, ANN201 (numba kernel)
    """``out = A P A^T + Q`` with ``A`` the identity but for its rows 0 and 1 (``row0``,
    ``row1``, of length ``d``), ``Q`` (2, 2) added to the first two rows and columns and
    ``qtheta`` to the other diagonal entries (a random walk of the parameters)."""
    d = P.shape[0]
    # AP = A P: rows 0 and 1 combine P's rows, the others are P's.
    for b in range(d):
        s0 = 0.0
        s1 = 0.0
        for c in range(d):
            s0 += row0[c] * P[c, b]
            s1 += row1[c] * P[c, b]
        out[0, b] = s0
        out[1, b] = s1
        for a in range(2, d):
            out[a, b] = P[a, b]
    # (A P) A^T: columns 0 and 1 combine (A P)'s columns, the others stay.
    for a in range(d):
        s0 = 0.0
        s1 = 0.0
        for c in range(d):
            s0 += out[a, c] * row0[c]
            s1 += out[a, c] * row1[c]
        out[a, 0] = s0
        out[a, 1] = s1
    for a in range(2):
        for b in range(2):
            out[a, b] += Q[a, b]
    for a in range(2, d):
        out[a, a] += qtheta
    for a in range(d):
        for b in range(a + 1, d):
            v = 0.5 * (out[a, b] + out[b, a])
            out[a, b] = v
            out[b, a] = v


def update_first(x, P, z, R):  # noqa: ANN001, ANN201 (numba kernel)
    """Kalman update of ``(x, P)`` in place with ``z = x[0] + noise`` of variance ``R``;
    returns ``(likelihood, nis)`` of the innovation (Gaussian density; NIS ``y^2 / S``)."""
    d = x.shape[0]
    S = P[0, 0] + R
    y = z - x[0]
    k = np.empty(d)
    for a in range(d):
        k[a] = P[a, 0] / S
    for a in range(d):
        x[a] += k[a] * y
    p0 = np.empty(d)
    for b in range(d):
        p0[b] = P[0, b]
    # Joseph's form (filterpy's): (I - k H) P (I - k H)^T + k R k^T.
    for a in range(d):
        for b in range(a, d):
            v = P[a, b] - k[a] * p0[b] - p0[a] * k[b] + k[a] * k[b] * S
            P[a, b] = v
            P[b, a] = v
    nis = y * y / S
    # filterpy's likelihood, floored at the smallest normal float.
    return max(math.exp(-0.5 * nis) / math.sqrt(2.0 * math.pi * S), 2.2250738585072014e-308), nis


def combine(mu, xs, Ps, x, P):  # noqa: ANN001, ANN201 (numba kernel)
    """The mixture's mean ``x`` and covariance ``P`` of the modes ``(xs[i], Ps[i])`` with
    weights ``mu``."""
    m, d = xs.shape
    for a in range(d):
        s = 0.0
        for i in range(m):
            s += mu[i] * xs[i, a]
        x[a] = s
    for a in range(d):
        for b in range(d):
            s = 0.0
            for i in range(m):
                s += mu[i] * (Ps[i, a, b] + (xs[i, a] - x[a]) * (xs[i, b] - x[b]))
            P[a, b] = s


def bank_step(x, P, Q, cx, gx, qv, shift, seen, z, noise, logw, forget):  # noqa: ANN001, ANN201 (numba kernel)
    """One sample of the wheels' filters: ``x`` (H, n, 2) contact positions and speed offsets,
    ``P`` (H, n, 3) their covariances ``(p_xx, p_xo, p_oo)``, ``Q`` (H, 3) each hypothesis's
    process noise per period. Per wheel: ``x+ = x + cx + gx o`` (the law's displacement and
    the offset's), ``o+ = o`` plus ``qv`` on its variance (the law's own error). The reading
    ``z`` (noise variance ``noise``) sees the contact through the gearbox play: ``x + shift``
    where ``seen`` is 1 (the play engaged), nothing where it is 0 (the encoder stands in the
    play: no update). Sets ``logw[H] <- forget logw - sum_i (y^2 / S + log S) / 2`` over the
    wheels seen."""
    H, n = x.shape[0], x.shape[1]
    for hyp in range(H):
        total = 0.0
        for i in range(n):
            g = gx[i]
            x[hyp, i, 0] += cx[i] + g * x[hyp, i, 1]
            p00 = P[hyp, i, 0] + 2.0 * g * P[hyp, i, 1] + g * g * P[hyp, i, 2] + Q[hyp, 0]
            p01 = P[hyp, i, 1] + g * P[hyp, i, 2] + Q[hyp, 1]
            p11 = P[hyp, i, 2] + Q[hyp, 2] + qv[i]
            if seen[i] > 0.0:
                S = p00 + noise[i]
                y = z[i] - (x[hyp, i, 0] + shift[i])
                k0 = p00 / S
                k1 = p01 / S
                x[hyp, i, 0] += k0 * y
                x[hyp, i, 1] += k1 * y
                p11 = p11 - k1 * p01
                p01 = p01 - k0 * p01
                p00 = p00 - k0 * p00
                total += y * y / S + math.log(S)
            P[hyp, i, 0] = p00
            P[hyp, i, 1] = p01
            P[hyp, i, 2] = p11
        logw[hyp] = forget * logw[hyp] - 0.5 * total


def predicted_first(cbar, means, rows0, Ps0, Qs):  # noqa: ANN001, ANN201 (numba kernel)
    """With mode probabilities ``cbar`` (m,), predicted means ``means`` (m, d), the first rows
    of the transitions ``rows0`` (m, d) from the mixed covariances ``Ps0`` (m, d, d) and the
    process noises ``Qs`` (m, 2, 2): the mixture's ``(mean of x0, variance of x0, mean of
    x1)``, the variance ``sum_j cbar_j (r_j P0_j r_j^T + Q_j[0, 0] + (mean_j - mean)^2)``."""
    m, d = means.shape[0], means.shape[1]
    x0 = 0.0
    x1 = 0.0
    for j in range(m):
        x0 += cbar[j] * means[j, 0]
        x1 += cbar[j] * means[j, 1]
    var = 0.0
    for j in range(m):
        quad = 0.0
        for a in range(d):
            ra = rows0[j, a]
            if ra == 0.0:
                continue
            row = 0.0
            for b in range(d):
                row += Ps0[j, a, b] * rows0[j, b]
            quad += ra * row
        dev = means[j, 0] - x0
        var += cbar[j] * (quad + Qs[j, 0, 0] + dev * dev)
    return x0, var, x1


def bank_moments(x, P, logw, drifts, o, var):  # noqa: ANN001, ANN201 (numba kernel)
    """After :func:`bank_step`: ``logw`` shifted to its maximum 0 (in place), the weights
    ``w = exp(logw) / sum``, and per wheel the mixture's offset mean ``o[i] = sum_h w_h
    x[h, i, 1]`` and variance ``var[i] = sum_h w_h (P[h, i, 2] + (x[h, i, 1] - o[i])^2)``
    (written in place); returns ``sum_h w_h drifts[h]``."""
    H, n = x.shape[0], x.shape[1]
    top = logw[0]
    for h in range(1, H):
        top = max(top, logw[h])
    w = np.empty(H)
    total = 0.0
    for h in range(H):
        logw[h] -= top
        w[h] = math.exp(logw[h])
        total += w[h]
    drift = 0.0
    for h in range(H):
        w[h] /= total
        drift += w[h] * drifts[h]
    for i in range(n):
        m = 0.0
        for h in range(H):
            m += w[h] * x[h, i, 1]
        v = 0.0
        for h in range(H):
            d = x[h, i, 1] - m
            v += w[h] * (P[h, i, 2] + d * d)
        o[i] = m
        var[i] = v
    return drift


def sign_of(v):  # noqa: ANN001, ANN201 (numba kernel)
    """-1, 0 or 1: the sign of ``v``."""
    return 1 if v > 0.0 else (-1 if v < 0.0 else 0)


def play_loaded(shift, start, end, o, half, loaded):  # noqa: ANN001, ANN201 (numba kernel)
    """Per wheel, 1 where the encoder stays engaged behind its contact over the period (the
    play operator's fixed point: the encoder ``shift`` from the contact is the play's half
    width ``half`` to 1e-9 relative, behind a contact whose speed ``start + o`` to ``end +
    o`` keeps its sign), else 0, in ``loaded``; returns how many are not. Without play
    (``half = 0``) every wheel is loaded."""
    n = shift.shape[0]
    missing = 0
    tol = 1e-9 * max(half, 1e-12)
    for i in range(n):
        ok = half == 0.0
        if not ok:
            a, b = start[i] + o[i], end[i] + o[i]
            sa = sign_of(a)
            sb = sign_of(b)
            ok = abs(abs(shift[i]) - half) <= tol and sa == sb and sb == -sign_of(shift[i])
        loaded[i] = 1.0 if ok else 0.0
        if not ok:
            missing += 1
    return missing


def bank_push(x, P, Q, start, end, cx, gx, law, y, wheels, q, noise, logw, forget, half, drifts, shift, loaded,
              speeds, var):  # noqa: ANN001, ANN201 (numba kernel)
    """:class:`WheelSpeedBank`'s sample where every encoder stays engaged (:func:`play_loaded`
    of the most likely hypothesis ``best``, ``shift = y - x[best, :, 0]``, written in
    ``shift`` and ``loaded``): :func:`bank_step` with the readings ``z = (wheels + 0.5) q``
    (counts to m, the cell's middle), the law's displacement ``cx`` and its error ``(law (end
    - start))^2``, the encoders' side ``y <- x[best, :, 0] + shift`` and :func:`bank_moments`;
    writes the contacts' speeds ``end + o`` (the law's end speeds plus the offsets' mixture
    mean) in ``speeds`` and their variances in ``var``, and returns the wander intensity.
    Where some encoder walks its play, returns -1 having changed nothing but ``shift`` and
    ``loaded`` (the caller follows the play operator along the period)."""
    H, n = x.shape[0], x.shape[1]
    best = 0
    for h in range(1, H):
        if logw[h] > logw[best]:
            best = h
    o = np.empty(n)
    for i in range(n):
        shift[i] = y[i] - x[best, i, 0]
        o[i] = x[best, i, 1]
    if play_loaded(shift, start, end, o, half, loaded) > 0:
        return -1.0
    qv = np.empty(n)
    z = np.empty(n)
    for i in range(n):
        d = law * (end[i] - start[i])
        qv[i] = d * d
        z[i] = cell_centre(wheels[i], q)
    bank_step(x, P, Q, cx, gx, qv, shift, loaded, z, noise, logw, forget)
    for i in range(n):
        y[i] = x[best, i, 0] + shift[i]
    drift = bank_moments(x, P, logw, drifts, o, var)
    for i in range(n):
        speeds[i] = end[i] + o[i]
    return drift


def cycle(Ps0, means, rows0, rows1, Qs, qtheta, cbar, z, R, xs, Ps, mu, x, P, nis):  # noqa: ANN001, ANN201
    """One IMM step after mixing: mode ``j``'s covariance ``A_j Ps0[j] A_j^T + Q_j`` (rows
    ``rows0[j]``, ``rows1[j]``; :func:`predict_rows`) about its predicted mean ``means[j]``,
    the update with ``z`` (variance ``R``), ``mu = cbar * likelihood`` normalized, and the
    mixture ``(x, P)``; ``xs``, ``Ps``, ``mu``, ``x``, ``P`` and each mode's NIS ``nis``
    written in place."""
    m = means.shape[0]
    total = 0.0
    for j in range(m):
        predict_rows(Ps0[j], rows0[j], rows1[j], Qs[j], qtheta, Ps[j])
        for a in range(means.shape[1]):
            xs[j, a] = means[j, a]
        likelihood, nis[j] = update_first(xs[j], Ps[j], z, R)
        mu[j] = cbar[j] * likelihood
        total += mu[j]
    for j in range(m):
        mu[j] /= total
    combine(mu, xs, Ps, x, P)


def measure_cycle(Ps0, means, rows0, rows1, Qs, qtheta, cbar, z, R0, noise, xs, Ps, mu, x, P, nis):  # noqa: ANN001, ANN201
    """:func:`predicted_first`, the measurement noise and :func:`cycle` in one call. The
    noise is ``R0`` plus the larger of two models of the extra noise at the predicted speed
    ``V`` (``noise`` = ``(a, b, c, d)``: ``a + b V^2`` matched from the innovations, ``c + d
    V^2`` from the wheels' residuals). Returns ``(x0, var, V, nis_mean)``: the mixture's
    predicted first state, its variance (without ``R0``), its predicted second state and the
    mode-weighted NIS of the update (``sum_j mu_j nis_j``)."""
    x0, var, speed = predicted_first(cbar, means, rows0, Ps0, Qs)
    matched = noise[0] + noise[1] * speed * speed
    wheel = noise[2] + noise[3] * speed * speed
    cycle(Ps0, means, rows0, rows1, Qs, qtheta, cbar, z, R0 + max(matched, wheel), xs, Ps, mu, x, P, nis)
    total = 0.0
    for j in range(mu.shape[0]):
        total += mu[j] * nis[j]
    return x0, var, speed, total


def predict_held(x, start, target, var, k, h, h3, drift2, mean, row0, row1, Q):  # noqa: ANN001, ANN201
    """The stuck mode's prediction while contact ``k`` holds its speed: the body rides it
    (``k < 0``: the contact nearest the speed ``x[1]``, the first of equals). Writes the
    mean (``X + v_k h``, ``v_k``), the transition's rows 0 and 1 (``row0`` = (1, 0, ..),
    ``row1`` = 0: the speed is the contact's whatever the body's was) and ``Q``: the contact's
    error ``var[k]`` carried over the period plus its wander ``drift2`` (squared intensity;
    ``h3 = h^3``). Returns ``k``, or ``-1 - k`` having written nothing when
    the contact moves (``start[k] != target[k]``: the caller follows the motor law)."""
    if k < 0:
        k = 0
        best = abs(start[0] - x[1])
        for i in range(1, start.shape[0]):
            gap = abs(start[i] - x[1])
            if gap < best:
                best = gap
                k = i
    v = start[k]
    if v != target[k]:
        return -1 - k
    d = x.shape[0]
    for a in range(d):
        mean[a] = x[a]
        row0[a] = 0.0
        row1[a] = 0.0
    mean[0] = x[0] + v * h
    mean[1] = v
    row0[0] = 1.0
    held_noise(var[k], h, h3, drift2, Q)
    return k


def held_noise(var, h, h3, drift2, Q):  # noqa: ANN001, ANN201
    """The stuck mode's process noise of ``(X, V)`` (:func:`predict_held`), in ``Q``: the
    contact's error ``var`` ((m/s)^2) held over the period, plus the white-noise acceleration
    model's ``drift2 [[h^3 / 3, h^2 / 2], [h^2 / 2, h]]`` (``h3 = h^3``)."""
    Q[0, 0] = var * h * h + drift2 * h3 / 3.0
    Q[0, 1] = var * h + drift2 * h * h / 2.0
    Q[1, 0] = Q[0, 1]
    Q[1, 1] = var + drift2 * h


def predict_walk(x, h, walk, s2, mean, row0, row1, Q):  # noqa: ANN001, ANN201
    """The free-form mode's prediction: the speed a random walk of squared intensity ``s2``
    (``walk = (h^3 / 3, h^2 / 2, h)``): mean ``(X + h V, V)``, rows ``(1, h, 0 ..)`` and ``(0,
    1, 0 ..)``, ``Q = s2 walk`` (in place)."""
    d = x.shape[0]
    for a in range(d):
        mean[a] = x[a]
        row0[a] = 0.0
        row1[a] = 0.0
    mean[0] = x[0] + h * x[1]
    row0[0] = 1.0
    row0[1] = h
    row1[1] = 1.0
    Q[0, 0] = s2 * walk[0]
    Q[0, 1] = s2 * walk[1]
    Q[1, 0] = s2 * walk[1]
    Q[1, 1] = s2 * walk[2]


def ride_step(level, var, grid, y, R, jumps, loglik):  # noqa: ANN001, ANN201 (numba kernel)
    """One sample of the ridden wheel's check (:class:`toolkit.estimation.RideCheck`), for
    every missed-count rate ``grid[g]``: the difference ``y`` (m) of the body's and the ridden
    wheel's positions read as counts is a level ``N(level[g], var[g])`` seen through white
    noise of variance ``R`` (m^2); over the period the losses move the level by a step of
    mean 0 and variance ``p jumps`` (``jumps``: the transitions times their squared counts,
    m^2). The Kalman update of the level (in place), and ``loglik[g]`` gains the log of the
    reading's Gaussian density."""
    half_log_2pi = 0.5 * math.log(2.0 * math.pi)
    for g in range(grid.size):
        P = var[g] + grid[g] * jumps
        F = P + R
        v = y - level[g]
        loglik[g] -= 0.5 * (v * v / F + math.log(F)) + half_log_2pi
        level[g] += P / F * v
        var[g] = P * R / F


def ride_push(state, ring, level, var, grid, loglik, y, travel, qc, qw, h, slope, noise_over, rate_mean):  # noqa: ANN001, ANN201, E501 (numba kernel)
    """One sample of the ridden wheel's check on the contact it has ridden since ``state[0] =
    0`` (:class:`toolkit.estimation.RideCheck`, whose docstring states the rules): ``y`` the
    difference of the positions read (m), ``travel`` the period's (m), ``qc``, ``qw`` the
    counts (m), ``h`` the period (s). ``state``: the readings since the ride began, the
    window's sums of the readings and of the readings times their index in ``ring`` (the
    last ``ring.size``), the sums of the squared steps, of the quantizations' share of them
    and of the travel over the steps that end a level window (every ride's), those steps,
    whether the check is open. Returns 1 where :func:`ride_step` added the sample's
    log-likelihoods, else 0."""
    n = ring.size
    count = int(state[0])
    step = y - ring[(count - 1) % n] if count > 0 else 0.0
    if count < n:
        ring[count] = y
        state[2] += count * y
        state[1] += y
        state[0] = count + 1
        if count + 1 < n:
            return 0
    else:
        slot = count % n
        state[2] += (n - 1) * y - (state[1] - ring[slot])
        state[1] += y - ring[slot]
        ring[slot] = y
        state[0] = count + 1
    R = read_variance(state, qc, qw, rate_mean)
    S = n * (n * n - 1) / 12.0
    fit = (state[2] - 0.5 * (n - 1) * state[1]) / (h * S)
    if not abs(fit) <= slope + 4.0 * math.sqrt(R / S) / h:
        # Not level (another contact, a slip, a play taken up): neither read nor measured.
        state[7] = 0.0
        return 0
    a = travel / qc % 1.0
    b = travel / qw % 1.0
    state[3] += step * step
    state[4] += qc * qc * a * (1.0 - a) + qw * qw * b * (1.0 - b)
    state[5] += travel
    state[6] += 1.0
    R = read_variance(state, qc, qw, rate_mean)
    if R < noise_over * quantization_variance(qc, qw):
        state[7] = 0.0
        return 0
    if state[7] == 0.0:
        state[7] = 1.0
        level[:] = y
        var[:] = R
        return 0
    ride_step(level, var, grid, y, R, travel * (qc + qw), loglik)
    return 1


def read_variance(state, qc, qw, rate_mean):  # noqa: ANN001, ANN201 (numba kernel)
    """The check's read noise variance (m^2) from its sums (:func:`ride_push`): the two
    quantizations' ``(qc^2 + qw^2) / 12`` plus half the mean squared step less the
    quantizations' and the losses' share (at ``rate_mean``), at least 0."""
    floor = quantization_variance(qc, qw)
    if state[6] == 0.0:
        return floor
    losses = rate_mean * state[5] * (qc + qw)
    return max(0.5 * (state[3] - state[4] - losses) / state[6], 0.0) + floor


def rate_moments(grid, log_grid, loglik, shape, rate, out):  # noqa: ANN001, ANN201 (numba kernel)
    """Mean and variance (``out[0]``, ``out[1]``) of the missed-count rate whose posterior is
    the Gamma density ``p^(shape - 1) exp(-rate p)`` times ``exp(loglik)`` on ``grid`` (rates
    evenly spaced in ``log p``, ``log_grid`` their logarithms): trapezoid sums in ``u = log
    p`` of the density times ``p``. Where the posterior is narrower than 0.7 of the grid's
    spacing (its log density's curvature in ``u`` above ``2 / du^2``; there the sums' error
    of a Gaussian, ``2 exp(-2 pi^2 sigma^2 / du^2)``, passes 1e-4)
    the density ``exp(c + a u - b e^u)`` through the three points about its peak instead: a
    Gamma density in ``p``, mean ``a / b``, variance ``a / b^2`` (exact where the posterior is
    Gamma, as with repairs alone). Where the peak is the grid's top (the mass lies above it)
    or not finite, the Gamma ``(shape, rate)`` alone."""
    G = grid.size
    du = log_grid[1] - log_grid[0]
    top = -math.inf
    peak = 0
    for g in range(G):
        value = shape * log_grid[g] - rate * grid[g] + loglik[g]
        if value > top:
            top = value
            peak = g
    if peak == G - 1 or not math.isfinite(top):
        # The posterior's mass lies above the grid (or the likelihood is not finite): the
        # check says nothing there, the Gamma alone.
        out[0] = shape / rate
        out[1] = shape / (rate * rate)
        return
    if peak > 0:
        lo = shape * log_grid[peak - 1] - rate * grid[peak - 1] + loglik[peak - 1]
        hi = shape * log_grid[peak + 1] - rate * grid[peak + 1] + loglik[peak + 1]
        bend = hi - 2.0 * top + lo
        if -bend > 2.0:
            # l(u) = c + a u - b e^u through the three points: the second difference gives b,
            # the first a.
            b = -bend / (grid[peak] * (2.0 * math.cosh(du) - 2.0))
            a = (hi - top + b * grid[peak] * (math.exp(du) - 1.0)) / du
            out[0] = a / b
            out[1] = a / (b * b)
            return
    s0 = s1 = s2 = 0.0
    for g in range(G):
        w = math.exp(shape * log_grid[g] - rate * grid[g] + loglik[g] - top)
        if g == 0 or g == G - 1:
            w *= 0.5
        s0 += w
        s1 += w * grid[g]
        s2 += w * grid[g] * grid[g]
    if not (s0 > 0.0 and math.isfinite(s0) and math.isfinite(s2)):
        out[0] = shape / rate
        out[1] = shape / (rate * rate)
        return
    mean = s1 / s0
    out[0] = mean
    out[1] = max(s2 / s0 - mean * mean, 0.0)
