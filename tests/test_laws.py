"""The formulas of :mod:`toolkit.laws`: values at their defining points, exact where
the arithmetic is exact (powers of two), and one method against another elsewhere."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from toolkit.laws import EPS, cell_centre, lag_response, quantization_variance, tie_tolerance

#: Force and mass scales of every law test: a power of two scales the floating-point
#: arithmetic exactly, so identities hold to the bit at each scale.
SCALES = [2.0 ** -20, 1.0, 2.0 ** 20]


def test_eps_is_the_double_precision_unit():
    """EPS is the spacing of doubles at 1, 2**-52 (mutant: any other constant)."""
    assert EPS == 2.0 ** -52
    assert 1.0 + EPS != 1.0 and 1.0 + EPS / 2 == 1.0


@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize("levels", [0, 1, 3, 7])
def test_tie_tolerance_is_exact_at_every_scale(levels, scale):
    """``4 (K + 1) eps F_tot`` to the bit: K + 1 a small integer and F_tot a power of two make
    every product exact (mutants: the factor 4, the ``+ 1``, ``*`` for ``/``, the total dropped)."""
    expected = math.ldexp(4 * (levels + 1), -52) * scale
    assert tie_tolerance(levels, scale) == expected
    assert tie_tolerance(levels, 3.0 * scale) == 3.0 * expected


def test_tie_tolerance_acts_per_element():
    """On arrays of totals the tolerance scales each element with its own total."""
    totals = np.array([2.0 ** -20, 1.0, 2.0 ** 20])
    np.testing.assert_array_equal(tie_tolerance(2, totals), 12.0 * EPS * totals)


@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize("count", [-3, -1, 0, 1, 1000])
def test_cell_centre_lies_in_its_cell_midway(count, scale):
    """The centre of cell ``c`` is ``(c + 1/2) q``: equidistant from the cell's edges ``c q``
    and ``(c + 1) q`` and inside the cell (exact for a power-of-two ``q``; mutants: ``+ 0.5`` to
    ``- 0.5`` or ``+ 1.5``, ``*`` for ``/``)."""
    q = 0.75 * scale
    centre = cell_centre(count, q)
    assert centre - count * q == (count + 1) * q - centre
    assert math.floor(centre / q) == count
    assert centre == (count + 0.5) * q


@pytest.mark.parametrize("scale", SCALES)
def test_quantization_variance_against_midpoint_cells(scale):
    """``q^2 / 12`` against a second method: the variance of ``N`` equally spaced midpoints
    of one cell is ``q^2 / 12 (1 - 1/N^2)``; with ``N = 1000`` the sums round to about
    ``N eps``, so rtol 1e-12 (mutants: 12 to 13 or 11, ``q * q`` to ``q + q`` or ``q / q``)."""
    q = 0.3 * scale
    n = 1000
    points = (np.arange(n) + 0.5) * q / n
    second = np.var(points) * n * n / (n * n - 1)
    np.testing.assert_allclose(quantization_variance(q), second, rtol=1e-12, atol=0.0)


@pytest.mark.parametrize("scale", SCALES)
def test_lag_response_at_its_defining_points(scale):
    """At the step the speed is the start, one time constant later it has gone ``1 - 1/e`` of
    the way, long after it is the command (dyadic speeds: exact at the step; mutants: the sign
    of the exponent, ``/ lag`` to ``* lag``, start and command swapped)."""
    u, v0, tau = 1.5 * scale, -0.25 * scale, 0.125
    assert lag_response(u, v0, 0.0, tau) == v0
    np.testing.assert_allclose(lag_response(u, v0, tau, tau), u + (v0 - u) / math.e, rtol=4 * EPS, atol=0.0)
    assert lag_response(u, v0, 800 * tau, tau) == u


@pytest.mark.parametrize("tau", [2.0 ** -6, 0.3, 4.0])
def test_lag_response_solves_the_first_order_lag(tau):
    """Against a second method: ``v' = (u - v) / tau`` integrated by scipy's DOP853 at
    rtol 1e-12; its global error stays below 1e-10 of the speeds here."""
    u, v0 = 0.7, -0.2
    times = np.linspace(0.0, 3.0 * tau, 13)
    ode = solve_ivp(lambda t, v: (u - v) / tau, (0.0, times[-1]), [v0], method="DOP853",
                    t_eval=times, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(lag_response(u, v0, times, tau), ode.y[0], rtol=1e-10, atol=1e-12)
