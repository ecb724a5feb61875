"""Encoder resolutions against the paper's hardware table (docs/physics.md section 5)."""

from __future__ import annotations

import math

import re

import numpy as np
import pytest

from toolkit import ParameterError, ParameterTypeError
from toolkit.model import Encoder


def test_wheel_encoder_matches_the_hardware_table():
    wheel = Encoder(48 * 74.83, 0.045, rate=50.0, backlash=0.0008)
    # 2 pi 0.045 / 3591.84 = 78.72 um; x 50 Hz = 3.94 mm/s; backlash 0.8 mm x 50 Hz = 40 mm/s.
    assert wheel.distance_per_count == pytest.approx(2 * math.pi * 0.045 / 3591.84, rel=1e-15)
    assert wheel.distance_per_count == pytest.approx(78.7e-6, abs=0.05e-6)
    assert wheel.speed_step == pytest.approx(3.9e-3, abs=0.05e-3)
    assert wheel.backlash_speed_step == pytest.approx(0.040, rel=1e-12)


def test_central_encoder_matches_the_hardware_table():
    central = Encoder(8192, 0.266)
    assert central.distance_per_count == pytest.approx(0.204e-3, abs=0.0005e-3)
    assert central.speed_step == pytest.approx(10.2e-3, abs=0.05e-3)


def test_counts_are_a_floor_sawtooth():
    enc = Encoder(8192, 0.266)
    d = enc.distance_per_count
    positions = np.array([-0.5, 0.0, 0.5, 0.999, 1.0, 2.5]) * d
    np.testing.assert_array_equal(enc.counts(positions), [-1, 0, 0, 0, 1, 2])
    # At constant speed the quantization error position - counts * d is in [0, d).
    x = np.linspace(0, 0.1, 1001)
    error = x - enc.counts(x) * d
    assert np.all((error >= 0) & (error < d))


@pytest.mark.parametrize("kwargs", [{"counts_per_rev": 0, "radius": 1}, {"counts_per_rev": 10, "radius": -1},
                                    {"counts_per_rev": 10, "radius": 1, "backlash": -0.1}])
def test_bad_encoders_are_refused(kwargs):
    with pytest.raises(ParameterError):
        Encoder(**kwargs)


# -- the sensor suite, the sensor law and records ---------------------------------------------
from toolkit.model import ContactSet, Motors, PiecewiseConstant, Plant  # noqa: E402
from toolkit.model.carousel import CAROUSEL
from toolkit.model.sensors import (EncoderRecord, Sensors, measure, play,  # noqa: E402
                                   record_simulation)
from toolkit.simulation import simulate  # noqa: E402


def test_encoder_error_follows_the_template():
    with pytest.raises(ParameterError, match=r"^The 'rate' parameter of Encoder must be > 0\. Got 0\.0 instead\.$"):
        Encoder(8192, 0.266, rate=0.0)
    with pytest.raises(ParameterError, match="'radius' parameter of Encoder must be finite"):
        Encoder(8192, float("nan"))
    with pytest.raises(ParameterError, match="'counts_per_rev' parameter of Encoder must be finite"):
        Encoder(float("inf"), 0.1)


@pytest.mark.parametrize("kwargs, name", [
    ({"missed_count_prob": -0.1}, "missed_count_prob"), ({"missed_count_prob": 1.5}, "missed_count_prob"),
    ({"count_noise": -1.0}, "count_noise"), ({"jitter": float("nan")}, "jitter"),
    ({"jitter": float("inf")}, "jitter"), ({"n_wheels": 0}, "n_wheels")])
def test_bad_sensor_suites_name_the_parameter(kwargs, name):
    args = {"n_wheels": 10, **kwargs}
    with pytest.raises(ParameterError, match=f"^The '{name}' parameter of Sensors must"):
        Sensors(Encoder(8192, 0.266), Encoder(3591.84, 0.045), **args)


