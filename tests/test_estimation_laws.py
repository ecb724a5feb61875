"""The estimation package's small laws, one by one: the chance that no count was lost and
what a loss does to a position (toolkit.estimation.missed_counts), the noise of the inputs a
filter does not know (toolkit.estimation.input_noise) and the consistency monitor's test
(toolkit.estimation.monitor). Each against its closed form, with thresholds bracketed from
both sides."""

from __future__ import annotations

import dataclasses
import math
import time
import warnings

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid
from scipy.linalg import cholesky
from scipy.optimize import nnls
from scipy.stats import chi2

from toolkit import ParameterError
from toolkit.analysis.scenarios import carousel_brake_scenario
from toolkit.estimation import EstimatorModel, KalmanEstimator, RTSSmoother, UnscentedEstimator
from toolkit.estimation.input_noise import GROSS_NIS, command_timing_variance, unknown_force_noise
from toolkit.estimation.missed_counts import (NO_LOSS, absorbed_variance, count_offset, log_no_loss,
                                              told_missed_rate)
from toolkit.estimation.monitor import ConsistencyMonitor, MonitorVerdict, NoiseMatcher, fit_noise, matched_variance
from toolkit.model.carousel import CAROUSEL
from toolkit.model.truth import ModelPrior

Q_C_UKF = CAROUSEL.sensors().central.distance_per_count

#: The rate whose chance of no loss over one transition is NO_LOSS to the last bit:
#: log1p(-P_EDGE) == log(NO_LOSS) in floating point (checked where it is used).
P_EDGE = -math.expm1(math.log(NO_LOSS))


# -- missed counts ------------------------------------------------------------------------------

@pytest.mark.parametrize("prior_p, sensors_p", [(1e-3, 3e-4), (3e-4, 1e-3), (0.0, 0.0), (0.0, 2e-3)])
def test_the_told_missed_count_rate_is_the_larger_of_the_priors_and_the_sensors(prior_p, sensors_p):
    model = EstimatorModel(np.array([1.0, 2.0]), 3.0, CAROUSEL.sensors(2, missed_count_prob=sensors_p))
    assert told_missed_rate(model, ModelPrior(missed_count_prob=prior_p)) == max(prior_p, sensors_p)


def test_the_chance_of_no_loss_is_the_binomials_or_the_gamma_poissons():
    # n log(1 - p) for a known rate; a log(b / (b + n)) with a = p^2 / s^2, b = p / s^2 for a
    # posterior (1e-13 relative: log1p against log of a ratio). Fractional transitions count
    # (half a transition: half the log); none, or no rate: log 1 = 0, whatever the variance.
    p, var = 2e-3, 1e-6
    a, b = p * p / var, p / var
    for n in (0.5, 1.0, 37.0):
        assert log_no_loss(p, 0.0, n) == pytest.approx(n * math.log(1.0 - p), rel=1e-13)
        assert log_no_loss(p, var, n) == pytest.approx(a * math.log(b / (b + n)), rel=1e-13)
    for p_, var_, n in ((0.0, 0.0, 10.0), (0.0, 1e-6, 10.0), (2e-3, 0.0, 0.0), (2e-3, 1e-6, -3.0)):
        assert log_no_loss(p_, var_, n) == 0.0


def test_a_line_absorbs_a_loss_from_half_a_transition_on():
    # Half a transition at p = 0.2: no loss with chance 0.8^0.5 = 0.894 < NO_LOSS, so the line
    # gains that chance's complement times (q / T)^2 (1e-13 relative).
    q, T = 1e-4, 0.3
    assert absorbed_variance(0.2, 0.0, 0.5, q, T) == pytest.approx((1.0 - 0.8 ** 0.5) * (q / T) ** 2, rel=1e-13)


def test_no_loss_with_a_chance_of_exactly_no_loss_is_taken_as_sure():
    # At P_EDGE one transition leaves no loss with chance NO_LOSS exactly: the line gains
    # nothing (the bias is almost surely 0, the bound included); one float above, it gains the
    # chance of a loss, 1 - NO_LOSS to rounding (1e-12), times (q / T)^2; one float below, nothing.
    assert math.log1p(-P_EDGE) == math.log(NO_LOSS)
    q, T = 1e-4, 0.3
    assert absorbed_variance(P_EDGE, 0.0, 1.0, q, T) == 0.0
    assert absorbed_variance(np.nextafter(P_EDGE, 0.0), 0.0, 1.0, q, T) == 0.0
    above = absorbed_variance(np.nextafter(P_EDGE, 1.0), 0.0, 1.0, q, T)
    assert above == pytest.approx((1.0 - NO_LOSS) * (q / T) ** 2, rel=1e-12)


