"""The baselines' laws, one by one: the alpha-beta tracker's recursion, tuning and refusals
(toolkit.estimation.alpha_beta), the finite differences (toolkit.estimation.finite_difference),
the FOAW estimator's variances (toolkit.estimation.window) and its kernel's band and origin
(toolkit._compiled.window). Each estimate is checked
against the recursion written again from its definition, on unevenly spaced samples, and
each refusal is matched whole."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from toolkit import ParameterError, ParameterTypeError, _compiled
from toolkit.estimation import (AdaptiveWindow, AlphaBetaTracker, CentralDifference, WheelDifference,
                                kalata_gains)
from toolkit.model.carousel import CAROUSEL
from toolkit.model.sensors import EncoderRecord, EncoderSample

SENSORS = CAROUSEL.sensors()
Q_C = SENSORS.central.distance_per_count
Q_W = SENSORS.wheel.distance_per_count
H = SENSORS.period
SCALES = [2.0 ** -20, 1.0, 2.0 ** 20]


def _uneven_record(seed: int, n: int = 60, truth: bool = False) -> EncoderRecord:
    """A record of a body that speeds up and slows down, read at unevenly spaced times (each
    period drawn in [0.5 h, 1.5 h]), its counts the floor of the position over q."""
    rng = np.random.default_rng(seed)
    times = np.concatenate(([0.0], np.cumsum(rng.uniform(0.5 * H, 1.5 * H, n - 1))))
    speed = 0.2 * np.sin(2.0 * times) + 0.05
    position = 0.013 + (1.0 - np.cos(2.0 * times)) * 0.1 + 0.05 * times
    counts = np.floor(position / Q_C).astype(np.int64)
    wheels = np.floor(np.outer(position, [1.0, 1.1, 0.9]) / Q_W).astype(np.int64)
    extra = dict(truth_speed=speed, truth_position=position) if truth else {}
    return EncoderRecord(times, counts, wheels, np.zeros((n, 3)), Q_C, Q_W, **extra)


def _alpha_beta_again(times, counts, alpha, beta, speed0):
    """The alpha-beta recursion from its definition: X- = X + h V, r = z - X-, X = X- +
    alpha r, V = V + (beta / h) r, z the count's cell centre, h each sample's own period."""
    X, V = (counts[0] + 0.5) * Q_C, speed0
    out = [(X, V)]
    for k in range(1, times.size):
        h = times[k] - times[k - 1]
        predicted = X + h * V
        r = (counts[k] + 0.5) * Q_C - predicted
        X, V = predicted + alpha * r, V + beta / h * r
        out.append((X, V))
    return np.array(out)


def test_the_tracker_runs_the_alpha_beta_recursion_over_each_samples_own_period():
    # Unevenly spaced samples: the recursion with each sample's own h (a nominal period in its
    # place errs by tens of percent of h). Same arithmetic as the reference: 1e-12 relative.
    record = _uneven_record(3, truth=True)
    tracker = AlphaBetaTracker(SENSORS, 0.7)
    before = time.perf_counter()
    result = tracker.run(record, speed=0.04)
    after = time.perf_counter()
    want = _alpha_beta_again(record.times, record.central_counts, tracker.alpha, tracker.beta, 0.04)
    np.testing.assert_allclose(result.speed, want[:, 1], rtol=1e-12)
    np.testing.assert_allclose(result.position, want[:, 0], rtol=1e-12)
    assert result.method == "alpha_beta"
    # The steady covariance is reported at every sample, and its speed entry as the variance.
    K = record.n_samples
    assert result.covariance.shape == (K, 2, 2)
    assert (result.covariance == tracker.covariance).all()
    assert (result.variance == tracker.covariance[1, 1]).all()
    # The NEES of each sample is e^T P^-1 e of the errors of (X, V) against the truth
    # (solved again here; 1e-9 relative for the two inverses' rounding).
    e = np.stack((want[:, 0] - record.truth_position, want[:, 1] - record.truth_speed), axis=1)
    nees = np.array([row @ np.linalg.solve(tracker.covariance, row) for row in e])
    np.testing.assert_allclose(result.nees, nees, rtol=1e-9)
    # The wall time is the run's: between 0 and the time the call took.
    assert 0.0 <= result.wall_time <= after - before


def test_the_tracker_starts_at_the_first_cell_centre_and_the_speed_it_is_given():
    # Stepped by hand: the first sample sets X to its cell centre and V to reset's speed
    # (0 when none is given, in run and in reset alike).
    record = _uneven_record(4)
    tracker = AlphaBetaTracker(SENSORS, 0.7)
    assert tracker.run(record).speed[0] == 0.0
    tracker.reset()
    assert tracker.observe(record.sample(0)) == (0.0, float(tracker.covariance[1, 1]))
    tracker.reset(speed=-0.25)
    assert tracker.observe(record.sample(0))[0] == -0.25
    want = _alpha_beta_again(record.times, record.central_counts, tracker.alpha, tracker.beta, -0.25)
    for k in range(1, 5):
        assert tracker.observe(record.sample(k))[0] == pytest.approx(want[k, 1], rel=1e-12)


def test_the_trackers_gains_and_steady_covariance_are_kalatas_and_read_only():
    # The tracking index is sigma_a h^2 / sigma_z with sigma_z = q / sqrt(12) (1e-15 relative:
    # the same products); the steady covariance is sigma_z^2 [[a, b / h], [b / h,
    # b (2 a - b) / (2 (1 - a) h^2)]] (Kalata's; 1e-12 relative), and it cannot be written.
    tracker = AlphaBetaTracker(SENSORS, 0.7)
    assert tracker.sensors is SENSORS
    sigma_z = Q_C / math.sqrt(12.0)
    assert tracker.index == pytest.approx(0.7 * H * H / sigma_z, rel=1e-15)
    a, b = kalata_gains(tracker.index)
    assert (tracker.alpha, tracker.beta) == (a, b)
    want = sigma_z ** 2 * np.array([[a, b / H], [b / H, b * (2 * a - b) / (2 * (1 - a) * H * H)]])
    np.testing.assert_allclose(tracker.covariance, want, rtol=1e-12)
    assert not tracker.covariance.flags.writeable
    with pytest.raises(ValueError):
        tracker.covariance[0, 0] = 1.0


@pytest.mark.parametrize("scale", SCALES)
def test_the_tuned_tracker_takes_half_the_total_force_over_the_mass(scale):
    # sigma_a = F_tot / (2 m): unequal force and mass scaled together by a power of two give
    # the same acceleration to the bit, and the same gains as the constructor given it.
    tuned = AlphaBetaTracker.tuned(SENSORS, 3.0 * scale, 5.0 * scale)
    assert tuned.accel_std == 0.3
    direct = AlphaBetaTracker(SENSORS, 0.3)
    assert (tuned.alpha, tuned.beta) == (direct.alpha, direct.beta)
    assert tuned.sensors is SENSORS


@pytest.mark.parametrize("call, error, message", [
    (lambda: AlphaBetaTracker("carousel", 1.0), ParameterTypeError,
     "The 'sensors' parameter of AlphaBetaTracker must be a Sensors. Got 'carousel' instead."),
    (lambda: AlphaBetaTracker(SENSORS, 0.0), ParameterError,
     "The 'accel_std' parameter of AlphaBetaTracker must be > 0. Got 0.0 instead."),
    (lambda: AlphaBetaTracker(SENSORS, -1.0), ParameterError,
     "The 'accel_std' parameter of AlphaBetaTracker must be > 0. Got -1.0 instead."),
    (lambda: AlphaBetaTracker.tuned(SENSORS, 0.0, 1.0), ParameterError,
     "The 'total_force' parameter of AlphaBetaTracker.tuned must be > 0. Got 0.0 instead."),
    (lambda: AlphaBetaTracker.tuned(SENSORS, 1.0, 0.0), ParameterError,
     "The 'mass' parameter of AlphaBetaTracker.tuned must be > 0. Got 0.0 instead."),
    (lambda: AlphaBetaTracker.tuned(SENSORS, "1", 1.0), ParameterTypeError,
     "The 'total_force' parameter of AlphaBetaTracker.tuned must be a real number. Got '1' instead."),
    (lambda: AlphaBetaTracker.tuned(SENSORS, 1.0, "1"), ParameterTypeError,
     "The 'mass' parameter of AlphaBetaTracker.tuned must be a real number. Got '1' instead."),
    (lambda: AlphaBetaTracker(SENSORS, 1.0).reset(speed=math.nan), ParameterError,
     "The 'speed' parameter of AlphaBetaTracker.reset must be finite. Got nan instead."),
])
def test_every_refusal_of_the_tracker_in_full(call, error, message):
    # Parameter, owner, rule and value, matched whole; the bounds are open (0 is refused).
    with pytest.raises(error) as info:
        call()
    assert str(info.value) == message


def _sample(t: float, central: int, wheels=(0, 0, 0)) -> EncoderSample:
    return EncoderSample(t, central, np.array(wheels, dtype=np.int64), np.zeros(len(wheels)))


def test_the_central_difference_is_the_count_change_over_each_samples_own_period():
    # V_k = (c_k - c_{k-1}) q / (t_k - t_{k-1}), with the variance of the difference of two
    # independent uniform errors, 2 (q^2 / 12) / h_k^2; before a second reading, the speed
    # given to reset with the nominal period's. Exact arithmetic of the same products
    # (1e-15 relative).
    estimator = CentralDifference(SENSORS)
    assert estimator.sensors is SENSORS
    estimator.reset(speed=0.125)
    first = estimator.observe(_sample(0.0, 40))
    assert first == (0.125, pytest.approx(2.0 * (Q_C * SENSORS.rate) ** 2 / 12.0, rel=1e-15))
    t, c = 0.0, 40
    for h, step in [(0.7 * H, 3), (1.3 * H, -5), (0.55 * H, 0)]:
        t, c = t + h, c + step
        speed, variance = estimator.observe(_sample(t, c))
        assert speed == pytest.approx(step * Q_C / h, rel=1e-15, abs=1e-300)
        assert variance == pytest.approx(2.0 * (Q_C / h) ** 2 / 12.0, rel=1e-12)
    estimator.reset()
    assert estimator.observe(_sample(1.0, 7))[0] == 0.0


@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize("forces, middle", [((2.0, 3.0, 1.0), 6.5), ((3.0, 1.5, 1.0), 4.0)])
def test_the_wheel_difference_is_the_weighted_median_of_the_wheels_differences(scale, forces, middle):
    # Wheels that moved 4, 9 and -2 counts over 0.7 periods: contact speeds (4, 9, -2) q / h.
    # Weights (2, 3, 1) leave the half total (3) on either side of the band [4, 9] q / h (the
    # body's speed its midpoint, 6.5 q / h); weights (3, 1.5, 1) put the median on the first
    # wheel's 4 q / h. Unequal weights at three scales (powers of two: the same median).
    sensors = CAROUSEL.sensors(3)
    estimator = WheelDifference(sensors, np.array(forces) * scale)
    assert estimator.sensors is sensors
    estimator.reset(speed=-0.5)
    q_rate = Q_W * sensors.rate
    assert estimator.observe(_sample(0.0, 0, (5, -3, 12))) == (-0.5, pytest.approx(q_rate ** 2 / 6.0, rel=1e-15))
    h = 0.7 * H
    speed, variance = estimator.observe(_sample(h, 0, (9, 6, 10)))
    np.testing.assert_allclose(estimator.contact_speeds, np.array([4.0, 9.0, -2.0]) * Q_W / h, rtol=1e-15)
    assert speed == pytest.approx(middle * Q_W / h, rel=1e-12)
    assert variance == pytest.approx(2.0 * (Q_W / h) ** 2 / 12.0, rel=1e-12)
    # The next period is 1.3 h long: its own (1, -1, 6) counts over it.
    speed, _ = estimator.observe(_sample(h + 1.3 * H, 0, (10, 5, 16)))
    np.testing.assert_allclose(estimator.contact_speeds, np.array([1.0, -1.0, 6.0]) * Q_W / (1.3 * H), rtol=1e-12)


def test_the_wheel_difference_takes_the_command_as_contact_speeds_only_before_a_difference():
    # After reset the contact speeds are 0 and a command leaves them; after the first reading
    # (no difference yet) the command is the best guess; after a difference it is not read.
    estimator = WheelDifference(CAROUSEL.sensors(3), [1.0, 2.0, 1.5])
    estimator.commanded([0.1, 0.2, 0.3])
    assert (estimator.contact_speeds == 0.0).all()
    assert estimator.observe(_sample(0.0, 0, (1, 2, 3)))[0] == 0.0
    estimator.commanded([0.1, 0.2, 0.3])
    assert estimator.contact_speeds.tolist() == [0.1, 0.2, 0.3]
    # Whole speeds given as integers are float speeds all the same.
    estimator.commanded([1, 0, -2])
    assert estimator.contact_speeds.dtype == np.float64 and estimator.contact_speeds.tolist() == [1.0, 0.0, -2.0]
    estimator.observe(_sample(H, 0, (1, 2, 3)))
    estimator.commanded([0.1, 0.2, 0.3])
    assert estimator.contact_speeds.tolist() == [0.0, 0.0, 0.0]
    estimator.reset()
    assert estimator.contact_speeds.tolist() == [0.0, 0.0, 0.0]


@pytest.mark.parametrize("call, error, message", [
    (lambda: CentralDifference("carousel"), ParameterTypeError,
     "The 'sensors' parameter of CentralDifference must be a Sensors. Got 'carousel' instead."),
    (lambda: WheelDifference("carousel", [1.0]), ParameterTypeError,
     "The 'sensors' parameter of WheelDifference must be a Sensors. Got 'carousel' instead."),
    (lambda: CentralDifference(SENSORS).reset(speed=math.inf), ParameterError,
     "The 'speed' parameter of CentralDifference.reset must be finite. Got inf instead."),
    (lambda: WheelDifference(CAROUSEL.sensors(1), [1.0]).reset(speed=math.inf), ParameterError,
     "The 'speed' parameter of WheelDifference.reset must be finite. Got inf instead."),
])
def test_every_refusal_of_the_finite_differences_in_full(call, error, message):
    with pytest.raises(error) as info:
        call()
    assert str(info.value) == message


WHITE = Q_C * Q_C / 12.0        # one reading's quantization variance


def _window_again(t: np.ndarray, y: np.ndarray, best: bool) -> tuple[float, float, float]:
    """Slope, variance and matched variance of the line over the readings ``t, y`` (the whole
    window, n + 1 readings), from the definitions: end-fit through the ends, variance 2 (q^2 /
    12) / T^2 over its span T; best-fit by numpy.polyfit, variance (q^2 / 12) / S with S the
    sum of the squared time deviations, matched on the residuals' variance r.r / (n - 1) (at
    least q^2 / 12) from three periods on."""
    n = t.size - 1
    if not best:
        span = t[-1] - t[0]
        return (y[-1] - y[0]) / span, 2.0 * WHITE / span ** 2, 2.0 * WHITE / span ** 2
    slope, intercept = np.polyfit(t - t[-1], y, 1)
    S = float(np.sum((t - t.mean()) ** 2))
    r = y - (intercept + slope * (t - t[-1]))
    matched = max(WHITE, float(r @ r) / (n - 1)) / S if n >= 3 else WHITE / S
    return slope, WHITE / S, matched


@pytest.mark.parametrize("fit", ["end", "best"])
def test_the_window_estimate_and_its_variances_over_uneven_periods(fit):
    # Readings of a body at 0.1 m/s with whole-count read noise of up to 3 counts, on
    # unevenly spaced samples, a band of 1 m (every window fits: the window is the longest,
    # min(n_max, readings - 1)), n_max = 3, over 40 readings: the buffer (4 (n_max + 1)
    # readings) is compacted twice. Slope and variances against the line fitted again over
    # the same readings (1e-9 relative: polyfit's rounding against the kernel's sums).
    rng = np.random.default_rng(11)
    t = np.concatenate(([0.0], np.cumsum(rng.uniform(0.5 * H, 1.5 * H, 39))))
    counts = np.floor(0.1 * t / Q_C).astype(np.int64) + rng.integers(-3, 4, t.size)
    y = (counts + 0.5) * Q_C
    estimator = AdaptiveWindow(SENSORS, fit=fit, max_window=3, band=1.0)
    assert estimator.name == f"foaw_{fit}" and estimator.band == 1.0
    residual_counted = 0
    for k in range(t.size):
        speed, variance = estimator.observe(_sample(t[k], int(counts[k])))
        n = min(3, k)
        assert estimator.window == n
        if n == 0:
            assert (speed, variance) == (0.0, 2.0 * WHITE * SENSORS.rate ** 2)
            assert estimator.matched_variance == variance
            continue
        slope, var, matched = _window_again(t[k - n:k + 1], y[k - n:k + 1], fit == "best")
        assert speed == pytest.approx(slope, rel=1e-9)
        assert variance == pytest.approx(var, rel=1e-9)
        assert estimator.matched_variance == pytest.approx(matched, rel=1e-9)
        residual_counted += matched > var * (1.0 + 1e-6)
    # The read noise (4 counts^2 per reading) is far above the quantization's (1/12): the
    # matched variance follows the residuals in most of the best fit's 37 windows of three
    # periods (so the comparison with the reference reads that branch), never in the end fit.
    assert residual_counted >= 30 if fit == "best" else residual_counted == 0


def test_the_best_fit_matched_variance_is_at_least_the_quantizations():
    # Readings exactly on a line over uneven periods (counts 0, 2, 3, 7, 8, 11 at 4 ms a
    # count): the residuals vanish, so the matched variance is the quantization's (q^2 / 12)
    # / S, as the variance (1e-12 relative: S summed in another order), and the slope is the
    # line's.
    counts = np.array([0, 2, 3, 7, 8, 11])
    t = counts * 0.004
    estimator = AdaptiveWindow(SENSORS, fit="best", max_window=5)
    for time_k, count in zip(t, counts):
        speed, variance = estimator.observe_count(time_k, int(count))
    S = float(np.sum((t - t.mean()) ** 2))
    assert estimator.window == 5
    assert speed == pytest.approx(Q_C / 0.004, rel=1e-12)
    assert variance == pytest.approx(WHITE / S, rel=1e-12)
    assert estimator.matched_variance == pytest.approx(WHITE / S, rel=1e-12)


def test_the_window_starts_empty_at_the_speed_it_is_given():
    # Before two readings there is no window (0): the estimate is reset's speed (0 by default)
    # with the variance of a difference over one nominal period, 2 (q^2 / 12) rate^2.
    estimator = AdaptiveWindow(SENSORS)
    assert estimator.window == 0 and estimator.band == 0.5 * Q_C and estimator.name == "foaw_end"
    estimator.observe_count(0.0, 5)
    estimator.observe_count(H, 9)
    assert estimator.window == 1
    estimator.reset()
    assert estimator.window == 0
    assert estimator.observe_count(1.0, 100) == (0.0, 2.0 * WHITE * SENSORS.rate ** 2)
    assert estimator.window == 0
    estimator.reset(speed=0.3)
    assert estimator.observe_count(1.0, 100)[0] == 0.3


def test_the_window_takes_one_period_and_no_band_of_zero():
    # The bounds from both sides: a window of one period and any positive band are taken.
    assert AdaptiveWindow(SENSORS, max_window=1).max_window == 1
    assert AdaptiveWindow(SENSORS, band=2.0 ** -40).band == 2.0 ** -40


@pytest.mark.parametrize("call, error, message", [
    (lambda: AdaptiveWindow("carousel"), ParameterTypeError,
     "The 'sensors' parameter of AdaptiveWindow must be a Sensors. Got 'carousel' instead."),
    (lambda: AdaptiveWindow(SENSORS, max_window=0), ParameterError,
     "The 'max_window' parameter of AdaptiveWindow must be >= 1. Got 0 instead."),
    (lambda: AdaptiveWindow(SENSORS, band=0.0), ParameterError,
     "The 'band' parameter of AdaptiveWindow must be > 0. Got 0.0 instead."),
    (lambda: AdaptiveWindow(SENSORS, band=-1.0), ParameterError,
     "The 'band' parameter of AdaptiveWindow must be > 0. Got -1.0 instead."),
    (lambda: AdaptiveWindow(SENSORS, fit="ends"), ParameterError,
     "The 'fit' parameter of AdaptiveWindow must be one of ['end', 'best']. Got 'ends' instead. "
     "Did you mean 'end'?"),
    (lambda: AdaptiveWindow(SENSORS).reset(speed=math.nan), ParameterError,
     "The 'speed' parameter of AdaptiveWindow.reset must be finite. Got nan instead."),
])
def test_every_refusal_of_the_window_in_full(call, error, message):
    with pytest.raises(error) as info:
        call()
    assert str(info.value) == message


# -- the FOAW kernel (toolkit._compiled.window) ---------------------------------------------------

@pytest.mark.parametrize("side", [1.0, -1.0])
def test_a_reading_exactly_on_the_band_is_inside_it(side):
    # Dyadic readings (exact arithmetic): the end-fit line through (0, 0) and (2, 1) misses
    # the middle reading 0.5 +- 0.25 by exactly 0.25 m, on either side. A band of 0.25 m takes
    # the two-period window; one float narrower, only the last period.
    W = _compiled.load("window")
    t = np.array([0.0, 1.0, 2.0])
    y = np.array([0.0, 0.5 + side * 0.25, 1.0])
    assert W.foaw(t, y, 3, 0.25, False) == (0.5, 2)
    assert W.foaw(t, y, 3, float(np.nextafter(0.25, 0.0)), False) == (1.0 - y[1], 1)


@pytest.mark.parametrize("best", [False, True])
def test_the_window_does_not_move_with_the_positions_origin(best):
    # Readings on a dyadic grid (whole counts of 2**-12 m, 0.02 s apart, with read noise):
    # shifted by 2**20 m they stay exact, and the kernel works on positions relative to the
    # last reading: the same windows and slopes, to the bit.
    W = _compiled.load("window")
    rng = np.random.default_rng(4)
    t = np.arange(40) * 0.02
    y = (np.floor(0.2 * t * 4096) + rng.integers(-2, 3, t.size)) / 4096
    for k in range(2, t.size):
        a = max(0, k - 15)
        here = W.foaw(t[a:k + 1], y[a:k + 1], k + 1 - a, 2.5 / 4096, best)
        far = W.foaw(t[a:k + 1], y[a:k + 1] + 2.0 ** 20, k + 1 - a, 2.5 / 4096, best)
        assert here == far, k