def test_sensor_rates_must_agree():
    with pytest.raises(ParameterError, match="'wheel' parameter of Sensors"):
        Sensors(Encoder(8192, 0.266, rate=50.0), Encoder(3591.84, 0.045, rate=100.0), 3)


def test_finite_difference_error_is_a_sawtooth_bounded_by_one_count():
    # Constant speed: X_k = V k h; c_k = floor(X_k / q) so |(c_k - c_{k-1}) q / h - V| < q / h
    # (floor(a) - floor(b) differs from a - b by less than 1): the bound |e| <= q per sample.
    enc = Encoder(8192, 0.266)
    q, h = enc.distance_per_count, 1 / enc.rate
    for V in (0.0013, 0.0517, 0.2, 0.35):
        X = V * h * np.arange(200)
        c = enc.counts(X)
        error = np.diff(c) * q - V * h
        assert np.all(np.abs(error) < q)
        assert np.ptp(error) > 0.5 * q                    # deterministic sawtooth, not zero


def test_play_operator_on_a_reversal_matches_the_closed_form():
    # Input up 0 -> A then back down; play b. Closed form: going up y = x - b/2 (after the
    # first b/2, from a centred start); after the turn y stays at A - b/2 until x <= A - b,
    # then y = x + b/2.
    b, A = 0.0008, 0.005
    x = np.concatenate((np.linspace(0, A, 501), np.linspace(A, A - 0.003, 301)[1:]))
    y = play(x[:, None], b, np.zeros(1))[:, 0]
    up = x[:501]
    expect_up = np.maximum(up - b / 2, 0.0)
    down = x[501:]
    expect_down = np.minimum(A - b / 2, down + b / 2)
    np.testing.assert_allclose(y[:501], expect_up, rtol=0, atol=1e-18)     # clip: exact ops
    np.testing.assert_allclose(y[501:], expect_down, rtol=0, atol=1e-18)
    # The encoder stands still for exactly b of travel after the turn.
    still = down[y[501:] == A - b / 2]
    assert A - still.min() == pytest.approx(b, abs=1e-5 + 1e-15)            # grid step 1e-5 m


def _startup_plant(lag: float = 0.0) -> Plant:
    # 10 contacts of 1 N at 1 m/s, m = 5 kg: V = 2 t until t = 0.5 s, then stuck at 1 m/s.
    motors = Motors(lag=lag) if lag > 0 else None
    return Plant(ContactSet(np.ones(10), np.ones(10)), 5.0, motors=motors)


def test_record_positions_match_the_constant_acceleration_closed_form():
    plant = _startup_plant()
    result = simulate(plant, 1.0)
    sensors = CAROUSEL.sensors()
    record = record_simulation(result, plant, sensors)
    t = record.times
    X = np.where(t < 0.5, t**2, 0.25 + (t - 0.5))
    # Gauss-Legendre is exact on lines: only rounding of the cumulative sum, ~1e-16 per piece.
    np.testing.assert_allclose(record.truth_position, X, rtol=0, atol=1e-13)
    np.testing.assert_array_equal(record.central_counts, np.floor(X / sensors.central.distance_per_count))
    np.testing.assert_allclose(record.truth_speed, np.minimum(2 * t, 1.0), rtol=0, atol=1e-14)
    # Contacts at a constant 1 m/s: x_i = t; the motor side trails by b/2 (loaded gearbox).
    motor = t[:, None] - sensors.backlash / 2
    np.testing.assert_array_equal(record.wheel_counts,
                                  np.floor(motor / sensors.wheel.distance_per_count) * np.ones((1, 10)))