def _offset_again(times, speed, p, q, var=0.0, seen=None):
    """count_offset's shift and added variance from the definitions: the counts crossed are
    the trapezoid integral of the speed over q (signed, and their absolute steps), none in
    the periods that end at a sample whose losses were repaired; shifted where no loss has a
    chance below NO_LOSS ((1 - p)^n, or the Gamma-Poisson's with a variance)."""
    steps = np.diff(cumulative_trapezoid(speed, times, initial=0.0)) / q
    if seen is not None:
        steps[seen[1:]] = 0.0
    signed = np.concatenate(([0.0], np.cumsum(steps)))
    crossed = np.concatenate(([0.0], np.cumsum(np.abs(steps))))
    if var > 0.0:
        a, b = p * p / var, p / var
        none = (b / (b + crossed)) ** a
    else:
        none = (1.0 - p) ** crossed
    lost = none < NO_LOSS
    shift = np.where(lost, signed * p / (1.0 - p) * q, 0.0)
    added = np.where(lost, crossed * p / (1.0 - p) ** 2 * q * q + (signed * q) ** 2 * var / (1.0 - p) ** 4, 0.0)
    return shift, added


@pytest.mark.parametrize("var", [0.0, 4e-6])
def test_the_count_offset_integrates_each_periods_own_speeds(var):
    # A body that speeds up, reverses and comes back, on unevenly spaced samples: the counts
    # crossed are the trapezoid rule's over each period's own ends (a period's speeds both
    # counted; the reversal cancels in the signed count, not in the crossed one); the
    # position shifted by the mean lost and its variance added, from the first sample whose
    # chance of no loss is below NO_LOSS. Against the same sums written again (1e-10
    # relative: cumulative sums in another order). P[1] and the speed entries are left alone.
    rng = np.random.default_rng(2)
    times = np.concatenate(([0.0], np.cumsum(rng.uniform(0.01, 0.03, 80))))
    speed = 0.3 * np.sin(3.0 * times) + 0.05
    q, p = 1e-4, 2e-3
    position = np.linspace(0.0, 0.1, times.size)
    cov = np.tile(np.array([[1e-9, 2e-8], [2e-8, 1e-6]]), (times.size, 1, 1))
    pos, P = count_offset(times, position, cov, speed, p, q, var)
    shift, added = _offset_again(times, speed, p, q, var)
    assert shift[0] == 0.0 and (shift != 0.0).sum() > 60          # (the test reads the shift)
    np.testing.assert_allclose(pos - position, shift, rtol=1e-10, atol=1e-18)
    np.testing.assert_allclose(P[:, 0, 0] - cov[:, 0, 0], added, rtol=1e-10, atol=1e-24)
    np.testing.assert_array_equal(P[:, 1], cov[:, 1])
    np.testing.assert_array_equal(P[:, 0, 1], cov[:, 0, 1])


def test_counts_crossed_where_a_loss_was_repaired_add_nothing():
    # seen[k]: the period ending at sample k crossed counts whose losses were repaired (an
    # exact hold's): they neither shift the position nor add variance (1e-10 relative).
    times = np.arange(41) * 0.02
    speed = np.full(times.size, 0.5)
    q, p = 1e-4, 1e-3
    seen = np.zeros(times.size, dtype=bool)
    seen[10:25] = True
    cov = np.tile(np.diag([1e-9, 1e-6]), (times.size, 1, 1))
    pos, P = count_offset(times, np.zeros(times.size), cov, speed, p, q, seen=seen)
    shift, added = _offset_again(times, speed, p, q, seen=seen)
    # 100 counts a period; after 25 periods, 15 of them repaired, 10 periods count: 1000.
    assert shift[25] == pytest.approx(1000.0 * p / (1.0 - p) * q, rel=1e-12)
    np.testing.assert_allclose(pos, shift, rtol=1e-10, atol=0.0)
    np.testing.assert_allclose(P[:, 0, 0] - cov[:, 0, 0], added, rtol=1e-10, atol=0.0)


