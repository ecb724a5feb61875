"""Encoder resolutions against the paper's hardware table (PHYSICS.md section 3)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from toolkit import ParameterError
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
