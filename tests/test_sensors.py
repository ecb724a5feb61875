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


def _stepped_record(motors, switch, contact_positions=None):
    """Three contacts commanded 0.1 -> -0.2 m/s at ``switch`` (s) through ``motors``, recorded
    by encoders without backlash; and the wheels' count distance (m)."""
    plant = Plant(ContactSet([0.1] * 3), 5.0, motors=motors,
                  commands=PiecewiseConstant([switch], [[0.1] * 3, [-0.2] * 3]))
    sensors = Sensors(Encoder(8192, 0.266), Encoder(3591.84, 0.045), 3)
    record = record_simulation(simulate(plant, 1.0), plant, sensors, contact_positions=contact_positions)
    return record, sensors.wheel.distance_per_count


def test_record_contact_positions_match_the_motor_lag_closed_form():
    # A command step 0.1 -> -0.2 m/s at t = 0.3 s through a 7.5 ms lag: after the step
    # x(t) = 0.03 + u s + (v0 - u) tau (1 - exp(-s / tau)), s = t - 0.3.
    tau, u, v0 = 0.0075, -0.2, 0.1
    record, q = _stepped_record(Motors(lag=tau), 0.3)
    t = record.times
    s = np.maximum(t - 0.3, 0.0)
    x = np.where(t < 0.3, v0 * t, 0.03 + u * s + (v0 - u) * tau * -np.expm1(-s / tau))
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


# -- each rule of the encoders and the suite, bracketed and refused in full --------------------
def _whole(message: str) -> str:
    return "^The " + re.escape(message) + "$"


def test_encoder_summary_holds_its_resolutions():
    # Dyadic numbers: counts_per_rev 2^13 at radius 2^-3 over 2 pi: q = 2 pi 2^-3 / 2^13
    # = pi 2^-15 (a product by powers of two: exact), x 64 Hz = pi 2^-9; backlash 2^-10 x 64.
    enc = Encoder(8192, 0.125, rate=64.0, backlash=2.0 ** -10)
    assert enc.summary() == {"distance_per_count": math.pi * 2.0 ** -15, "speed_step": math.pi * 2.0 ** -9,
                             "backlash_speed_step": 2.0 ** -4, "rate": 64.0}


@pytest.mark.parametrize("name", ["counts_per_rev", "radius", "rate"])
def test_encoder_positive_parameters_are_bracketed_at_zero(name):
    """0 is refused with the whole message, 2^-1074 (the least positive double) and 0.5
    (below a bound of 1) are taken as given."""
    args = {"counts_per_rev": 8192.0, "radius": 0.266, "rate": 50.0, name: 0.0}
    with pytest.raises(ParameterError, match=_whole(f"'{name}' parameter of Encoder must be > 0. Got 0.0 instead.")):
        Encoder(**args)
    for value in (0.5, 2.0 ** -1074):
        assert getattr(Encoder(**{**args, name: value}), name) == value


def test_encoder_backlash_is_bracketed_at_zero():
    assert Encoder(8192, 0.266, backlash=0.0).backlash == 0.0
    assert Encoder(8192, 0.266, backlash=0.5).backlash == 0.5
    with pytest.raises(ParameterError,
                       match=_whole("'backlash' parameter of Encoder must be >= 0. Got -1e-09 instead.")):
        Encoder(8192, 0.266, backlash=-1e-9)


def _suite(**kwargs):
    args = {"central": Encoder(8192, 0.266, rate=64.0), "wheel": Encoder(3591.84, 0.045, rate=64.0, backlash=0.001),
            "n_wheels": 3, **kwargs}
    return Sensors(**args)


@pytest.mark.parametrize("change, error, message", [
    ({"central": 1.0}, ParameterTypeError, "'central' parameter of Sensors must be an Encoder. Got 1.0 instead."),
    ({"wheel": "w"}, ParameterTypeError, "'wheel' parameter of Sensors must be an Encoder. Got 'w' instead."),
    ({"wheel": Encoder(3591.84, 0.045, rate=100.0)}, ParameterError,
     "'wheel' parameter of Sensors must have the central encoder's rate (64 Hz). Got 'rate 100 Hz' instead."),
    ({"n_wheels": 0}, ParameterError, "'n_wheels' parameter of Sensors must be >= 1. Got 0 instead."),
    ({"missed_count_prob": -0.25}, ParameterError,
     "'missed_count_prob' parameter of Sensors must be >= 0. Got -0.25 instead."),
    ({"missed_count_prob": 1.25}, ParameterError,
     "'missed_count_prob' parameter of Sensors must be <= 1. Got 1.25 instead."),
    ({"count_noise": -0.5}, ParameterError, "'count_noise' parameter of Sensors must be >= 0. Got -0.5 instead."),
    ({"jitter": -0.5}, ParameterError, "'jitter' parameter of Sensors must be >= 0. Got -0.5 instead."),
    ({"jitter": 2.0 ** -10 + 2.0 ** -60}, ParameterError,
     "'jitter' parameter of Sensors must be <= 0.0625 period (0.0009766 s at 64 Hz: the read offsets are a "
     "normal law truncated at a quarter period, which must lie at least 4 standard deviations out). "
     "Got 0.0009765625000000009 instead."),
])
def test_sensor_suites_refuse_with_the_whole_message(change, error, message):
    with pytest.raises(error, match=_whole(message)):
        _suite(**change)