def test_record_contact_positions_match_the_motor_lag_closed_form():
    # A command step 0.1 -> -0.2 m/s at t = 0.3 s through a 7.5 ms lag: after the step
    # x(t) = 0.03 + u s + (v0 - u) tau (1 - exp(-s / tau)), s = t - 0.3.
    tau, u, v0 = 0.0075, -0.2, 0.1
    plant = Plant(ContactSet([v0, v0, v0]), 5.0, motors=Motors(lag=tau),
                  commands=PiecewiseConstant([0.3], [[v0] * 3, [u] * 3]))
    result = simulate(plant, 1.0)
    sensors = Sensors(Encoder(8192, 0.266), Encoder(3591.84, 0.045), 3)      # no backlash
    record = record_simulation(result, plant, sensors)
    t = record.times
    s = np.maximum(t - 0.3, 0.0)
    x = np.where(t < 0.3, v0 * t, 0.03 + u * s + (v0 - u) * tau * -np.expm1(-s / tau))
    q = sensors.wheel.distance_per_count
    # Gauss-Legendre error below 1e-17 m (GAUSS_NODES note); floors of x / q agree unless x
    # lies within 1e-12 m of a count edge (x = 0 at t = 0 is exact), which this would reveal.
    assert np.min(np.abs(x[1:] / q - np.rint(x[1:] / q))) * q > 1e-12
    np.testing.assert_array_equal(record.wheel_counts[:, 0], np.floor(x / q))


def _noisy_record(seed: int) -> EncoderRecord:
    plant = _startup_plant(lag=0.0075)
    result = simulate(plant, 1.0)
    sensors = CAROUSEL.sensors(missed_count_prob=0.01, count_noise=0.5, jitter=1e-3)
    return record_simulation(result, plant, sensors, rng=np.random.default_rng(seed))


def test_same_seed_gives_the_same_record():
    a, b, c = _noisy_record(7), _noisy_record(7), _noisy_record(8)
    np.testing.assert_array_equal(a.central_counts, b.central_counts)
    np.testing.assert_array_equal(a.wheel_counts, b.wheel_counts)
    assert not np.array_equal(a.wheel_counts, c.wheel_counts)


def test_one_sample_at_a_time_equals_the_whole_record():
    sensors = CAROUSEL.sensors(n_wheels=3, missed_count_prob=0.05, count_noise=0.7)
    k = np.arange(100)
    X = 0.004 * k + 1e-4 * np.sin(k)
    x = np.outer(0.003 * np.cos(k / 10), [1.0, -1.0, 0.5])
    whole = measure(sensors, X, x, sensors.initial_state(), np.random.default_rng(3))
    rng, state, rows = np.random.default_rng(3), sensors.initial_state(), []
    for j in k:
        c, w, state = measure(sensors, X[j:j + 1], x[j:j + 1], state, rng)
        rows.append((c[0], w[0]))
    np.testing.assert_array_equal(whole[0], [r[0] for r in rows])
    np.testing.assert_array_equal(whole[1], np.array([r[1] for r in rows]))


def test_every_transition_missed_freezes_the_counts():
    sensors = CAROUSEL.sensors(n_wheels=2, missed_count_prob=1.0)
    X = np.linspace(0, 0.1, 50)
    central, wheel, _ = measure(sensors, X, np.c_[X, -X], sensors.initial_state(), np.random.default_rng(0))
    assert np.all(central == 0) and np.all(wheel == wheel[0])


def test_noisy_sensors_need_a_generator():
    sensors = CAROUSEL.sensors(n_wheels=1, count_noise=1.0)
    with pytest.raises(ParameterTypeError, match="'rng' parameter of measure"):
        measure(sensors, [0.0], [[0.0]], sensors.initial_state(), None)


def test_sensor_reader_equals_measure_and_keeps_the_state():
    # The loop's reader and measure() run the same per-row law with the same draws.
    from toolkit.model.sensors import SensorReader

    sensors = CAROUSEL.sensors(n_wheels=3, missed_count_prob=0.05, count_noise=0.7)
    k = np.arange(60)
    X = 0.004 * k + 1e-4 * np.sin(k)
    x = np.outer(0.003 * np.cos(k / 10), [1.0, -1.0, 0.5])
    central, wheel, state = measure(sensors, X, x, sensors.initial_state(), np.random.default_rng(5))
    reader = SensorReader(sensors, sensors.initial_state(), np.random.default_rng(5))
    rows = [reader.read(float(X[j]), x[j]) for j in k]
    np.testing.assert_array_equal(central, [r[0] for r in rows])
    np.testing.assert_array_equal(wheel, np.array([r[1] for r in rows]))
    np.testing.assert_array_equal(reader.state.motor, state.motor)
    assert reader.state.central_offset == state.central_offset