def test_the_count_offset_takes_a_chance_of_exactly_no_loss_as_sure():
    # One count crossed per period (q = 1 m, 1 m/s, periods of 1 s: exact), at P_EDGE: after
    # the first period no loss has chance NO_LOSS exactly, so the position is the counts'; after
    # the second, it is shifted by 2 p / (1 - p) counts. A covariance of whole numbers is read
    # as floats.
    times = np.array([0.0, 1.0, 2.0])
    cov = np.zeros((3, 2, 2), dtype=np.int64)
    pos, P = count_offset(times, np.zeros(3), cov, np.ones(3), P_EDGE, 1.0)
    assert pos[1] == 0.0 and P[1, 0, 0] == 0.0
    assert pos[2] == pytest.approx(2.0 * P_EDGE / (1.0 - P_EDGE), rel=1e-15)
    assert P[2, 0, 0] == pytest.approx(2.0 * P_EDGE / (1.0 - P_EDGE) ** 2, rel=1e-15)
    # One float above the edge, one count crossed is enough; at the first sample nothing is
    # crossed yet, whatever the rate: the counts' position and covariance.
    p = np.nextafter(P_EDGE, 1.0)
    pos, P = count_offset(times, np.zeros(3), cov, np.ones(3), p, 1.0)
    assert pos[0] == 0.0 and P[0, 0, 0] == 0.0
    assert pos[1] == pytest.approx(p / (1.0 - p), rel=1e-15)


# -- the inputs a filter does not know ----------------------------------------------------------

def test_an_innovation_exactly_on_the_gate_is_not_gross():
    # |y| = count + sqrt(GROSS_NIS S) to the bit: no excess, no noise (None); just beyond the
    # gate (one count plus 2**-40 m), some.
    count, S = 2e-4, 1.0
    gate = count + math.sqrt(GROSS_NIS * S)
    assert abs(gate) - count - math.sqrt(GROSS_NIS * S) == 0.0
    assert unknown_force_noise(gate, S, count, 0.02, 1.0) is None
    assert unknown_force_noise(-gate, S, count, 0.02, 1.0) is None
    assert unknown_force_noise(gate + 2.0 ** -40, S, count, 0.02, 1.0) is not None


def test_no_contacts_no_timing_variance():
    # Without contacts (empty commands) nothing departs: the reach and its variance are 0.
    assert command_timing_variance(np.zeros(0), np.zeros(0), 0.02, 0.0075, 5.0) == 0.0
    assert command_timing_variance([], [], 0.02, 0.0, 5.0) == 0.0


# -- the consistency monitor ---------------------------------------------------------------------

def test_the_monitors_threshold_is_the_chi_square_quantile_of_its_window():
    # The default window (10) and level (1e-4), and others: the 1 - level quantile of
    # chi-square(W), scipy's upper-tail inverse (1e-9 relative: ppf against isf).
    assert ConsistencyMonitor().window == 10 and ConsistencyMonitor().false_alarm == 1e-4
    for window, level in [(10, 1e-4), (1, 0.3), (25, 1e-6), (3, 0.999)]:
        monitor = ConsistencyMonitor(window, level)
        assert monitor.threshold == pytest.approx(chi2.isf(level, window), rel=1e-9, abs=1e-300)


def test_the_monitor_sums_the_last_window_of_finite_nis():
    # A window of 3: the statistic is the sum of the last three values pushed, NaN and inf
    # counted as 0 (no update that sample); the mean over the values held (NaN before any).
    # Dyadic values: the running sum is exact.
    monitor = ConsistencyMonitor(3, 1e-3)
    assert math.isnan(monitor.mean)
    pushed = [0.0, 0.5, 2.0, 0.25, math.nan, 4.0, math.inf, 1.5, 0.0, 0.0, 0.0]
    held = []
    for value in pushed:
        verdict = monitor.push(value)
        held = (held + [value if math.isfinite(value) else 0.0])[-3:]
        assert verdict.statistic == sum(held)
        assert monitor.mean == sum(held) / len(held)
    assert verdict.statistic == 0.0
    monitor.reset()
    assert math.isnan(monitor.mean) and monitor.push(0.125).statistic == 0.125