def test_sensor_suite_bounds_are_taken_at_their_edges():
    # The jitter bound is 1/16 period = 2^-4 / 64 = 2^-10 s at 64 Hz, exact: taken at it and
    # refused 2^-60 above (the previous test). Probabilities 0 and 1 and zero noise are taken.
    assert _suite(jitter=2.0 ** -10).jitter == 2.0 ** -10
    edge = _suite(missed_count_prob=1.0, count_noise=0.0, n_wheels=1)
    assert (edge.missed_count_prob, edge.count_noise, edge.n_wheels) == (1.0, 0.0, 1)
    assert _suite(missed_count_prob=0.0).missed_count_prob == 0.0
    assert _suite(n_wheels=2.0).n_wheels == 2 and type(_suite(n_wheels=2.0).n_wheels) is int
    # The suite's rate, period and play are its encoders': 64 Hz, 2^-6 s, the wheel's 1 mm.
    suite = _suite()
    assert (suite.rate, suite.period, suite.backlash) == (64.0, 2.0 ** -6, 0.001)


def test_sensors_checked_for_a_plant():
    suite = _suite()
    assert Sensors.checked(suite, 3, "Loop") is suite
    with pytest.raises(ParameterTypeError,
                       match=_whole("'sensors' parameter of Loop must be a Sensors or None. Got 3 instead.")):
        Sensors.checked(3, 3, "Loop")
    with pytest.raises(ParameterError, match=_whole(
            "'sensors' parameter of Loop must have one wheel encoder per contact (4). Got 3 instead.")):
        Sensors.checked(suite, 4, "Loop")


def test_read_noise_variance_matches_sheppards_correction_and_the_rounded_law():
    """A normal of std s rounded to whole counts has variance s^2 + 1/12 up to terms of
    order exp(-2 pi^2 s^2) (Sheppard's correction; the Poisson summation of the normal's
    characteristic function): below 1e-30 at s >= 2, so the sum is exact to its rounding
    (30 terms: 1e-14 relative)."""
    assert _suite().read_noise_variance == 0.0
    for s in (2.0, 3.5, 10.0):
        assert _suite(count_noise=s).read_noise_variance == pytest.approx(s * s + 1 / 12, rel=1e-14, abs=0)
    # s = 1/2: 2 (P(k=1) + 4 P(k=2) + 9 P(k=3) + ...) = 0.3250 (a sum of the normal's masses
    # by scipy's stats.norm, a second method; 1e-12: its cdf's rounding over 40 terms).
    from scipy.stats import norm

    k = np.arange(1, 40)
    expect = 2 * np.sum(k * k * (norm.cdf(k + 0.5, scale=0.5) - norm.cdf(k - 0.5, scale=0.5)))
    assert _suite(count_noise=0.5).read_noise_variance == pytest.approx(expect, rel=1e-12, abs=0)
    assert expect == pytest.approx(0.325, abs=5e-4)
    # s = 1/20: only k = +-1 matter, 2 P(k = 1) = 2 (Phi(30) - Phi(10)) = 2 Phi(-10).
    assert _suite(count_noise=0.05).read_noise_variance == pytest.approx(2 * norm.sf(10.0), rel=1e-12, abs=0)


def test_initial_state_loads_each_gearbox_against_its_own_motion():
    # Unequal speeds of each sign and zero: motor = x0 - sign(v) b / 2 exactly (b = 1 mm);
    # counts floor(x / q); no offsets.
    suite = _suite()
    b, qw, qc = 0.001, suite.wheel.distance_per_count, suite.central.distance_per_count
    x0 = np.array([0.25, -0.5, 0.125])
    state = suite.initial_state([0.3, -0.05, 0.0], central_position=7.5 * qc, contact_positions=x0)
    np.testing.assert_array_equal(state.motor, x0 - np.array([b / 2, -b / 2, 0.0]))
    np.testing.assert_array_equal(state.wheel_count, np.floor(state.motor / qw))
    assert state.central_count == 7 and type(state.central_count) is int
    assert state.central_offset == 0
    np.testing.assert_array_equal(state.wheel_offset, np.zeros(3, dtype=np.int64))
    assert state.wheel_offset.dtype == np.int64
    rest = suite.initial_state()
    np.testing.assert_array_equal(rest.motor, np.zeros(3))
    assert rest.central_count == 0 and rest.central_offset == 0


def test_measure_refuses_a_shape_and_a_missing_generator_in_full():
    suite = _suite()
    with pytest.raises(ParameterError, match=_whole(
            "'contact_positions' parameter of measure must have shape (2, 3). Got 'an array of shape (2, 2)' "
            "instead.")):
        measure(suite, [0.0, 1.0], np.zeros((2, 2)), suite.initial_state())
    for noisy in ({"missed_count_prob": 0.5}, {"count_noise": 0.5}):
        with pytest.raises(ParameterTypeError, match=_whole(
                "'rng' parameter of measure must be a numpy.random.Generator when counts can be missed or noisy. "
                "Got 1 instead.")):
            measure(_suite(**noisy), [0.0], np.zeros((1, 3)), suite.initial_state(), 1)
    # A noiseless suite needs none, and consumes no draws from one it is given.
    rng = np.random.default_rng(4)
    central, wheel, _ = measure(suite, [0.0], np.zeros((1, 3)), suite.initial_state(), rng)
    assert rng.random() == np.random.default_rng(4).random()