def test_record_initial_commands_are_checked():
    with pytest.raises(ParameterError, match="'initial_commands' parameter of EncoderRecord must have shape"):
        EncoderRecord([0.0, 0.02], [0, 1], [[0, 0], [1, 1]], [[0.1, 0.1], [0.1, 0.1]], 1e-4, 1e-4,
                      initial_commands=[0.1])
    with pytest.raises(ParameterError, match="'initial_commands' parameter of EncoderRecord must be finite"):
        EncoderRecord([0.0, 0.02], [0, 1], [[0, 0], [1, 1]], [[0.1, 0.1], [0.1, 0.1]], 1e-4, 1e-4,
                      initial_commands=[0.1, float("nan")])


def test_record_force_is_checked_and_filled_from_the_plant():
    with pytest.raises(ParameterError, match="'force' parameter of EncoderRecord must have shape"):
        EncoderRecord([0.0, 0.02], [0, 1], [[0, 0], [1, 1]], [[0.1, 0.1], [0.1, 0.1]], 1e-4, 1e-4,
                      force=[0.1])
    with pytest.raises(ParameterError, match="'force' parameter of EncoderRecord must be finite"):
        EncoderRecord([0.0, 0.02], [0, 1], [[0, 0], [1, 1]], [[0.1, 0.1], [0.1, 0.1]], 1e-4, 1e-4,
                      force=[0.1, float("inf")])
    # record_simulation stamps the plant's outside force at each sample (held like the
    # commands): a switch at 0.5 s from 0.3 N to -0.1 N, exact values.
    plant = Plant(ContactSet([0.0, 0.1]), 1.0, external_force=PiecewiseConstant([0.5], [0.3, -0.1]))
    record = record_simulation(simulate(plant, 1.0), plant, CAROUSEL.sensors(2))
    np.testing.assert_array_equal(record.force, np.where(record.times < 0.5, 0.3, -0.1))
    assert record.sample(30).force == -0.1


def test_record_starts_anywhere_on_the_count_grids():
    # The encoders count from wherever the body and the contacts were at power-up: starting
    # them x0 and c0 into the grids adds x0 to the true position and counts floor((x0 + X) /
    # q) (the closed form of the constant-acceleration run above); a start one whole count in
    # shifts every count by exactly one (an identity).
    plant = _startup_plant()
    result = simulate(plant, 1.0)
    sensors = CAROUSEL.sensors()
    q, qw = sensors.central.distance_per_count, sensors.wheel.distance_per_count
    base = record_simulation(result, plant, sensors)
    x0, c0 = 0.37 * q, np.linspace(0.1, 0.9, 10) * qw
    moved = record_simulation(result, plant, sensors, central_position=x0, contact_positions=c0)
    t = moved.times
    X = np.where(t < 0.5, t**2, 0.25 + (t - 0.5))
    np.testing.assert_allclose(moved.truth_position, x0 + X, rtol=0, atol=1e-13)
    np.testing.assert_array_equal(moved.central_counts, np.floor((x0 + X) / q))
    motor = t[:, None] + c0 - sensors.backlash / 2
    np.testing.assert_array_equal(moved.wheel_counts, np.floor(motor / qw))
    whole = record_simulation(result, plant, sensors, central_position=q, contact_positions=np.full(10, qw))
    np.testing.assert_array_equal(whole.central_counts, base.central_counts + 1)
    np.testing.assert_array_equal(whole.wheel_counts, base.wheel_counts + 1)
    with pytest.raises(ParameterError, match="contact_positions"):
        record_simulation(result, plant, sensors, contact_positions=[0.0, 0.0])
    with pytest.raises(ParameterError, match="central_position"):
        record_simulation(result, plant, sensors, central_position=1e30)
    with pytest.raises(ParameterError, match="central_position"):
        record_simulation(result, plant, sensors, central_position=np.nan)


