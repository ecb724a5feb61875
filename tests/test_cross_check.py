"""The independent cross-check of the closed loop: the smoothed python-control plant converges
to the exact loop linearly in the friction width, on plants of unequal forces and two mass
scales; bad input is refused by name."""

from __future__ import annotations

import numpy as np
import pytest

import toolkit as tk
from toolkit.controllers import SpeedHold, VirtualViscosity
from toolkit.errors import ParameterError
from toolkit.loop.cross_check import ORDER_BAND, cross_check, smoothed_plant
from toolkit.simulation import Budget, SimulationStatus

pytest.importorskip("control")

WIDTHS = (1e-2, 1e-3, 1e-4)
FORCES = np.array([0.3, 1.1, 0.7, 2.1, 0.5, 1.6, 0.9, 1.3])       # N, unequal


def _plant(mass: float, damping: float) -> tk.Plant:
    """Eight contacts of unequal magnitudes (0.3 .. 2.1 N, F_tot = 8.5 N), motor lag 7.5 ms,
    speed limits 0.35 m/s."""
    return tk.Plant(tk.ContactSet(np.zeros(8), FORCES), mass=mass, damping=damping,
                    motors=tk.Motors(lag=0.0075, speed_limits=(-0.35, 0.35)))


@pytest.mark.slow
@pytest.mark.parametrize("mass", [1.0, 20.0])            # F_tot / m = 8.5 and 0.425 m/s^2
def test_difference_shrinks_linearly_with_the_width(mass):
    plant = _plant(mass, damping=2.0)
    slope = 2.0 * float(FORCES.sum()) / 0.5                 # staircase over +-0.25 m/s
    check = cross_check(plant, SpeedHold(0.12, slope), 2.0, widths=(1e-3, 1e-4, 1e-5), v0=0.02)
    assert check.status is SimulationStatus.SUCCESS, check.message
    d = check.differences
    # No difference is exactly 0 (two different models), and they shrink with the width.
    assert np.all(d > 0) and np.all(np.diff(d) < 0), d
    # The smoothed model converges linearly in w: each observed order and the fitted one lie
    # in ORDER_BAND around 1 (approached from below as w shrinks).
    assert np.all((check.orders >= ORDER_BAND[0]) & (check.orders <= ORDER_BAND[1])), check.orders
    assert ORDER_BAND[0] <= check.order <= ORDER_BAND[1] and check.converges
    # At w = 1e-5 m/s the loops agree to within 1 % of the reference speed.
    assert d[-1] < 0.01 * 0.12


def test_viscous_staircase_creeps_in_the_band_at_first_order():
    # No feedback, no drag: the exact body sticks at the band's edge, the smoothed one creeps
    # into the band at a speed proportional to w (the law's slope f / w inside it).
    plant = _plant(5.0, damping=0.0)
    check = cross_check(plant, VirtualViscosity(20.0, 0.1), 1.0, widths=WIDTHS)
    assert np.all(check.differences > 0) and np.all(np.diff(check.differences) < 0)
    assert ORDER_BAND[0] <= check.order <= ORDER_BAND[1]


def test_smoothed_plant_is_the_stated_law():
    plant = _plant(5.0, damping=1.0)
    system = smoothed_plant(plant, 1e-3)
    x = np.concatenate(([0.05], np.linspace(-0.1, 0.2, 8)))
    u = np.concatenate((np.full(8, 0.5), [0.3]))     # commands beyond the limit: clipped to 0.35
    f = plant.contacts.forces
    dV = (np.sum(f * np.tanh((x[1:] - 0.05) / 1e-3)) + 0.3 - 1.0 * 0.05) / 5.0
    expected = np.concatenate(([dV], (0.35 - x[1:]) / 0.0075))
    # The same expression evaluated twice: equal to rounding (a few ulps of the largest term).
    np.testing.assert_allclose(system.updfcn(0.0, x, u, {}), expected, rtol=1e-14, atol=0)
    assert system.ninputs == 9 and system.nstates == 9 and system.noutputs == 1


def test_budget_stops_the_smoothed_integrations():
    check = cross_check(_plant(5.0, 0.0), VirtualViscosity(20.0, 0.1), 1.0, widths=WIDTHS,
                        budget=Budget(max_steps=200))
    assert check.status is SimulationStatus.MAX_STEPS and not check.converges
    assert check.differences.size < len(WIDTHS)


def test_bad_input_is_refused_by_name():
    plant = _plant(5.0, 0.0)
    with pytest.raises(ParameterError, match="'widths'.*decreasing"):
        cross_check(plant, VirtualViscosity(20.0, 0.1), 1.0, widths=[1e-4, 1e-2])
    with pytest.raises(ParameterError, match="'width'"):
        smoothed_plant(plant, 0.0)
    limited = tk.Plant(plant.contacts, mass=5.0, motors=tk.Motors(lag=0.01, rate_limit=2.0))
    with pytest.raises(ParameterError, match="'plant'.*rate limit"):
        cross_check(limited, VirtualViscosity(20.0, 0.1), 1.0)