def test_missed_counts_per_channel_follow_the_binomial_law():
    """Each channel moving at its own speed (unequal, both signs) loses a fraction p of its
    transitions, against its motion: after N transitions the offset is -sign(v) Binomial(N,
    p). Checked per channel against its own mean N p and standard deviation sqrt(N p (1-p))
    (5 sigma: a false failure once in 2e6), so a loss drawn from another channel's count or
    with a changed sign shows."""
    p = 0.25
    suite = _suite(missed_count_prob=p)
    qc, qw = suite.central.distance_per_count, suite.wheel.distance_per_count
    k = np.arange(2001)
    X = -3.0 * qc * k                                      # the body: 3 counts back per sample
    x = np.outer(k * qw, [1.0, -5.0, 12.0]) + 0.5 * qw     # the wheels: 1, 5 and 12 per sample
    start = suite.initial_state(central_position=X[0], contact_positions=x[0])
    central, wheel, state = measure(suite, X, x, start, np.random.default_rng(11))
    true_c = np.floor(X / qc).astype(np.int64)
    motor = play(x, suite.backlash, start.motor)
    true_w = np.floor(motor / qw).astype(np.int64)
    lost_c = central - true_c
    lost_w = wheel - true_w
    for lost, moved in ((lost_c[-1], true_c[-1] - true_c[0]),
                        *zip(lost_w[-1], true_w[-1] - true_w[0])):
        n = abs(int(moved))
        assert n > 1000
        assert -np.sign(moved) * lost == pytest.approx(n * p, abs=5 * math.sqrt(n * p * (1 - p)))
    assert state.central_offset == lost_c[-1]
    np.testing.assert_array_equal(state.wheel_offset, lost_w[-1])
    np.testing.assert_array_equal(state.wheel_count, true_w[-1])
    assert state.central_count == true_c[-1]
    # Missed counts never come back: each channel's loss is monotone in the sample.
    assert np.all(np.diff(lost_c) >= 0)
    assert np.all(np.diff(lost_w[:, 0]) <= 0) and np.all(np.diff(lost_w[:, 1]) >= 0)


def test_read_noise_per_channel_has_the_rounded_laws_variance():
    """Still positions: every read is the true count plus rounded noise, not accumulated.
    Per channel the sample variance over N = 4000 reads matches read_noise_variance (its
    standard error is sqrt(2/N) var for a near-normal law: 5 of them), and the mean 0."""
    s = 1.5
    suite = _suite(count_noise=s)
    qc, qw = suite.central.distance_per_count, suite.wheel.distance_per_count
    N = 4000
    X = np.full(N, 10.5 * qc)
    x = np.tile(np.array([3.5, -7.5, 100.5]) * qw, (N, 1))
    start = suite.initial_state(central_position=X[0], contact_positions=x[0])
    central, wheel, _ = measure(suite, X, x, start, np.random.default_rng(21))
    var = suite.read_noise_variance
    for noise in (central - 10, *(wheel - np.floor(x[0] / qw).astype(np.int64)).T):
        assert np.all(noise == np.rint(noise))
        assert np.var(noise) == pytest.approx(var, rel=5 * math.sqrt(2 / N))
        assert abs(np.mean(noise)) < 5 * math.sqrt(var / N)


def _record(**change):
    args = {"times": [0.0, 0.02, 0.03, 0.07], "central_counts": [0, 1, 3, 6],
            "wheel_counts": [[0, 0], [1, -1], [2, -3], [5, -7]],
            "commands": [[0.1, -0.1], [0.1, -0.1], [0.2, -0.2], [0.2, -0.2]],
            "central_resolution": 1e-4, "wheel_resolution": 2e-5, **change}
    return EncoderRecord(**args)


