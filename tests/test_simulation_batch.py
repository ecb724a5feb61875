"""Tests of the batch path: every scene equals the single-run exact method."""

from __future__ import annotations

import json

import numpy as np
import pytest

from toolkit.model import ContactSet
from toolkit.errors import ParameterError
from toolkit.model import Plant
from toolkit.simulation import SimulationStatus, simulate, simulate_batch

RTOL = 1e-12      # the target: each scene equal to the single-run result to 1e-12


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(314159)


def _single(speeds, forces, mass, t_end, v0=0.0, damping=0.0):
    return simulate(Plant(ContactSet(speeds, forces), mass, damping=damping), t_end, v0=v0)


def test_random_startups_equal_single_runs(rng):
    scenes, n = 10_000, 10
    speeds = rng.uniform(-0.35, 0.35, (scenes, n))
    forces = rng.uniform(0.05, 0.15, (scenes, n))
    batch = simulate_batch(speeds, forces, 0.5, 5.0)     # (its speed: python -m toolkit.bench batch)
    assert batch.success and batch.final_speeds.shape == (scenes,)
    for s in rng.choice(scenes, 60, replace=False):
        single = _single(speeds[s], forces[s], 0.5, 5.0)
        assert batch.final_speeds[s] == pytest.approx(single.V[-1], rel=RTOL, abs=1e-300)
        assert batch.n_events[s] == single.n_events
        assert batch.stuck[s] == (single.events[-1].kind == "stick" if single.events else False)


def test_drag_initial_speeds_ties_and_lifted_contacts(rng):
    scenes, n = 400, 7
    speeds = rng.uniform(-0.35, 0.35, (scenes, n))
    speeds[:, 3] = speeds[:, 2]                         # coincident speeds
    forces = rng.uniform(0.5, 1.5, (scenes, n))
    forces[:, 0] = 0.0                                   # a lifted contact
    mass = rng.uniform(0.1, 2.0, scenes)
    damping = rng.uniform(0.0, 3.0, scenes)
    v0 = rng.uniform(-1.0, 1.0, scenes)
    batch = simulate_batch(speeds, forces, mass, 2.0, v0=v0, damping=damping)
    for s in range(0, scenes, 5):
        single = _single(speeds[s], forces[s], mass[s], 2.0, v0[s], damping[s])
        # With drag the final speed is a closed-form exponential: rounding only.
        assert batch.final_speeds[s] == pytest.approx(single.V[-1], rel=RTOL, abs=1e-15)
        assert batch.n_events[s] == single.n_events


def test_even_sets_stop_at_the_first_band_edge():
    speeds = np.array([[0.1, 0.2, 0.3, 0.4], [-0.4, -0.3, -0.2, -0.1]])
    batch = simulate_batch(speeds, None, 1.0, 10.0, v0=[0.0, 0.0])
    # From rest: below the first band [0.2, 0.3] -> 0.2; above the second [-0.3, -0.2] -> -0.2.
    np.testing.assert_array_equal(batch.final_speeds, [0.2, -0.2])
    assert batch.stuck.all() and batch.status is SimulationStatus.SUCCESS


def test_docstring_example():
    result = simulate_batch([[-1.0, 0.5, 2.0], [0.0, 1.0, 3.0]], None, 1.0, 5.0)
    assert result.final_speeds.tolist() == [0.5, 1.0] and result.n_scenes == 2


@pytest.mark.parametrize("kwargs", [
    {"speeds": [0.0, 1.0]},                                   # not 2-D
    {"forces": [[1.0, -1.0]]},                                # negative
    {"forces": [[0.0, 0.0]]},                                 # no contact touches
    {"forces": [[1.0, 1.0, 1.0]]},                            # shape mismatch
    {"mass": 0.0},
    {"mass": [1.0, 2.0]},                                     # wrong length
    {"damping": -1.0},
    {"t_end": 0.0},
])
def test_refuses_bad_input(kwargs):
    args = {"speeds": [[0.0, 1.0]], "forces": [[1.0, 1.0]], "mass": 1.0, "t_end": 1.0}
    args.update(kwargs)
    with pytest.raises(ParameterError):
        simulate_batch(args.pop("speeds"), args.pop("forces"), args.pop("mass"),
                       args.pop("t_end"), **args)


def test_result_is_read_only():
    result = simulate_batch([[0.0, 1.0, 2.0]], None, 1.0, 1.0)
    with pytest.raises(ValueError):
        result.final_speeds[0] = 3.0


def test_to_dict_is_json_able():
    result = simulate_batch([[-1.0, 0.5, 2.0]], None, 1.0, 5.0)
    summary = json.loads(json.dumps(result.to_dict()))
    assert summary["final_speeds"] == [0.5] and summary["n_events"] == [1]
    assert summary["stuck"] == [True] and summary["status"] == "SUCCESS"
