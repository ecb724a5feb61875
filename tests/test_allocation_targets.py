"""Tests of the allocation targets (toolkit/allocation/targets.py)."""

from __future__ import annotations

import numpy as np
import pytest

from toolkit.allocation.targets import (
    EquilibriumSpeed,
    ForceCurve,
    FrictionFraction,
    Viscosity,
    parse_band,
)
from toolkit.errors import ParameterError, ParameterTypeError


def test_force_curve_band_and_read_only() -> None:
    curve = ForceCurve([-0.2, 0.0, 0.3], [2.0, 1.0, -1.0])
    assert curve.band == (-0.2, 0.3)
    with pytest.raises(ValueError):
        curve.speeds[0] = 1.0


def test_force_curve_one_sided_values_at_a_vertical_step() -> None:
    # A repeated speed is a vertical step: left limit = first sample, right limit = second.
    curve = ForceCurve([0.0, 0.1, 0.1, 0.2], [4.0, 4.0, -4.0, -4.0])
    assert float(curve.value_left(0.1)) == 4.0
    assert float(curve.value_right(0.1)) == -4.0
    # Linear in between: exact interpolation (rtol from one rounding of a*b+c).
    line = ForceCurve([0.0, 1.0], [3.0, -1.0])
    np.testing.assert_allclose(line.value_left([0.25, 0.5]), [2.0, 1.0], rtol=1e-15, atol=0)


def test_force_curve_restrict_keeps_values() -> None:
    curve = ForceCurve([-1.0, 0.0, 1.0], [2.0, 0.0, -4.0])
    cut = curve.restrict(-0.5, 0.5)
    np.testing.assert_allclose(cut.speeds, [-0.5, 0.0, 0.5], rtol=0, atol=0)
    np.testing.assert_allclose(cut.forces, [1.0, 0.0, -2.0], rtol=1e-15, atol=1e-15)


@pytest.mark.parametrize("speeds, forces, weights, error, word", [
    ([0.1, 0.0], [1.0, 0.0], None, ParameterError, "non-decreasing"),
    ([0.0, 0.1], [1.0], None, ParameterError, "same length"),
    ([0.0, np.nan], [1.0, 0.0], None, ParameterError, "finite"),
    ([0.0, 0.1], [1.0, 0.0], [1.0], ParameterError, "same length"),
    ([0.0, 0.1], [1.0, 0.0], [1.0, -1.0], ParameterError, ">= 0"),
    ("abc", [1.0], None, ParameterTypeError, "array of numbers"),
])
def test_force_curve_refusals(speeds, forces, weights, error, word) -> None:
    with pytest.raises(error, match=word) as info:
        ForceCurve(speeds, forces, weights)
    assert "parameter of ForceCurve" in str(info.value)


def test_force_curve_accepts_non_finite_forces_as_a_request() -> None:
    # Unrealizable requests are built; allocate() projects or refuses them.
    curve = ForceCurve([0.0, 1.0], [np.inf, np.nan])
    assert np.isinf(curve.forces[0]) and np.isnan(curve.forces[1])


def test_viscosity_curve_is_the_linear_law() -> None:
    target = Viscosity(slope=20.0, center=0.05, band=0.3)
    assert target.band == pytest.approx((-0.25, 0.35), rel=0, abs=1e-15)
    curve = target.to_curve(total_force=10.0)
    # F = -slope (V - center) at the band ends (exact arithmetic up to one rounding).
    np.testing.assert_allclose(curve.forces, [6.0, -6.0], rtol=1e-14, atol=0)
    assert Viscosity(1.0, 0.0, (-0.1, 0.2)).band == (-0.1, 0.2)


def test_friction_fraction_curve_is_constant() -> None:
    curve = FrictionFraction(0.4, 0.35).to_curve(total_force=10.0)
    np.testing.assert_array_equal(curve.speeds, [-0.35, 0.35])
    np.testing.assert_allclose(curve.forces, [-4.0, -4.0], rtol=1e-15, atol=0)


def test_equilibrium_speed_curve_is_a_coulomb_step() -> None:
    curve = EquilibriumSpeed(0.1, margin=2).to_curve(10.0, (-0.35, 0.35))
    np.testing.assert_array_equal(curve.speeds, [-0.35, 0.1, 0.1, 0.35])
    np.testing.assert_array_equal(curve.forces, [10.0, 10.0, -10.0, -10.0])
    at_edge = EquilibriumSpeed(-0.35).to_curve(10.0, (-0.35, 0.35))
    np.testing.assert_array_equal(at_edge.speeds, [-0.35, -0.35, 0.35])


@pytest.mark.parametrize("build, error, word", [
    (lambda: Viscosity(-1.0, 0.0, 0.3), ParameterError, "slope"),
    (lambda: Viscosity(1.0, np.nan, 0.3), ParameterError, "center"),
    (lambda: Viscosity(1.0, 0.0, -0.3), ParameterError, "band"),
    (lambda: Viscosity(1.0, 0.0, (0.3, -0.3)), ParameterError, "lo < hi"),
    # Zero-width bands: a law at a single speed is met by a Coulomb step with error 0.
    (lambda: Viscosity(10.0, 0.0, 0.0), ParameterError, "band"),
    (lambda: Viscosity(10.0, 0.0, (0.1, 0.1)), ParameterError, "lo < hi"),
    (lambda: FrictionFraction(0.4, 0.0), ParameterError, "band"),
    (lambda: FrictionFraction(0.4, (0.2, 0.2)), ParameterError, "lo < hi"),
    (lambda: Viscosity(1.0, 0.0, (0.1, 0.2, 0.3)), ParameterError, "pair"),
    (lambda: FrictionFraction("half", 0.3), ParameterTypeError, "fraction"),
    (lambda: FrictionFraction(0.5, "wide"), ParameterTypeError, "band"),
    (lambda: EquilibriumSpeed(0.0, margin=-1), ParameterError, "margin"),
    (lambda: EquilibriumSpeed(0.0, margin=1.5), ParameterTypeError, "margin"),
    (lambda: EquilibriumSpeed(np.inf), ParameterError, "speed"),
])
def test_target_refusals_name_parameter_rule_and_value(build, error, word) -> None:
    with pytest.raises(error, match=word) as info:
        build()
    assert "Got" in str(info.value) and "must" in str(info.value)


def test_parse_band_forms() -> None:
    assert parse_band(0.2, "band", "X", center=0.1) == pytest.approx((-0.1, 0.3), abs=1e-15)
    assert parse_band((0.0, 0.5), "band", "X") == (0.0, 0.5)
