"""The encoders' extra noise fitted from residuals (``toolkit.estimation.monitor.fit_noise``,
``NoiseMatcher``) within the sensor law's bounds: read noise ``a >= 0`` and jitter
``0 <= b <= b_max``, where ``b_max`` is the square of the largest jitter the sensors allow
(``MAX_JITTER_PERIODS`` of a period)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from toolkit.estimation import AdaptiveKalman
from toolkit.estimation.monitor import NoiseMatcher, fit_noise
from toolkit.model.sensors import MAX_JITTER_PERIODS


def _bounded(e, x, b_max):
    """The second method: scipy's bounded linear least squares (BVLS) of e ~ a + b x, its
    columns scaled to order 1 (x by its mean, e by its largest value) so that its tolerance
    means the same at every scale."""
    xs, es = x.mean(), np.abs(e).max()
    A = np.column_stack((np.ones_like(x), x / xs))
    a, c = lsq_linear(A, e / es, bounds=([0.0, 0.0], [np.inf, b_max * xs / es]), method="bvls", tol=1e-15).x
    return a * es, c * es / xs


@pytest.mark.parametrize("scale", [2.0 ** -20, 1.0, 2.0 ** 20])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_jitter_beyond_its_bound_is_fitted_at_the_bound(scale, seed):
    # An excess that grows with V^2 over speeds that hardly change (a body held at 8-9 mm/s,
    # its estimate wandering): the free fit puts it on V^2, b far above any jitter the
    # sensors allow; bounded, b = b_max exactly and a is the rest, as BVLS finds it (1e-9
    # relative: two solvers' rounding). Speeds scaled by `scale`, the bound by 1/scale^2.
    rng = np.random.default_rng(seed)
    h = 1.0 / 364.0
    b_max = (MAX_JITTER_PERIODS * h) ** 2 / scale ** 2
    x = (rng.uniform(8e-3, 9e-3, 200) * scale) ** 2
    e = 7.6e-8 * x / x.mean() + rng.normal(0.0, 1e-9, 200)
    free_a, free_b = fit_noise(e, x)
    assert free_b > b_max                                  # (what the bound is there for)
    a, b = fit_noise(e, x, b_max)
    assert b == b_max
    want = _bounded(e, x, b_max)
    assert a == pytest.approx(want[0], rel=1e-9) and b == pytest.approx(want[1], rel=1e-9)
    assert np.sum((e - a - b * x) ** 2) <= np.sum((e - free_a - min(free_b, b_max) * x) ** 2)


def test_a_bound_above_the_free_fit_changes_nothing():
    rng = np.random.default_rng(3)
    x = rng.uniform(0.05, 0.3, 40) ** 2
    e = 2e-10 + 1e-8 * x + rng.normal(0.0, 2e-11, 40)
    a, b = fit_noise(e, x)
    assert fit_noise(e, x, 1.0001 * b) == (a, b)
    bounded = fit_noise(e, x, 0.9999 * b)                  # (just below: the bound holds)
    assert bounded[1] == 0.9999 * b


def test_no_jitter_allowed_leaves_the_mean_excess_as_read_noise():
    e = np.array([1e-10, 3e-10, 2e-10, 6e-10])
    x = np.array([0.01, 0.04, 0.09, 0.16])
    assert fit_noise(e, x, 0.0) == (pytest.approx(np.mean(e), rel=1e-15), 0.0)
    matcher = NoiseMatcher(20, jitter_max=0.0)
    for y, v in zip(np.sqrt(e + 1e-9), np.sqrt(x)):
        matcher.push(float(y), 0.5e-9, 0.5e-9, float(v))
    assert (matcher.a, matcher.b) == (pytest.approx(np.mean(e), rel=1e-12), 0.0)


def test_the_matcher_bounds_its_jitter_by_the_square_of_jitter_max():
    # Excesses that grow as (1 ms)^2 V^2 against a bound of 0.3 ms: every refit puts b at
    # the bound, 0.3 ms squared (9e-8 s^2, neither 2 x 0.3 ms nor its cube), a the rest of
    # the fit (fit_noise with that bound on the same rows, to the bit).
    rng = np.random.default_rng(5)
    matcher = NoiseMatcher(20, jitter_max=3e-4)
    rows = []
    for k in range(40):
        speed = rng.uniform(0.05, 0.3)
        innovation = math.sqrt(2e-9 + 1e-6 * speed * speed)
        matcher.push(innovation, 1e-9, 1e-9, speed)
        rows.append((innovation * innovation - 2e-9, speed * speed))
    table = np.array(rows[-20:])
    table = table[np.argsort(table[:, 0])[:19]]
    assert matcher.b == 3e-4 ** 2
    assert (matcher.a, matcher.b) == fit_noise(table[:, 0], table[:, 1], 3e-4 ** 2)


def test_the_matcher_refuses_a_negative_bound():
    with pytest.raises(ValueError, match=r"'jitter_max' parameter of NoiseMatcher must be >= 0"):
        NoiseMatcher(20, jitter_max=-1e-3)


@pytest.mark.parametrize("rate", [20.0, 364.0])
def test_the_adaptive_filter_bounds_jitter_by_the_sensor_law(rate):
    from toolkit.estimation import EstimatorModel
    from toolkit.model.sensors import Encoder, Sensors

    sensors = Sensors(Encoder(8192.0, 0.266, rate), Encoder(3591.84, 0.045, rate, backlash=8e-4), 3)
    adaptive = AdaptiveKalman(EstimatorModel(np.array([0.8, 0.3, 1.2]), 8.0, sensors))
    assert adaptive._noise.jitter_max == MAX_JITTER_PERIODS / rate
    assert math.isclose(adaptive._jitter_max, MAX_JITTER_PERIODS / rate, rel_tol=1e-15)
