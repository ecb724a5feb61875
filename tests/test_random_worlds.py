"""Worlds drawn at random (toolkit.analysis.robustness): the draws within their ranges, each
world a scene that gives the same numbers, the truth never reaching the estimator, the
default told the truth, and the NEES shares that expose gross overconfidence."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from toolkit.analysis.robustness import (DEPARTURES, WORLD_LINES, WORLD_METHODS, WORLD_RANGES, draw_world,
                                         robustness_estimators, score_world, world_scenario)
from toolkit.analysis.scenarios import carousel_brake_scenario
from toolkit.estimation import KalmanEstimator, TRUTH_TOLD, truth_told
from toolkit.estimation._base import GROSS_NEES, score
from toolkit.model.sensors import EncoderRecord
from toolkit.scenes.build import build_scene
from toolkit.scenes.worlds import world_scene
from toolkit.scenes.spec import dumps_scene, loads_scene
from toolkit.scenes.study import estimate_scene


def _within(value: float, key: str) -> bool:
    low, high = WORLD_RANGES[key]
    return low <= value <= high


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), index=st.integers(0, 10**6))
def test_every_draw_lies_within_its_stated_range(seed, index):
    world = draw_world(seed, index)
    assert _within(world.n, "contacts") and all(f > 0 for f in world.forces)
    for key in ("mass", "rate", "wheel_scale", "central_scale"):
        assert _within(getattr(world, key), key), key
    assert _within(world.lag, "told_lag")
    assert world.v0 == 0.0 or _within(world.v0, "v0")
    assert _within(len(world.times), "steps") and len(world.commands) == len(world.times) + 1
    # Steps over 0.5 s .. 1.5 s before the end; one may follow another by under a period.
    assert all(np.diff(world.times) > 0) and 0.5 <= world.times[0]
    assert world.times[-1] <= world.duration - 1.5 + 1.0 / world.rate
    assert all(_within(v, "speed") for row in world.commands for v in row)
    truth = world.truth
    assert _within(truth.friction_spread, "friction_spread") and _within(truth.contact_drift, "contact_drift")
    assert _within(truth.read_noise, "read_noise") and _within(truth.missed_count_prob, "missed_count_prob")
    assert truth.drag is None or _within(truth.drag, "drag")
    assert truth.lag is None or _within(truth.lag, "lag")
    assert _within(truth.jitter * world.rate, "jitter_periods")
    truth.sensors(world.sensors())          # the true encoders accept the drawn jitter
    assert world == draw_world(seed, index)  # reproducible from (seed, index) alone


def test_the_draws_cover_their_ranges():
    # Over 200 worlds every departure is present in some and absent in others, both starts
    # occur, and so do steps closer than one period (transients the samples do not see); the
    # contacts' count spans most of 3-40. Fails if a branch of the draw is never taken.
    worlds = [draw_world(2026, i) for i in range(200)]
    names = {"friction_spread": "friction_spread", "drag": "drag", "lag": "lag", "contact_drift": "contact_drift",
             "read_noise": "read_noise", "missed_count_prob": "missed_count_prob", "jitter": "jitter"}
    for key in DEPARTURES:
        present = [getattr(w.truth, names[key]) not in (None, 0.0) for w in worlds]
        # Each present with probability 1/2: 200 draws give 100 +- 7; 60-140 holds but for 1e-8.
        assert 60 <= sum(present) <= 140, key
    assert 60 <= sum(w.v0 == 0.0 for w in worlds) <= 140
    assert any(min(np.diff(w.times), default=1.0) < 1.0 / w.rate for w in worlds)
    assert min(w.n for w in worlds) <= 5 and max(w.n for w in worlds) >= 38
    assert {len(w.times) for w in worlds} == {1, 2, 3, 4}


def test_a_world_is_a_scene_that_round_trips_and_builds_its_plant():
    world = draw_world(2026, 3)
    scene = world_scene(world)
    assert loads_scene(dumps_scene(scene)) == scene
    objects = build_scene(loads_scene(dumps_scene(scene)))
    plant = objects.estimation.plant
    np.testing.assert_array_equal(plant.contacts.forces, world.forces)
    np.testing.assert_array_equal(plant.commands.times, world.times)
    np.testing.assert_array_equal(plant.commands.values, world.commands)
    assert plant.mass == world.mass and plant.motors.lag == world.lag
    assert objects.estimation.sensors == world.sensors()
    assert tuple(objects.estimation.estimators) == WORLD_METHODS
    assert objects.estimation.truth == world.truth
    assert world.label in scene.description and world.truth.describe() in scene.description
    assert str(world) == scene.description and f"{world.n} contacts" in str(world)


def _small(count: int) -> list:
    """The first ``count`` worlds of seed 5 with at most 12 contacts at at most 60 Hz (cheap)."""
    out = []
    for index in range(200):
        world = draw_world(5, index)
        if world.n <= 12 and world.rate <= 60.0 and not world.truth.is_nominal:
            out.append(world)
        if len(out) == count:
            return out
    raise AssertionError("too few small worlds")


@pytest.mark.slow
@pytest.mark.parametrize("world", _small(2), ids=lambda w: w.label)
def test_the_same_world_through_its_scene_gives_the_same_numbers(world):
    # Second path: the scene file (estimate with [estimation.truth]) against the bench's
    # world_scenario and score_world; the same arithmetic, so equal to the bit (rtol 0).
    scored = score_world(world)
    study = estimate_scene(loads_scene(dumps_scene(world_scene(world))))
    rows = {row["name"]: row for row in study.rows()}
    assert list(rows) == [*WORLD_METHODS, TRUTH_TOLD]
    for name, score_row in scored.scores.items():
        row = rows[name]
        assert row["rms"] == score_row["rms"], name
        assert row["rms_phases"] == {p: score_row[p] for p in row["rms_phases"]}, name
        for key in ("nees_in_band", "nees_over_100", "nees_max"):
            assert row[key] == score_row[key], (name, key)
    np.testing.assert_array_equal(study.record.central_counts, world_scenario(world).record.central_counts)
    checks = scored.checks()
    assert set(checks) == set(WORLD_LINES)


class _Poison:
    """A truth field that refuses every use."""

    def __getattr__(self, name):
        raise AssertionError(f"the estimator read the truth ({name})")

    def __array__(self, *args, **kwargs):
        raise AssertionError("the estimator read the truth (as an array)")

    def __getitem__(self, key):
        raise AssertionError("the estimator read the truth (an item)")

    def __len__(self):
        raise AssertionError("the estimator read the truth (its length)")


@pytest.mark.slow
def test_the_estimator_never_reads_the_truth():
    # A world where the default leaves its nominal model (so its adaptive parts run): its
    # estimators are built with the true world and plant poisoned, and run sample by sample
    # over the record with every truth field a sentinel that raises on any use; the
    # estimates equal those of the clean record's run, bit for bit (rtol 0).
    world = _small(1)[0]
    sc = world_scenario(world)
    clean = robustness_estimators(sc)["kalman"].run(sc.record, speed=world.v0, speed_std=1e-4)
    blind = dataclasses.replace(sc, world=_Poison(), plant=_Poison(), result=_Poison())
    estimator = robustness_estimators(blind)["kalman"]
    record = sc.record
    poisoned = object.__new__(EncoderRecord)
    poisoned.__dict__.update(record.__dict__)
    for name in ("truth_speed", "truth_position", "truth_contact_speeds"):
        object.__setattr__(poisoned, name, _Poison())
    estimator.reset(speed=world.v0, speed_std=1e-4, contact_speeds=poisoned.initial_commands)
    out = np.array([estimator.step(poisoned.sample(k)) for k in range(poisoned.n_samples)])
    assert estimator.tripped is not None                 # the adaptive filter ran too
    np.testing.assert_array_equal(out[:, 0], clean.speed)
    np.testing.assert_array_equal(out[:, 1], clean.variance)


def test_truth_told_is_the_default_on_the_true_model():
    # The carousel's brake record in the nominal world: told the truth, the default's model
    # is the scene's, so its estimates are the default's, bit for bit (rtol 0).
    sc = carousel_brake_scenario(seed=0)
    told = truth_told(sc.world)
    assert told.name == TRUTH_TOLD
    a = told.run(sc.record, speed_std=1e-4)
    b = KalmanEstimator(sc.model).run(sc.record, speed_std=1e-4)
    np.testing.assert_array_equal(a.speed, b.speed)
    assert a.method == TRUTH_TOLD and b.method == "kalman"
    # In a world that departs, its model and prior are the truth's, not the scene's.
    from toolkit.model.truth import WorldTruth

    sc = carousel_brake_scenario(seed=1, truth=WorldTruth(friction_spread=0.3, drag=1.5, lag=0.02,
                                                          contact_drift=1e-3, missed_count_prob=1e-3))
    told = truth_told(sc.world)
    np.testing.assert_array_equal(told.model.forces, sc.world.plant.contacts.forces)
    assert (told.model.damping, told.model.motor_lag, told.model.contact_drift) == (1.5, 0.02, 1e-3)
    assert told.prior.friction_spread == 0.0 and told.prior.lag_range == (0.02, 0.02)
    assert told.prior.drag_range == (1.5, 1.5) and told.prior.missed_count_prob == 1e-3
    assert told.model.sensors.missed_count_prob == 1e-3


def test_truth_told_refuses_anything_but_a_true_world():
    from toolkit import ParameterTypeError

    with pytest.raises(ParameterTypeError, match="^The 'world' parameter of truth_told must be a TrueWorld"):
        truth_told(carousel_brake_scenario(seed=0).model)


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_nees_shares_and_largest_from_their_closed_form(scale):
    # Ten samples whose NEES is known in closed form: a diagonal covariance (scale^2 units)
    # and errors of (0, k scale) on sample k, so NEES_k = k^2 / 1 for the speed alone,
    # with the position exact. NEES 0..81: above 100 none; in the chi-square(2) band
    # [0.0506, 7.38] those with k^2 in it (k = 1, 2): 2 of 10; largest 81. Then the errors
    # grown by 20: NEES 400 k^2 > 100 for k >= 1 (9 of 10), largest 32400 (rtol 1e-12:
    # rounding of a 2x2 inverse).
    k = np.arange(10.0)
    times = 0.02 * k
    truth_v, truth_x = np.full(10, 0.1 * scale), 0.1 * scale * times
    counts = np.zeros(10, dtype=np.int64)
    record = EncoderRecord(times, counts, np.zeros((10, 1), dtype=np.int64), np.zeros((10, 1)), 1e-4, 1e-4,
                           truth_speed=truth_v, truth_position=truth_x)
    cov = np.tile(np.diag([scale**2, scale**2]), (10, 1, 1))
    for grow, over, band, largest in ((1.0, 0.0, 0.2, 81.0), (20.0, 0.9, 0.0, 32400.0)):
        speed = truth_v + grow * k * scale
        result = score(record, "test", speed, np.full(10, scale**2), 0.0, position=truth_x.copy(), covariance=cov)
        assert result.nees_over_100 == pytest.approx(over, rel=0, abs=1e-15)
        assert result.nees_in_band == pytest.approx(band, rel=0, abs=1e-15)
        assert result.nees_max == pytest.approx(largest, rel=1e-12, abs=0)
        assert result.to_dict()["nees_over_100"] == result.nees_over_100
    assert GROSS_NEES == 100.0
    assert math.exp(-GROSS_NEES / 2) < 1e-21        # chi-square(2) tail beyond 100: exp(-50)
