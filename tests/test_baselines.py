"""The practitioner's baselines: first-order adaptive windowing (FOAW) and the alpha-beta
tracker. Closed forms (exact on a ramp, Kalata's gains equal to the Kalman steady state), a
second implementation of FOAW written from the paper's definitions (numpy.polyfit), and the
phase rule of the scores. ``make test`` runs the FOAW kernel tests compiled and as Python."""

from __future__ import annotations

import math

import numpy as np
import pytest

from toolkit import ParameterError
from toolkit._compiled import load
from toolkit.analysis.scenarios import carousel_brake_scenario
from toolkit.model.carousel import CAROUSEL
from toolkit.estimation import (AdaptiveWindow, AlphaBetaTracker, EstimatorModel, kalata_gains,
                                steady_state_gain)
from toolkit.estimation._base import phase_masks
from toolkit.model.sensors import EncoderRecord, Sensors

W = load("window")


def _second_foaw(t: np.ndarray, y: np.ndarray, n_max: int, d: float, best: bool) -> tuple[float, int]:
    """FOAW at the last sample, written again from the definitions: for n = 1, 2, ... fit the
    line (through the ends, or numpy.polyfit of degree 1) and accept while every reading is
    within d of it."""
    k = t.size - 1
    slope, used = 0.0, 0
    for n in range(1, min(n_max, k) + 1):
        tw, yw = t[k - n:], y[k - n:]
        if best:
            b, a = np.polyfit(tw - t[k], yw, 1)
            inside = np.abs(yw - (a + b * (tw - t[k]))) <= d
        else:
            b = (yw[-1] - yw[0]) / (tw[-1] - tw[0])
            inside = np.abs(yw[1:-1] - (yw[-1] + b * (tw[1:-1] - tw[-1]))) <= d
        if not inside.all():
            break
        slope, used = b, n
    return slope, used


@pytest.mark.parametrize("best", [False, True])
def test_foaw_is_exact_on_a_ramp_and_takes_the_longest_window(best):
    # Noise-free positions on a line: every window fits, so the window grows to n_max and
    # the slope is the line's to rounding (1e-12 relative).
    t = np.arange(60) * 0.02
    y = 0.3 + 0.1937 * t
    slope, n = W.foaw(t, y, t.size, 1e-6, best)
    assert n == t.size - 1
    assert slope == pytest.approx(0.1937, rel=1e-12)
    # Fewer readings than the window: the longest the readings allow.
    assert W.foaw(t[:5], y[:5], 5, 1e-6, best)[1] == 4
    assert W.foaw(t[:1], y[:1], 1, 1e-6, best) == (0.0, 0)


@pytest.mark.parametrize("best", [False, True])
def test_foaw_equals_a_second_implementation_on_quantized_motion(best):
    # Quantized readings of a body that accelerates, cruises, then brakes, with read noise:
    # the kernel and the polyfit transcription pick the same window and slope at every
    # sample (the same arithmetic up to rounding: 1e-9 relative on the slope). The band is
    # 0.93 counts: readings are whole counts apart, so a band of whole counts would put
    # deviations exactly on it, where rounding decides.
    rng = np.random.default_rng(5)
    q, h = 2.04e-4, 0.02
    t = np.arange(300) * h
    speed = np.interp(t, [0, 1, 3, 3.5, 6], [0, 0.2, 0.2, -0.1, -0.1])
    x = np.concatenate(([0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * h))) + rng.uniform(0, q)
    y = (np.floor(x / q) + 0.5 + np.rint(rng.normal(0, 0.3, t.size))) * q
    for k in range(1, t.size):
        a = max(0, k - 40)
        got = W.foaw(t[a:k + 1], y[a:k + 1], k + 1 - a, 0.93 * q, best)
        want = _second_foaw(t[a:k + 1], y[a:k + 1], 40, 0.93 * q, best)
        assert got[1] == want[1], k
        assert got[0] == pytest.approx(want[0], rel=1e-9, abs=1e-12), k


def test_foaw_window_restarts_at_a_speed_step():
    # A body at 0.1 m/s that jumps to 0.2 m/s at sample 30 (unquantized): the end-fit windows
    # after the step hold only readings after it (a line through a kink misses the band of
    # 1 um by metres per second times seconds), so the slope is 0.2 exactly from 2 samples on.
    t = np.arange(50) * 0.02
    x = np.where(t < 0.6, 0.1 * t, 0.06 + 0.2 * (t - 0.6))
    for k in range(32, 50):
        slope, n = W.foaw(t[:k + 1], x[:k + 1], k + 1, 1e-6, False)
        assert n == k - 30 and slope == pytest.approx(0.2, rel=1e-12)