def test_the_monitor_fails_only_above_its_threshold_and_says_so():
    # A window of 1: the statistic is the value pushed. At the threshold exactly it passes;
    # one float above, it fails, naming the window, the sum and the threshold; a failure
    # elsewhere fails the sample with its own reason, whatever the sum.
    monitor = ConsistencyMonitor(1, 0.01)
    T = monitor.threshold
    assert monitor.push(T) == MonitorVerdict(True, T, T, "")
    above = float(np.nextafter(T, math.inf))
    assert monitor.push(above) == MonitorVerdict(False, above, T, f"NIS over the last 1 samples {above:.3g} > {T:.3g}")
    assert monitor.push(0.5, "a hold failed") == MonitorVerdict(False, 0.5, T, "a hold failed")


@pytest.mark.parametrize("call, message", [
    (lambda: ConsistencyMonitor(window=0), "The 'window' parameter of ConsistencyMonitor must be >= 1. Got 0 instead."),
    (lambda: ConsistencyMonitor(false_alarm=0.0),
     "The 'false_alarm' parameter of ConsistencyMonitor must be > 0. Got 0.0 instead."),
    (lambda: ConsistencyMonitor(false_alarm=1.5),
     "The 'false_alarm' parameter of ConsistencyMonitor must be <= 1. Got 1.5 instead."),
    (lambda: ConsistencyMonitor(false_alarm=1.0),
     "The 'false_alarm' parameter of ConsistencyMonitor must be < 1. Got 1.0 instead."),
    (lambda: NoiseMatcher(window=1), "The 'window' parameter of NoiseMatcher must be >= 2. Got 1 instead."),
])
def test_every_refusal_of_the_monitor_and_the_matcher_in_full(call, message):
    with pytest.raises(ParameterError) as info:
        call()
    assert str(info.value) == message


def test_covariance_matching_is_the_innovations_excess_at_least_the_floor():
    # mean(y^2) - mean(H P H^T) = 14/3 - 2 (1e-6 m^2); a floor below it leaves it, a floor
    # above it is the result (1e-12 relative: two means).
    y, predicted = np.array([1e-3, -2e-3, 3e-3]), np.array([1e-6, 2e-6, 3e-6])
    assert matched_variance(y, predicted, 1e-6) == pytest.approx(8e-6 / 3.0, rel=1e-12)
    assert matched_variance(y, predicted, 5e-6) == 5e-6


def _nnls_fit(e, x):
    """The nonnegative least squares of e ~ a + b x (scipy's NNLS: a second method)."""
    (a, b), _ = nnls(np.column_stack((np.ones_like(x), x)), e)
    return a, b


@pytest.mark.parametrize("a, b", [(2e-10, 9e-8), (-1e-10, 9e-8), (3e-10, -5e-9), (-2e-10, -4e-9)])
def test_the_noise_fit_is_the_nonnegative_least_squares(a, b):
    # Excess a + b V^2 plus noise (std 2e-11 m^2) at 40 speeds of 0.05-0.3 m/s: fit_noise
    # equals scipy's NNLS (both coefficients free; a at 0; b at 0; both at 0), to 1e-7 of
    # the larger term (NNLS's own tolerance against the normal equations).
    rng = np.random.default_rng(5)
    x = rng.uniform(0.05, 0.3, 40) ** 2
    e = a + b * x + rng.normal(0.0, 2e-11, x.size)
    got, want = fit_noise(e, x), _nnls_fit(e, x)
    assert got[0] == pytest.approx(want[0], rel=1e-7, abs=1e-7 * abs(a))
    assert got[1] == pytest.approx(want[1], rel=1e-7, abs=1e-7 * abs(b))


@pytest.mark.parametrize("seed", range(12))
def test_the_noise_fit_is_the_nonnegative_least_squares_on_drawn_data(seed):
    # Coefficients of either sign and noise of 0.1-10 times the signal, drawn: the same NNLS
    # (1e-7 of the data's scale).
    rng = np.random.default_rng(100 + seed)
    x = rng.uniform(0.0, 0.1, rng.integers(3, 30))
    e = rng.normal(0.0, 1e-10) + rng.normal(0.0, 1e-8) * x + rng.normal(0.0, 10.0 ** rng.uniform(-11, -9), x.size)
    got, want = fit_noise(e, x), _nnls_fit(e, x)
    scale = float(np.max(np.abs(e)))
    assert got[0] == pytest.approx(want[0], abs=1e-7 * scale)
    assert got[1] == pytest.approx(want[1], abs=1e-7 * scale / float(np.max(x)))


