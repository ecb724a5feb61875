"""The estimation package's small laws, one by one: the chance that no count was lost and
what a loss does to a position (toolkit.estimation.missed_counts), the noise of the inputs a
filter does not know (toolkit.estimation.input_noise) and the consistency monitor's test
(toolkit.estimation.monitor). Each against its closed form, with thresholds bracketed from
both sides."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from toolkit.estimation import EstimatorModel
from toolkit.estimation.input_noise import GROSS_NIS, command_timing_variance, unknown_force_noise
from toolkit.estimation.missed_counts import (NO_LOSS, absorbed_variance, count_offset, log_no_loss,
                                              told_missed_rate)
from toolkit.model.carousel import CAROUSEL
from toolkit.model.truth import ModelPrior

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