def test_foaw_estimator_on_a_record_uses_the_kernel_on_the_last_window():
    sc = carousel_brake_scenario(seed=1, t_end=3.0, brake_time=1.5)
    rec = sc.record
    q = sc.sensors.central.distance_per_count
    est = AdaptiveWindow(sc.sensors, fit="best", max_window=20)
    result = est.run(rec)
    y = (rec.central_counts + 0.5) * q
    for k in (1, 10, 60, 80, 149):
        a = max(0, k - 20)
        slope, _ = _second_foaw(rec.times[a:k + 1], y[a:k + 1], 20, q / 2, True)
        assert result.speed[k] == pytest.approx(slope, rel=1e-9, abs=1e-12)
    assert result.nees is None and result.nees_in_band is None
    with pytest.raises(ParameterError, match="^The 'fit' parameter of AdaptiveWindow must"):
        AdaptiveWindow(sc.sensors, fit="middle")
    with pytest.raises(ParameterError, match="^The 'max_window' parameter of AdaptiveWindow must"):
        AdaptiveWindow(sc.sensors, max_window=0)


@pytest.mark.parametrize("accel_std", [0.01, 0.3, 2.0, 40.0])
def test_kalata_gains_are_the_kalman_steady_state(accel_std):
    # Kalata's closed form against the Riccati fixed point iterated with filterpy (white
    # acceleration, R = q^2 / 12): K = (alpha, beta / h), equal to the iteration's 1e-12
    # tolerance (1e-9 relative asserted), over four decades of the tracking index.
    sensors = CAROUSEL.sensors()
    model = EstimatorModel(np.ones(10), 5.0, sensors)
    gain, prior = steady_state_gain(model, accel_std)
    tracker = AlphaBetaTracker(sensors, accel_std)
    h = sensors.period
    np.testing.assert_allclose([tracker.alpha, tracker.beta / h], gain[:, 0], rtol=1e-9)
    # Its steady covariance is the filter's posterior (I - K H) P (identity; 1e-7 relative:
    # at large indices alpha -> 1 and P - K H P cancels to about 1e-8 of P).
    posterior = prior - gain @ prior[:1, :]
    np.testing.assert_allclose(tracker.covariance, posterior, rtol=1e-7)


def test_kalata_gains_limits():
    # Lambda -> 0: alpha ~ sqrt(2 Lambda), beta ~ Lambda (the slow filter); Lambda -> inf:
    # alpha -> 1, beta -> 2 (the finite difference): to the next order of each expansion.
    alpha, beta = kalata_gains(1e-8)
    assert alpha == pytest.approx(math.sqrt(2e-8), rel=1e-3) and beta == pytest.approx(1e-8, rel=1e-3)
    alpha, beta = kalata_gains(1e6)
    assert alpha == pytest.approx(1.0, abs=1e-5) and beta == pytest.approx(2.0, abs=1e-5)
    with pytest.raises(ParameterError, match="'index' parameter of kalata_gains"):
        kalata_gains(0.0)


def test_alpha_beta_tracks_a_constant_speed_without_error():
    # A type-2 loop: on readings of a line (a speed of a whole number of counts per period,
    # so the readings carry no quantization error) the speed error decays to zero,
    # geometrically at the error dynamics' pole radius sqrt(1 - alpha) (z^2 - (2 - alpha -
    # beta) z + 1 - alpha; 0.29 at sigma_a = 0.5 m/s^2): after 400 samples below 1e-9 m/s.
    sensors = CAROUSEL.sensors()
    q, h = sensors.central.distance_per_count, sensors.period
    V = 7 * q / h
    k = np.arange(400)
    counts = 7 * k
    record = EncoderRecord(k * h, counts, np.zeros((400, 1), dtype=np.int64), np.zeros((400, 1)), q,
                           sensors.wheel.distance_per_count)
    result = AlphaBetaTracker(sensors, 0.5).run(record)
    assert abs(result.speed[-1] - V) < 1e-9


def test_phases_follow_the_largest_command_change():
    sc = carousel_brake_scenario(seed=0, t_end=8.0, brake_time=4.0)
    masks = phase_masks(sc.record)
    t = sc.record.times
    np.testing.assert_array_equal(masks["startup"], t < 1.0)
    np.testing.assert_array_equal(masks["cruise"], (t >= 1.0) & (t < 4.0))
    np.testing.assert_array_equal(masks["brake"], (t >= 4.0) & (t < 5.0))
    np.testing.assert_array_equal(masks["braked"], t >= 5.0)
    # No change after the first sample: no brake and nothing braked.
    short = carousel_brake_scenario(seed=0, t_end=3.0, brake_time=4.0)
    masks = phase_masks(short.record)
    assert masks["brake"] is None and masks["braked"] is None
    np.testing.assert_array_equal(masks["cruise"], short.record.times >= 1.0)