def _two_contacts():
    plant = Plant(ContactSet([0.0, 0.1]), 1.0)
    return plant, simulate(plant, 1.0), CAROUSEL.sensors(2)


@pytest.mark.parametrize("change, error, message", [
    ({"sensors": "x"}, ParameterTypeError, "'sensors' parameter of record_simulation must be a Sensors. Got 'x' instead."),
    ({"result": "x"}, ParameterTypeError, "'result' parameter of record_simulation must be an exact SimulationResult "
                                          "with a dense output. Got 'x' instead."),
    ({"sensors": CAROUSEL.sensors(3)}, ParameterError,
     "'sensors' parameter of record_simulation must have n_wheels = plant.n = 2. Got 3 instead."),
    ({"t_end": -0.5}, ParameterError, "'t_end' parameter of record_simulation must be >= 0. Got -0.5 instead."),
    ({"t_end": 2.0}, ParameterError, "'t_end' parameter of record_simulation must be <= 1. Got 2.0 instead."),
    ({"sensors": CAROUSEL.sensors(2, jitter=1e-3)}, ParameterTypeError,
     "'rng' parameter of record_simulation must be a numpy.random.Generator when the sensors jitter. "
     "Got None instead."),
    ({"central_position": 1e30}, ParameterError, "'central_position' parameter of record_simulation must be within "
                                                 "2^52 counts of the grid's origin. Got 1e+30 instead."),
    ({"contact_positions": [0.0, 0.0, 0.0]}, ParameterError,
     "'contact_positions' parameter of record_simulation must have shape (2,). Got 'an array of shape (3,)' instead."),
])
def test_record_simulation_refuses_with_the_whole_message(change, error, message):
    """Each refusal matched whole: parameter, owner, rule and value (mutants: any of them
    changed or dropped, the jitter test's threshold)."""
    plant, result, sensors = _two_contacts()
    args = {"result": result, "plant": plant, "sensors": sensors, **change}
    with pytest.raises(error, match="^The " + re.escape(message) + "$"):
        record_simulation(args.pop("result"), args.pop("plant"), args.pop("sensors"), **args)


def test_record_simulation_bounds_the_start_and_the_horizon_exactly():
    """The central start must lie strictly within 2^52 counts: ``2^52 q`` is refused and
    ``(1 - 2^-10) 2^52 q`` read (mutants: ``<`` to ``<=``, 2^52 to 2^53 or 3^52 or 2 * 52,
    ``* q`` to ``/ q``). ``t_end`` bounds the stamps, ``k / rate`` up to it (0 gives the one
    sample at 0; mutant: the lower bound 0 to 1)."""
    plant, result, sensors = _two_contacts()
    q = sensors.central.distance_per_count
    with pytest.raises(ParameterError, match="'central_position' parameter of record_simulation must be within 2"):
        record_simulation(result, plant, sensors, central_position=2.0 ** 52 * q)
    with pytest.raises(ParameterError, match="'central_position' parameter of record_simulation must be within 2"):
        record_simulation(result, plant, sensors, central_position=-(2.0 ** 52) * q)
    far = record_simulation(result, plant, sensors, central_position=(1 - 2.0 ** -10) * 2.0 ** 52 * q)
    assert far.central_counts[0] == np.floor((1 - 2.0 ** -10) * 2.0 ** 52)
    np.testing.assert_array_equal(record_simulation(result, plant, sensors, t_end=0.5).times, np.arange(26) / 50.0)
    np.testing.assert_array_equal(record_simulation(result, plant, sensors, t_end=0.0).times, [0.0])
    np.testing.assert_array_equal(record_simulation(result, plant, sensors).times, np.arange(51) / 50.0)