@pytest.mark.parametrize("change, error, message", [
    ({"times": [0.0, 0.02, 0.02, 0.07]}, ParameterError,
     "'times' parameter of EncoderRecord must be strictly increasing. Got [0.0, 0.02, 0.02, 0.07] instead."),
    ({"times": np.arange(10.0)[::-1]}, ParameterError,
     "'times' parameter of EncoderRecord must be strictly increasing. Got [9.0, 8.0, 7.0, 6.0, 5.0, 4.0, 3.0, 2.0] "
     "instead."),
    ({"central_counts": [0.0, 1.0, 3.0, 6.0]}, ParameterError,
     "'central_counts' parameter of EncoderRecord must be a 1-dimensional array of integer counts. "
     "Got 'an array of dtype float64 and shape (4,)' instead."),
    ({"wheel_counts": [0, 1, 2, 5]}, ParameterError,
     "'wheel_counts' parameter of EncoderRecord must be a 2-dimensional array of integer counts. "
     "Got 'an array of dtype int64 and shape (4,)' instead."),
    ({"central_counts": [0, 1, 3]}, ParameterError,
     "'central_counts' parameter of EncoderRecord must have shape (4,). Got 'an array of shape (3,)' instead."),
    ({"wheel_counts": [[0, 0], [1, -1], [2, -3]]}, ParameterError,
     "'wheel_counts' parameter of EncoderRecord must have shape (4, 2). Got 'an array of shape (3, 2)' instead."),
    ({"commands": [[0.1], [0.1], [0.2], [0.2]]}, ParameterError,
     "'commands' parameter of EncoderRecord must have shape (4, 2). Got 'an array of shape (4, 1)' instead."),
    ({"commands": [0.1, 0.1, 0.2, 0.2]}, ParameterError,
     "'commands' parameter of EncoderRecord must be 2-dimensional. Got 'an array of shape (4,)' instead."),
    ({"central_resolution": 0.0}, ParameterError,
     "'central_resolution' parameter of EncoderRecord must be > 0. Got 0.0 instead."),
    ({"wheel_resolution": -1.0}, ParameterError,
     "'wheel_resolution' parameter of EncoderRecord must be > 0. Got -1.0 instead."),
    ({"wheel_backlash": -1e-3}, ParameterError,
     "'wheel_backlash' parameter of EncoderRecord must be >= 0. Got -0.001 instead."),
    ({"truth_speed": [0.0, 0.1, 0.2]}, ParameterError,
     "'truth_speed' parameter of EncoderRecord must have shape (4,). Got 'an array of shape (3,)' instead."),
    ({"truth_position": [[0.0], [0.1], [0.2], [0.3]]}, ParameterError,
     "'truth_position' parameter of EncoderRecord must be 1-dimensional. Got 'an array of shape (4, 1)' instead."),
    ({"truth_position": [0.0, 0.1, 0.2, 0.3, 0.4]}, ParameterError,
     "'truth_position' parameter of EncoderRecord must have shape (4,). Got 'an array of shape (5,)' instead."),
    ({"truth_contact_speeds": [[0.1, 0.1, 0.1]] * 4}, ParameterError,
     "'truth_contact_speeds' parameter of EncoderRecord must have shape (4, 2). Got 'an array of shape (4, 3)' "
     "instead."),
    ({"truth_contact_speeds": [0.1] * 4}, ParameterError,
     "'truth_contact_speeds' parameter of EncoderRecord must be 2-dimensional. Got 'an array of shape (4,)' "
     "instead."),
    ({"initial_commands": [0.1, 0.1, 0.1]}, ParameterError,
     "'initial_commands' parameter of EncoderRecord must have shape (2,). Got 'an array of shape (3,)' instead."),
    ({"force": [[0.0]] * 4}, ParameterError,
     "'force' parameter of EncoderRecord must be 1-dimensional. Got 'an array of shape (4, 1)' instead."),
    ({"force": [0.0] * 5}, ParameterError,
     "'force' parameter of EncoderRecord must have shape (4,). Got 'an array of shape (5,)' instead."),
])
def test_encoder_record_refuses_with_the_whole_message(change, error, message):
    with pytest.raises(error, match=_whole(message)):
        _record(**change)


def test_encoder_record_holds_what_it_was_given():
    """Uneven stamps (periods 0.02, 0.01, 0.04 s): the period is their median 0.02 s, not the
    mean or the first; the duration 0.07 s; every array read-only and in its own dtype."""
    record = _record(wheel_backlash=0.0, truth_speed=[0.0, 0.1, 0.2, 0.3], truth_position=[0.0, 1e-3, 2e-3, 3e-3],
                     truth_contact_speeds=[[0.1, -0.1]] * 4, initial_commands=[0.05, -0.05],
                     force=[0.5, -0.25, 0.0, 1.0])
    assert (record.n_samples, len(record), record.n_wheels) == (4, 4, 2)
    assert record.period == 0.02 and record.duration == 0.07 and record.has_truth
    assert record.central_counts.dtype == np.int64 and record.wheel_counts.dtype == np.int64
    np.testing.assert_array_equal(record.truth_contact_speeds, [[0.1, -0.1]] * 4)
    np.testing.assert_array_equal(record.truth_position, [0.0, 1e-3, 2e-3, 3e-3])
    for name in ("times", "central_counts", "wheel_counts", "commands", "initial_commands", "force",
                 "truth_speed"):
        assert not getattr(record, name).flags.writeable, name
    sample = record.sample(2)
    assert (sample.time, sample.central_count, sample.force) == (0.03, 3, 0.0)
    assert type(sample.time) is float and type(sample.central_count) is int and type(sample.force) is float
    np.testing.assert_array_equal(sample.wheel_counts, [2, -3])
    np.testing.assert_array_equal(sample.command, [0.2, -0.2])
    assert record.sample(1).force == -0.25
    # Counts given as uint8 are widened to int64 (not wrapped); a lone stamp has no period.
    wide = _record(central_counts=np.array([0, 1, 3, 250], dtype=np.uint8))
    assert wide.central_counts.dtype == np.int64 and wide.central_counts[-1] == 250
    bare = _record()
    assert not bare.has_truth and bare.force is None and bare.initial_commands is None
    assert bare.sample(3).force == 0.0 and bare.wheel_backlash == 0.0
    one = EncoderRecord([0.5], [1], [[2]], [[0.1]], 1e-4, 1e-4)
    assert math.isnan(one.period) and one.duration == 0.0


