"""The missed-count rate from the body's counts against the wheel it rides (RideCheck):
recovered through the sensor law where read noise hides every loss from the exact lines, its
read noise measured, silent where there is no read noise, and in the adaptive filter on the
issue's "all at once" world, where it makes the position's spread independent of the prior."""

from __future__ import annotations

import numpy as np
import pytest

from toolkit.analysis.robustness import ROBUSTNESS_CASES
from toolkit.errors import ParameterError
from toolkit.estimation import KalmanEstimator, MissedCountRate, ModelPrior, RideCheck
from toolkit.model.carousel import CAROUSEL
from toolkit.model.sensors import measure


def _ride(p: float, seed: int, speed: float, noise: float = 0.5, duration: float = 30.0) -> tuple:
    """The body riding one wheel at ``speed`` for ``duration`` s, read by the carousel's
    encoders through the sensor law (read noise, missed counts at ``p``), fed to a check."""
    sensors = CAROUSEL.sensors(1, count_noise=noise, missed_count_prob=p)
    h = sensors.period
    t = np.arange(int(duration / h)) * h
    rng = np.random.default_rng(seed)
    X = speed * t + rng.uniform(0.0, 1e-3)
    x = (speed * t + rng.uniform(0.0, 1e-3))[:, None]
    state = sensors.initial_state(np.array([speed]), central_position=X[0], contact_positions=x[0])
    central, wheels, _ = measure(sensors, X, x, state, rng)
    rate = MissedCountRate()
    check = RideCheck(sensors.central.distance_per_count, sensors.wheel.distance_per_count, rate, h)
    for k in range(t.size):
        check.push(int(central[k]), int(wheels[k, 0]), 0, speed)
    return rate, check, sensors


@pytest.mark.parametrize("p", [3e-4, 1e-3, 3e-3])
@pytest.mark.parametrize("speed", [0.2, -0.13])
def test_the_rate_is_recovered_through_the_sensor_law(p, speed):
    # 30 s rides (about 3e4 central and 8e4 wheel transitions at 0.2 m/s), read noise 0.5
    # count, four seeds. Each record's posterior mean lies within 3.5 of its own std of p
    # (measured |z| <= 2.9 over six seeds at each of these p and speeds); the four records'
    # mean within 20 % of p (measured 0.88-1.03 of p: the steps are whole counts, which the
    # Gaussian quasi-likelihood reads by their first two moments only).
    means = []
    for seed in range(4):
        rate, check, _ = _ride(p, seed, speed)
        assert rate.checked > 1400
        assert abs(rate.mean - p) <= 3.5 * np.sqrt(rate.variance), (seed, rate.mean, np.sqrt(rate.variance))
        means.append(rate.mean)
    assert abs(np.mean(means) / p - 1.0) <= 0.2, means


def test_no_loss_gives_a_rate_near_zero_and_the_read_noise():
    # Read noise 0.5 count, no loss: the posterior mean falls from the prior's 1e-3 to below
    # 2e-6 (measured 1.9e-7 to 8.6e-7); the check's read noise (its variance less the two
    # quantizations', in counts^2 of both channels) is the sensor law's rounded normal's,
    # 0.325 (Sensors.read_noise_variance), within 15 % over four seeds (measured 0.31-0.37 per
    # record at 0.2 m/s; the quantization's steps are alpha (1 - alpha), not white).
    found = []
    for seed in range(4):
        rate, check, sensors = _ride(0.0, seed, 0.2)
        assert rate.mean < 2e-6
        qc, qw = sensors.central.distance_per_count, sensors.wheel.distance_per_count
        found.append(check.read_variance / (qc * qc + qw * qw) - 1.0 / 12.0)
    assert abs(np.mean(found) / sensors.read_noise_variance - 1.0) <= 0.15, found


def test_without_read_noise_the_check_does_not_read():
    # Ideal reads with missed counts: the quantization alone is a sawtooth, not white noise,
    # so the check stays shut (the exact lines see the losses there): nothing checked, the
    # posterior the prior's.
    rate, check, sensors = _ride(1e-3, 0, 0.2, noise=0.0, duration=10.0)
    assert rate.checked == 0 and rate.mean == pytest.approx(1e-3, rel=1e-15)


def test_the_all_at_once_world_is_consistent_whatever_the_rate_prior(monkeypatch):
    # Issue 18's "all at once" world (the rate 1e-3, not told), seeds 0-5, the rate's prior
    # mean at 1e-4 and at 1e-2 (ten times off either way): the NEES in band's median is at
    # least 0.8 (issue 18's line; measured 0.83 and 0.97 here, 0.92 and 0.96 over ten seeds)
    # and the rates the default identified have a median within a factor 2 of the truth
    # (measured 0.92e-3 and 1.42e-3). Without the check the prior decides: 0.40 at 1e-4.
    case = ROBUSTNESS_CASES["all at once"]
    scenes = [case.scenario(seed) for seed in range(6)]
    for mean in (1e-4, 1e-2):
        prior = ModelPrior(missed_count_mean=mean)
        results = [KalmanEstimator(sc.model, prior).run(sc.record, speed_std=1e-4) for sc in scenes]
        assert np.median([r.nees_in_band for r in results]) >= 0.8, [r.nees_in_band for r in results]
        assert 0.5e-3 <= np.median([r.missed_count_prob for r in results]) <= 2e-3
    monkeypatch.setattr(RideCheck, "push", lambda self, *args: None)
    prior = ModelPrior(missed_count_mean=1e-4)
    blind = [KalmanEstimator(sc.model, prior).run(sc.record, speed_std=1e-4).nees_in_band for sc in scenes]
    assert np.median(blind) < 0.7, blind


@pytest.mark.parametrize("value", [0.0, -1e-3, 0.05])
def test_a_bad_rate_prior_mean_names_itself(value):
    with pytest.raises(ParameterError, match="missed_count_mean"):
        ModelPrior(missed_count_mean=value)