@pytest.mark.parametrize("scale", [2.0 ** -20, 1.0, 2.0 ** 20])
def test_the_noise_fit_scales_with_the_speeds(scale):
    # Speeds scaled by a power of two scale V^2 by its square and b by the inverse, to the
    # bit: the test of a degenerate fit is relative to the speeds' own size.
    rng = np.random.default_rng(8)
    x = rng.uniform(0.05, 0.3, 30) ** 2
    e = 2e-10 + 9e-8 * x + rng.normal(0.0, 2e-11, x.size)
    a, b = fit_noise(e, x)
    assert a > 0.0 and b > 0.0
    assert fit_noise(e, x * scale ** 2) == (a, b / scale ** 2)


def test_the_noise_fit_of_one_speed_or_none():
    # No rows: nothing. One row, or every row at one speed (no slope to fit): the constant,
    # the excess's mean (1e-15 relative), clipped at 0. All speeds 0: the same, without a
    # division by their zero sum of squares.
    assert fit_noise(np.zeros(0), np.zeros(0)) == (0.0, 0.0)
    assert fit_noise(np.array([3e-10]), np.array([0.04])) == (3e-10, 0.0)
    a, b = fit_noise(np.array([1e-10, 3e-10, 2e-10, 6e-10]), np.full(4, 0.09))
    assert a == pytest.approx(3e-10, rel=1e-15) and b == 0.0
    assert fit_noise(np.array([-1e-10, -3e-10]), np.full(2, 0.09)) == (0.0, 0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        a, b = fit_noise(np.array([1e-10, 3e-10, 2e-10, 6e-10]), np.zeros(4))
    assert a == pytest.approx(3e-10, rel=1e-15) and b == 0.0


def test_the_noise_matcher_starts_at_nothing_and_refits_every_few_updates_once_full():
    # Fresh (default window 100): a = b = 0, no extra variance. With a window of 20 rows (the
    # trimmed fit's least) the fit follows every update until the window is full, then only
    # every REFIT updates; the extra variance is a + b V^2 (1e-15 relative).
    assert NoiseMatcher().window == 100
    matcher = NoiseMatcher(20)
    assert (matcher.a, matcher.b, matcher.extra(0.3)) == (0.0, 0.0, 0.0)
    rng = np.random.default_rng(3)
    last = None
    for k in range(1, 41):
        speed = rng.uniform(0.05, 0.3)
        matcher.push(rng.normal() * math.sqrt(3e-10 + 9e-8 * speed * speed), 1e-10, 1e-10, speed)
        fit = (matcher.a, matcher.b)
        if k > 20 and k % NoiseMatcher.REFIT:
            assert fit == last, k
        elif k > 1:
            assert fit != last, k
        last = fit
    assert matcher.b > 0.0
    assert matcher.extra(0.2) == pytest.approx(matcher.a + matcher.b * 0.04, rel=1e-15)


# -- the smoother --------------------------------------------------------------------------------

def _rts_again(X, P, F, u, Q):
    """The Rauch-Tung-Striebel backward pass of the filter's states X and covariances P, with
    the step into sample k+1 x_{k+1} = F_{k+1} x_k + u_{k+1} + noise of covariance Q_{k+1}
    (written from the recursion, solved with numpy; filterpy's is the smoother's)."""
    xs, ps = X.copy(), P.copy()
    for k in range(X.shape[0] - 2, -1, -1):
        predicted = F[k + 1] @ P[k] @ F[k + 1].T + Q[k + 1]
        gain = np.linalg.solve(predicted, F[k + 1] @ P[k]).T
        xs[k] = X[k] + gain @ (xs[k + 1] - F[k + 1] @ X[k] - u[k + 1])
        ps[k] = P[k] + gain @ (ps[k + 1] - predicted) @ gain.T
    return xs, ps


def test_the_smoother_is_the_rts_recursion_over_the_filters_own_steps():
    # A short brake record where the nominal model holds (the monitor does not trip): the
    # smoothed speeds, positions and covariances are the RTS recursion over the forward
    # filter's states, covariances, transitions, known inputs and process noises (1e-8
    # relative: pinv against solve, on covariances of 1e-9 to 1e-7). The last sample is the
    # filter's own. Its wall time adds the backward pass to the filter's.
    sc = carousel_brake_scenario(seed=0, t_end=2.0, brake_time=1.0)
    rts = RTSSmoother(sc.model)
    before = time.perf_counter()
    result = rts.run(sc.record, speed=0.01, speed_std=0.02)
    after = time.perf_counter()
    assert rts.refused is None and rts.tripped is None and result.method == "rts"
    f = rts.forward.nominal_pass
    assert f.states[0, 1] == 0.01                         # (the speed it was given)
    assert np.ptp(f.inputs[1:, 1]) > 0.0                  # (inputs that change: the brake)
    xs, ps = _rts_again(f.states, f.covariances, f.transitions, f.inputs, f.process_noises)
    assert xs[-1].tolist() == f.states[-1].tolist()
    scale = float(np.max(np.abs(ps)))
    np.testing.assert_allclose(result.speed, xs[:, 1], rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(result.position, xs[:, 0], rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(result.covariance, ps, rtol=1e-8, atol=1e-8 * scale)
    np.testing.assert_array_equal(result.variance, result.covariance[:, 1, 1])
    assert result.nees is not None and result.times is sc.record.times
    assert f.wall_time <= result.wall_time <= after - before


def test_the_smoother_passes_its_prior_start_and_initial_covariance_to_the_filter():
    # The forward filter is the default's with the smoother's prior and initial covariance,
    # and reset starts it at the speed given: its first estimate is that speed with the
    # initial covariance's speed variance (what it was given, exactly).
    sc = carousel_brake_scenario(seed=0, t_end=0.5, brake_time=1.0)
    prior, C = ModelPrior(friction_spread=0.1), np.array([[4e-8, 1e-7], [1e-7, 9e-4]])
    rts = RTSSmoother(sc.model, prior=prior, initial_covariance=C)
    assert rts.forward.prior is prior and rts.model is sc.model
    rts.reset(speed=0.1)
    assert rts.forward.step(sc.record.sample(0)) == (0.1, 9e-4)
    rts.reset(speed=-0.05, speed_std=0.02)
    assert rts.forward.step(sc.record.sample(0)) == (-0.05, 9e-4)
    # Without an initial covariance, the speed's std given to reset (0 m/s by default).
    plain = RTSSmoother(sc.model)
    assert plain.refused is None and plain.tripped is None          # (before any run)
    plain.reset(speed_std=0.02)
    assert plain.forward.step(sc.record.sample(0)) == (0.0, pytest.approx(4e-4, rel=1e-15))


def test_the_smoother_resets_its_filter_as_the_default_is_reset():
    # The contacts' speeds before the first sample (the motors had settled there) reach the
    # forward filter: stepped, it gives the default filter's estimates reset alike, to the
    # bit, and other estimates than without them (the motors' lag moves the contacts from
    # there).
    sc = carousel_brake_scenario(seed=0, t_end=0.5, brake_time=1.0)
    settled = np.linspace(-0.1, 0.1, 10)
    rts, default = RTSSmoother(sc.model), KalmanEstimator(sc.model)
    runs = []
    for contact_speeds in (settled, None):
        rts.reset(speed=0.02, speed_std=0.03, contact_speeds=contact_speeds)
        default.reset(speed=0.02, speed_std=0.03, contact_speeds=contact_speeds)
        ours = [rts.forward.step(sc.record.sample(k)) for k in range(8)]
        assert ours == [default.step(sc.record.sample(k)) for k in range(8)]
        runs.append(ours)
    assert runs[0] != runs[1]


def test_the_smoother_cannot_be_stepped():
    sc = carousel_brake_scenario(seed=0, t_end=0.5, brake_time=1.0)
    rts = RTSSmoother(sc.model)
    message = "The RTS smoother is offline: call run(record); step the KalmanEstimator."
    for call in (lambda: rts.observe(sc.record.sample(0)), lambda: rts.commanded(np.zeros(10))):
        with pytest.raises(NotImplementedError) as info:
            call()
        assert str(info.value) == message


# -- the unscented filter -----------------------------------------------------------------------

class _Logged(UnscentedEstimator):
    """The UKF with each step's inputs, the state before it and the state after it logged."""

    def _advance(self, z, R, track, var_v, steady, bounds=None, force=0.0, count=0, t=0.0, wheels=None):
        before = None if track is None else (self.kf.ukf.x.copy(), self.kf.ukf.P.copy())
        super()._advance(z, R, track, var_v, steady, bounds, force, count, t, wheels)
        self.log.append((before, (z, R, track, var_v, steady, bounds, force),
                         self.kf.ukf.x.copy(), self.kf.ukf.P.copy(), self.last_nis))


def _ukf_step_again(model, x, P, z, R, track, var_v, steady, bounds, force):
    """One UKF step written from its definition: Julier's sigma points (kappa = 1, n = 2:
    weights 1/3 and 1/6 each, the points x +- the rows of the upper Cholesky factor of 3 P, as
    filterpy draws them) moved by the exact flow over the period; the process noise the model's
    linearized input noise, plus the contact estimate's variance on V where a point ends stuck
    and the mean's own flow arrives nowhere, plus the floor 1e-12 on each diagonal; then the
    update of the position (a linear reading: the points drawn again about the prediction give
    the Kalman update of its mean and covariance). Returns x, P, the NIS y^2 / S and whether
    the contact's variance was added."""
    root = cholesky(3.0 * P)
    sigmas = np.vstack((x, x + root, x - root))
    weights = np.array([1.0, 0.5, 0.5, 0.5, 0.5]) / 3.0
    moved, stuck = [], False
    for X0, V0 in sigmas:
        step = model.flow(float(V0), track, force)
        moved.append((X0 + step.body_displacement, step.state.V))
        stuck = stuck or step.state.stuck is not None
    moved = np.array(moved)
    _, _, Q, _, arrival, _ = model.increment(float(x[1]), track, math.sqrt(var_v), math.sqrt(P[1, 1]), steady,
                                             bounds, force)
    Q = Q + np.diag([1e-12, 1e-12 + (var_v if stuck and arrival is None else 0.0)])
    mean = weights @ moved
    d = moved - mean
    P_pred = d.T @ (weights[:, None] * d) + Q
    S = P_pred[0, 0] + R
    gain = P_pred[:, 0] / S
    y = z - mean[0]
    return mean + gain * y, P_pred - np.outer(gain, gain) * S, y * y / S, stuck and arrival is None


@pytest.mark.parametrize("force", [0.0, 0.3])
def test_each_unscented_step_is_the_unscented_transform_through_the_exact_flow(force):
    # The brake record, with or without an outside force of 0.3 N held throughout (known to
    # the filter): every step's posterior and NIS against the step written again from the
    # definitions on the same inputs (1e-9 relative; 1e-9 of the covariance's scale where an
    # entry cancels). Without the force, some steps' sigma points end stuck with nowhere to
    # arrive (the contact's variance added); with it, none do.
    sc = carousel_brake_scenario(seed=0, t_end=1.0, brake_time=0.5)
    record = dataclasses.replace(sc.record, force=np.full(sc.record.n_samples, force))
    ukf = _Logged(sc.model)
    ukf.log = []
    ukf.filter(record, speed=0.0, speed_std=0.02)
    (start, _, x0, P0, nis0), steps = ukf.log[0], ukf.log[1:]
    assert start is None and math.isnan(nis0) and x0[1] == 0.0
    assert P0.tolist() == np.diag([Q_C_UKF ** 2 / 12.0, 0.02 ** 2]).tolist()
    added = 0
    for (x, P), (z, R, *inputs), x_after, P_after, nis in steps:
        want_x, want_P, want_nis, stuck = _ukf_step_again(sc.model, x, P, z, R, *inputs)
        added += stuck
        np.testing.assert_allclose(x_after, want_x, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(P_after, want_P, rtol=1e-9, atol=1e-9 * np.abs(want_P).max())
        assert nis == pytest.approx(want_nis, rel=1e-9)
    assert (added > 0) == (force == 0.0) and added < len(steps)


def test_the_unscented_filter_starts_from_its_initial_covariance_and_holds_nothing_exactly():
    # Given an initial covariance, the first sample's is that one; its speed the one given,
    # its position the count's cell centre; no NIS (no update yet). The sigma points are the
    # UKF's way with sticking: no exact holds.
    sc = carousel_brake_scenario(seed=0, t_end=0.5, brake_time=1.0)
    C = np.array([[4e-8, 1e-7], [1e-7, 9e-4]])
    ukf = UnscentedEstimator(sc.model, initial_covariance=C)
    assert not ukf.exact_holds
    ukf.reset(speed=0.07)
    assert ukf.observe(sc.record.sample(0)) == (0.07, 9e-4)
    assert ukf.kf.P.tolist() == C.tolist() and math.isnan(ukf.last_nis)
    assert ukf.kf.x[0, 0] == (sc.record.central_counts[0] + 0.5) * Q_C_UKF