def test_contact_speeds_follow_the_motor_law_at_any_time():
    """Ideal motors: the commands clipped to the speed limits, piecewise constant; dynamic
    motors: the lag's closed form v = u + (v0 - u) exp(-s / tau) after each switch, with the
    kinks at the switches. Unequal commands, limits that cut one of them."""
    from toolkit.model.sensors import contact_speeds_at

    commands = PiecewiseConstant([0.25, 0.5], [[0.1, -0.3], [0.4, 0.2], [-0.05, 0.0]])
    t = np.array([0.0, 0.125, 0.25, 0.375, 0.5, 0.75])
    ideal = Plant(ContactSet([0.1, -0.3]), 1.0, motors=Motors(speed_limits=(-0.25, 0.35)), commands=commands)
    speeds, kinks = contact_speeds_at(ideal, t)
    np.testing.assert_array_equal(speeds, [[0.1, -0.25], [0.1, -0.25], [0.35, 0.2], [0.35, 0.2],
                                           [-0.05, 0.0], [-0.05, 0.0]])
    np.testing.assert_array_equal(kinks, [0.25, 0.5])
    # Without commands the contacts keep their speeds (unclipped when there are no motors).
    still, none = contact_speeds_at(Plant(ContactSet([0.1, -0.3]), 1.0), t[:3])
    np.testing.assert_array_equal(still, [[0.1, -0.3]] * 3)
    assert none.size == 0
    tau = 2.0 ** -6
    lagging = Plant(ContactSet([0.1, -0.3]), 1.0, motors=Motors(lag=tau), commands=commands)
    speeds, kinks = contact_speeds_at(lagging, t)
    v0 = np.array([0.1, -0.3])
    u1, u2 = np.array([0.4, 0.2]), np.array([-0.05, 0.0])
    v1 = u1 + (v0 - u1) * np.exp(-0.25 / tau)          # at the second switch
    expect = [v0, v0, v0, u1 + (v0 - u1) * np.exp(-0.125 / tau), v1, u2 + (v1 - u2) * np.exp(-0.25 / tau)]
    # The closed form evaluated once more in another order: a few ulp of 0.4 m/s.
    np.testing.assert_allclose(speeds, expect, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(kinks, [0.25, 0.5])


# -- what the suite and the record keep, as floats and integers --------------------------------
def test_parameters_are_kept_as_the_floats_and_integers_they_are_checked_as():
    """Integers (and NumPy scalars) given are stored as Python floats after the check, so a
    record or a scene sees one type whatever was typed."""
    enc = Encoder(8192, 1, rate=64, backlash=1)
    for name in ("counts_per_rev", "radius", "rate", "backlash"):
        assert type(getattr(enc, name)) is float, name
    suite = Sensors(enc, Encoder(100, 1, rate=64), 2, missed_count_prob=np.float32(0.5), count_noise=1,
                    jitter=np.float32(2.0 ** -10))
    for name in ("missed_count_prob", "count_noise", "jitter"):
        assert type(getattr(suite, name)) is float, name
    record = EncoderRecord([0, 1], [0, 1], [[0], [1]], [[0.0], [0.0]], 1, 1, wheel_backlash=0)
    assert type(record.wheel_backlash) is float and record.times.dtype == np.float64
    counts = enc.counts(np.array([0.5, 1.5]) * enc.distance_per_count)
    assert counts.dtype == np.int64 and counts.tolist() == [0, 1]


def test_integer_counts_are_copied_into_read_only_int64():
    """The record keeps its own read-only int64 copy of the counts (the caller's array stays
    writable and unchanged), from int64, int32 or unsigned input alike."""
    given = np.array([0, 1, 3], dtype=np.int64)
    wheels = np.array([[0], [2], [5]], dtype=np.int32)
    record = EncoderRecord([0.0, 0.5, 1.0], given, wheels, [[0.0]] * 3, 1e-4, 1e-4)
    given[0] = 7
    assert given.flags.writeable and record.central_counts[0] == 0
    assert not record.central_counts.flags.writeable and record.wheel_counts.dtype == np.int64
    for bad in (np.array([0.0, 1.0, 3.0]), np.array(["0", "1", "3"]), np.array([True, False, True])):
        with pytest.raises(ParameterError, match="^" + re.escape(
                "The 'central_counts' parameter of EncoderRecord must be a 1-dimensional array of integer counts. "
                f"Got 'an array of dtype {bad.dtype} and shape (3,)' instead.") + "$"):
            EncoderRecord([0.0, 0.5, 1.0], bad, wheels, [[0.0]] * 3, 1e-4, 1e-4)
    with pytest.raises(ParameterError, match="^" + re.escape(
            "The 'times' parameter of EncoderRecord must be finite (no NaN or inf). Got nan instead.") + "$"):
        EncoderRecord([0.0, np.nan, 1.0], given, wheels, [[0.0]] * 3, 1e-4, 1e-4)
    record = EncoderRecord([0.0], [0], [[0]], [[0.0]], 1e-4, 1e-4, force=[0.5], initial_commands=[0.25])
    assert not record.force.flags.writeable and not record.initial_commands.flags.writeable


def test_measure_names_each_position_argument_in_full():
    suite = _suite()
    with pytest.raises(ParameterError, match=_whole(
            "'central_positions' parameter of measure must be finite (no NaN or inf). Got nan instead.")):
        measure(suite, [0.0, np.nan], np.zeros((2, 3)), suite.initial_state())
    with pytest.raises(ParameterError, match=_whole(
            "'contact_positions' parameter of measure must be 2-dimensional. Got 'an array of shape (3,)' instead.")):
        measure(suite, [0.0], np.zeros(3), suite.initial_state())


def test_initial_state_takes_a_row_or_a_column_of_positions():
    # One value per wheel, whatever the nesting: a (1, n) row and an (n, 1) column of speeds.
    suite = _suite()
    state = suite.initial_state([[0.5], [-0.5], [0.0]], contact_positions=[[0.25, 0.5, 0.75]])
    assert state.motor.shape == (3,) and state.wheel_count.shape == (3,)
    np.testing.assert_array_equal(state.motor, [0.25 - 0.0005, 0.5 + 0.0005, 0.75])


def test_a_reader_from_a_hand_made_state_reports_int64_counts():
    """A state written by hand with float counts and offsets (``np.zeros(n)``) and a list for
    the motor side: the reader keeps int64 counts, so it reports int64 counts and offsets and
    the missed counts are still whole; every transition missed (p = 1) freezes each wheel at
    its count."""
    from toolkit.model.sensors import SensorReader, SensorState

    suite = _suite(missed_count_prob=1.0)
    qw = suite.wheel.distance_per_count
    state = SensorState(motor=[0.5 * qw, 1.5 * qw, -2.5 * qw], central_count=0, wheel_count=np.array([0.0, 1.0, -3.0]),
                        central_offset=0, wheel_offset=np.zeros(3))
    reader = SensorReader(suite, state, np.random.default_rng(1))
    for k in range(1, 4):
        central, wheels = reader.read(0.0, np.array([0.5 + 7 * k, 1.5 - 5 * k, -2.5]) * qw)
        assert wheels.dtype == np.int64 and type(central) is int
        np.testing.assert_array_equal(wheels, [0, 1, -3])
    after = reader.state
    assert after.wheel_count.dtype == np.int64 and after.wheel_offset.dtype == np.int64
    assert after.motor.dtype == np.float64


@pytest.mark.parametrize("s", [0.5, 0.75, 1.5])
def test_read_noise_is_added_per_channel_with_its_own_draws(s):
    """The noise is added (not subtracted) to each channel, one normal draw per channel per
    read, central first: the same draws taken from a generator of the same seed give each
    read exactly (an identity of the documented draw order); and at a half count or more it is
    drawn at all (the noise test of the law above covers the variance)."""
    suite = _suite(count_noise=s)
    qc, qw = suite.central.distance_per_count, suite.wheel.distance_per_count
    X = np.full(50, 10.5 * qc)
    x = np.tile(np.array([3.5, -7.5, 100.5]) * qw, (50, 1))
    start = suite.initial_state(central_position=X[0], contact_positions=x[0])
    central, wheel, _ = measure(suite, X, x, start, np.random.default_rng(2))
    rng = np.random.default_rng(2)
    for k in range(50):
        c = int(np.rint(rng.normal(0.0, s)))
        w = np.rint(rng.normal(0.0, s, 3)).astype(np.int64)
        assert central[k] == 10 + c
        np.testing.assert_array_equal(wheel[k], np.array([3, -8, 100]) + w)
    assert np.any(central != 10) and np.any(wheel[:, 0] != wheel[0, 0])
    from toolkit.model.sensors import SensorReader

    _, noisy = SensorReader(suite, start, np.random.default_rng(2)).read(float(X[0]), x[0])
    assert noisy.dtype == np.int64


# -- record_simulation: jitter, starts on the grid, the horizon, and what it records ------------
def test_jitter_moves_the_reads_by_the_documented_draws_not_the_stamps():
    """With jitter the encoders are read at ``t_k + d_k``, ``d_k`` normal of std ``jitter``
    truncated at a quarter period and the reads kept within ``[0, t_end]``, while the record
    stamps ``t_k``; the truth is at the stamps. The draws are the generator's first ``k``
    normals (no other draws for noiseless counts): from the same seed, every count is the
    closed form of the startup run (X = t^2 to 0.5 s, then 0.25 + (t - 0.5); contacts at 1
    m/s, the motor side b/2 behind) at the read instants. At 8192 Hz with the largest jitter
    (1/16 period, 2^-17 s: the quarter period is 4 standard deviations), seed 42 draws offsets
    beyond the quarter period on both sides and positive offsets at the first and the last
    stamp (asserted), so the truncation, the clip to the horizon and the start of the
    integral all show."""
    rate = 8192.0
    plant = _startup_plant()
    result = simulate(plant, 1.0)
    sensors = Sensors(Encoder(8192, 0.266, rate=rate), Encoder(3591.84, 0.045, rate=rate, backlash=0.0008), 10,
                      jitter=2.0 ** -17)
    q, qw, b = sensors.central.distance_per_count, sensors.wheel.distance_per_count, sensors.backlash
    stamps = np.arange(8193) / rate
    d = np.random.default_rng(42).normal(0.0, 2.0 ** -17, stamps.size)
    quarter = 0.25 / rate
    assert d.max() > quarter and d.min() < -quarter and d[0] > 0 and d[-1] > 0
    reads = np.clip(stamps + np.clip(d, -quarter, quarter), 0.0, 1.0)
    x0, c0 = 0.25 * q, np.linspace(0.5, 5.0, 10) * qw
    # Wheels 0 and 1 start so that a count edge lies midway between the truncated and the
    # untruncated read of the largest and of the most negative offset (0.4 um from each,
    # far above rounding): the truncation shows in their counts.
    for i, k in enumerate((int(np.argmax(d)), int(np.argmin(d)))):
        mid = stamps[k] + 0.5 * (np.clip(d[k], -quarter, quarter) + d[k]) - b / 2
        c0[i] = (np.ceil(mid / qw) + 3) * qw - mid
    record = record_simulation(result, plant, sensors, rng=np.random.default_rng(42), central_position=x0,
                               contact_positions=c0)
    np.testing.assert_array_equal(record.times, stamps)
    X = np.where(reads < 0.5, reads ** 2, 0.25 + (reads - 0.5))
    # Gauss-Legendre is exact on the pieces (lines and parabolas): rounding only; the floors
    # agree exactly unless a read lies within 1e-12 m of a count edge (x = 0 at t = 0 is
    # exact), which this would reveal.
    for pos, step in ((x0 + X, q), (c0 + reads[:, None] - b / 2, qw)):
        assert np.min(np.abs(pos / step - np.rint(pos / step))) * step > 1e-12
    np.testing.assert_array_equal(record.central_counts, np.floor((x0 + X) / q))
    np.testing.assert_array_equal(record.wheel_counts, np.floor((c0 + reads[:, None] - b / 2) / qw))
    T = np.where(stamps < 0.5, stamps ** 2, 0.25 + (stamps - 0.5))
    np.testing.assert_allclose(record.truth_position, x0 + T, rtol=0, atol=1e-13)
    np.testing.assert_allclose(record.truth_speed, np.minimum(2 * stamps, 1.0), rtol=0, atol=1e-14)


def test_every_transition_missed_keeps_the_counts_where_the_grids_start():
    """p = 1: no transition is ever seen, so each channel reports for good the count of its
    start on its grid: floor(x0 / q) for the body, floor((c0_i - b/2) / q_w) for each wheel
    (the motor side loaded b/2 behind), with unequal starts."""
    plant = _startup_plant()
    result = simulate(plant, 1.0)
    sensors = CAROUSEL.sensors(missed_count_prob=1.0)
    q, qw, b = sensors.central.distance_per_count, sensors.wheel.distance_per_count, sensors.backlash
    x0, c0 = 7.5 * q, np.arange(1, 11) * 3.25 * qw
    record = record_simulation(result, plant, sensors, rng=np.random.default_rng(0), central_position=x0,
                               contact_positions=c0)
    assert np.all(record.central_counts == 7)
    np.testing.assert_array_equal(record.wheel_counts, np.tile(np.floor((c0 - b / 2) / qw), (51, 1)))


def test_record_keeps_the_commands_the_play_and_the_first_command():
    """The commands at each stamp (a switch at 0.3 s from 0.1 to -0.2 m/s, exact), the wheels'
    play, the first command as the motors' settled one; without truth, none is kept."""
    plant = Plant(ContactSet([0.1, 0.1, 0.1]), 5.0, motors=Motors(lag=0.0075),
                  commands=PiecewiseConstant([0.3], [[0.1, 0.2, 0.3], [-0.2, -0.1, 0.0]]))
    result = simulate(plant, 1.0)
    sensors = CAROUSEL.sensors(3)
    record = record_simulation(result, plant, sensors, truth=False)
    t = record.times
    np.testing.assert_array_equal(record.commands, np.where(t[:, None] < 0.3, [0.1, 0.2, 0.3], [-0.2, -0.1, 0.0]))
    np.testing.assert_array_equal(record.initial_commands, [0.1, 0.2, 0.3])
    assert record.wheel_backlash == sensors.backlash > 0
    assert record.truth_speed is None and record.truth_position is None and record.truth_contact_speeds is None
    np.testing.assert_array_equal(record.force, np.zeros(t.size))


def test_record_simulation_reads_the_dense_outputs_horizon():
    """Default horizon: the dense output's ``t_end`` (which a stopped run keeps past its
    ``t_final``), else ``t_final``; a result without a dense output, or without ``speed_at``,
    is refused. Stand-in results (a body at rest) isolate the rule."""
    from types import SimpleNamespace

    plant = Plant(ContactSet([0.0, 0.0]), 1.0)
    sensors = CAROUSEL.sensors(2)

    def rest(dense):
        return SimpleNamespace(dense=dense, t_final=0.25, t=np.array([0.0, 0.25]), events=[],
                               speed_at=lambda t: np.zeros(np.shape(t)))

    np.testing.assert_array_equal(record_simulation(rest(SimpleNamespace(t_end=0.5)), plant, sensors).times,
                                  np.arange(26) / 50.0)
    np.testing.assert_array_equal(record_simulation(rest(SimpleNamespace()), plant, sensors).times,
                                  np.arange(13) / 50.0)
    for bad in (rest(None), SimpleNamespace(dense=SimpleNamespace(t_end=0.5), t_final=0.25)):
        with pytest.raises(ParameterTypeError, match="'result' parameter of record_simulation must be an exact"):
            record_simulation(bad, plant, sensors)


def test_record_simulation_names_each_start_argument_in_full():
    plant, result, sensors = _two_contacts()
    for kwargs, error, message in (
            ({"central_position": "a"}, ParameterTypeError,
             "'central_position' parameter of record_simulation must be a real number. Got 'a' instead."),
            ({"contact_positions": [0.0, np.inf]}, ParameterError,
             "'contact_positions' parameter of record_simulation must be finite (no NaN or inf). Got inf instead."),
            ({"sensors": CAROUSEL.sensors(2, jitter=1e-3), "rng": 5}, ParameterTypeError,
             "'rng' parameter of record_simulation must be a numpy.random.Generator when the sensors jitter. "
             "Got 5 instead.")):
        args = {"sensors": sensors, **kwargs}
        with pytest.raises(error, match=_whole(message)):
            record_simulation(result, plant, args.pop("sensors"), **args)


def test_contact_speed_kinks_are_the_ramp_ends_within_the_horizon():
    """Rate-limited motors (4 m/s^2, no lag): each command step is a ramp of |gap| / 4 s. Steps
    at 0.25 s (0.1 -> 0.5 and -0.1 -> -0.3: ramps of 0.1 and 0.05 s) and 0.5 s (to 0: 0.125
    and 0.075 s): kinks at the switches and the ramp ends, exactly, up to the last time asked
    for (a ramp cut by the next switch or by the horizon leaves none); the speeds on the
    ramps are the closed form v0 + r s (dyadic: exact to a rounding of the offsets)."""
    from toolkit.model.sensors import contact_speeds_at

    commands = PiecewiseConstant([0.25, 0.5], [[0.1, -0.1], [0.5, -0.3], [0.0, 0.0]])
    plant = Plant(ContactSet([0.1, -0.1]), 1.0, motors=Motors(rate_limit=4.0), commands=commands)
    speeds, kinks = contact_speeds_at(plant, np.array([0.0, 0.3, 0.375, 0.625, 0.75]))
    np.testing.assert_allclose(kinks, [0.25, 0.3, 0.35, 0.5, 0.575, 0.625], rtol=0, atol=1e-15)
    np.testing.assert_allclose(speeds, [[0.1, -0.1], [0.3, -0.3], [0.5, -0.3], [0.0, 0.0], [0.0, 0.0]],
                               rtol=0, atol=1e-15)
    _, early = contact_speeds_at(plant, np.array([0.0, 0.3]))
    np.testing.assert_allclose(early, [0.25, 0.5], rtol=0, atol=1e-15)        # the switches only
    _, cut = contact_speeds_at(plant, np.array([0.33]))
    np.testing.assert_allclose(cut, [0.25, 0.3, 0.5], rtol=0, atol=1e-15)
    # Ideal motors without limits: the commands themselves (no motors to clip them).
    free = Plant(ContactSet([0.1, -0.1]), 1.0, commands=commands)
    np.testing.assert_array_equal(contact_speeds_at(free, [0.3, 0.6])[0], [[0.5, -0.3], [0.0, 0.0]])


def test_play_of_whole_positions_keeps_the_half_widths():
    # Integer positions 0, 1, 3 through a play of 1 (from 0): 0, then dragged to 1 - 1/2 and
    # 3 - 1/2; the output is float whatever the input's type (exact halves).
    np.testing.assert_array_equal(play([[0], [1], [3]], 1.0, [0.0])[:, 0], [0.0, 0.5, 2.5])
    np.testing.assert_array_equal(play([[0], [1], [3]], 1, [0])[:, 0], [0.0, 0.5, 2.5])
    from toolkit.model.sensors import SensorReader, SensorState

    suite = _suite()
    reader = SensorReader(suite, SensorState(motor=[0, 1, 2], central_count=0, wheel_count=[0, 0, 0],
                                             central_offset=0, wheel_offset=[0, 0, 0]))
    assert reader.state.motor.dtype == np.float64


def test_contact_speeds_of_no_times_and_of_ramps_cut_by_the_horizon():
    from toolkit.model.sensors import contact_speeds_at

    commands = PiecewiseConstant([0.25], [[0.1, -0.1], [0.5, -0.3]])
    plant = Plant(ContactSet([0.1, -0.1]), 1.0, motors=Motors(rate_limit=4.0), commands=commands)
    speeds, kinks = contact_speeds_at(plant, np.array([]))
    assert speeds.shape == (0, 2)
    np.testing.assert_array_equal(kinks, [0.25])


def test_record_contact_positions_match_the_motor_ramp_closed_form():
    """Rate-limited motors (4 m/s^2, no lag), a command step 0.1 -> -0.2 m/s at 0.31 s (between
    stamps): each contact ramps for 0.075 s, to 0.385 s (between stamps too), then holds.
    x(t) = 0.1 t to 0.31 s, then 0.031 + 0.1 s - 2 s^2 on the ramp (s = t - 0.31), then
    0.031 + 0.1 r - 2 r^2 - 0.2 (s - r) (r = 0.075). Gauss-Legendre is exact on each piece
    between the kinks it is given (switch and ramp end); a kink left out costs about 1e-4 m,
    more than a count (79 um)."""
    u, v0, r, rate = -0.2, 0.1, 0.075, 4.0
    # The first wheel starts 1e-9 m above a count edge at 0.4 s, the first stamp after the
    # ramp's end: a ramp end missing from the kinks (8-node Gauss across it errs by -1.8e-6 m
    # over [0.38, 0.4]) shows in its counts.
    q = Encoder(3591.84, 0.045).distance_per_count
    at = 0.031 + v0 * r - 0.5 * rate * r ** 2 + u * (0.09 - r)
    c0 = np.array([(np.ceil(at / q) + 1) * q - at + 1e-9, 0.0, 0.0])
    record, q = _stepped_record(Motors(rate_limit=rate), 0.31, c0)
    t = record.times
    s = np.maximum(t - 0.31, 0.0)
    ramp = np.minimum(s, r)
    x = c0 + np.where(t < 0.31, v0 * t, 0.031 + v0 * ramp - 0.5 * rate * ramp ** 2 + u * (s - ramp))[:, None]
    assert np.min(np.abs(x[1:] / q - np.rint(x[1:] / q))) * q > 1e-12
    np.testing.assert_array_equal(record.wheel_counts, np.floor(x / q))
