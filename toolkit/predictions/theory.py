"""What the ideal model predicts for the paper's viscosity and friction-fraction experiments.

The viscosity correction ``C = tau k / m`` of a finite staircase of equal contacts for each
definition of the time constant (:func:`startup_correction`, :func:`staircase_correction`
in closed form for the 63.2 % crossing, :func:`least_squares_correction` by fitting the exact
ideal trajectory, :func:`viscosity_correction` for any set), the exact travel time
(:func:`travel_time`) and the braking transition time (:func:`transition_time`). Numerics
only; the derivations: docs/methods.md and docs/physics.md section 6."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import as_float, as_float_array, check_option
from ..errors import ParameterError, parameter_message
from ..model import ContactSet, Plant
from ._measure import ONE_MINUS_INV_E, TIME_CONSTANTS, exponential_time_constant

__all__ = ["travel_time", "resting_speed", "time_constant", "viscosity_correction",
           "staircase_correction", "least_squares_correction", "startup_correction",
           "uniform_staircase", "transition_time", "ONE_MINUS_INV_E"]

#: Samples of the exact ideal trajectory a least-squares prediction is fitted to.
FIT_SAMPLES = 1001


def _check_contacts(contacts: Any, owner: str) -> ContactSet:
    if not isinstance(contacts, ContactSet):
        raise ParameterError(parameter_message("contacts", owner, "be a ContactSet", contacts))
    return contacts


def travel_time(contacts: ContactSet, mass: float, v_from: float, v_to: float) -> float:
    """Exact time for the ideal body (no drag, no outside force) to go from ``v_from`` to ``v_to``.

    ``T = sum over plateaus of m |dV| / |F|`` with ``F`` the staircase of ``contacts``.

    Parameters
    ----------
    contacts : ContactSet
    mass : float, kg
    v_from, v_to : float, m/s

    Returns
    -------
    float, s
        ``inf`` when the force on the way is zero or points the other way (the body stops
        first); 0 when ``v_from == v_to``.
    """
    owner = "travel_time"
    _check_contacts(contacts, owner)
    m = as_float(mass, "mass", owner, low=0.0, low_open=True)
    a = as_float(v_from, "v_from", owner)
    b = as_float(v_to, "v_to", owner)
    if a == b:
        return 0.0
    direction = 1.0 if b > a else -1.0
    levels = contacts.staircase().levels
    inside = levels[(levels > min(a, b)) & (levels < max(a, b))]
    edges = np.concatenate(([a], inside if direction > 0 else inside[::-1], [b]))
    middles = 0.5 * (edges[:-1] + edges[1:])
    push = direction * contacts.force(middles)            # force along the motion, N
    if np.any(push <= 0.0):
        return math.inf
    return float(np.sum(m * np.abs(np.diff(edges)) / push))


def resting_speed(contacts: ContactSet, v0: float) -> float:
    """Where the ideal body started at ``v0`` comes to rest: the nearest point of the
    equilibrium set (the weighted median; for a zero-force band its near edge), m/s."""
    lo, hi = _check_contacts(contacts, "resting_speed").equilibrium()
    return float(min(max(as_float(v0, "v0", "resting_speed"), lo), hi))


def time_constant(contacts: ContactSet, mass: float, v0: float) -> float:
    """The 63.2 % time of the ideal startup from ``v0``: exact travel time to
    ``v0 + (1 - 1/e) (V_stop - v0)``, s (``nan`` when ``v0`` is already at rest)."""
    stop = resting_speed(contacts, v0)
    if stop == v0:
        return math.nan
    return travel_time(contacts, mass, v0, v0 + ONE_MINUS_INV_E * (stop - v0))


def viscosity_correction(contacts: ContactSet, mass: float, v0: float, slope: float) -> float:
    """``C = tau_staircase * slope / mass``: the staircase's 63.2 % time over the linear law's.

    Parameters
    ----------
    contacts : ContactSet
        The staircase realizing the commanded viscosity.
    mass : float, kg
    v0 : float, m/s
        Start speed.
    slope : float, N s/m
        The commanded viscosity ``k = dF/dV`` (for ``n`` equal contacts with spacing ``s``,
        ``2 f / s``).

    Returns
    -------
    float
        1 for a perfectly viscous law; see the module docstring for its dependence on the
        number of contacts and on where the start lies.
    """
    k = as_float(slope, "slope", "viscosity_correction", low=0.0, low_open=True)
    return time_constant(contacts, mass, v0) * k / float(mass)


def staircase_correction(n: int, start: Any) -> Any:
    """Closed-form viscosity correction ``C(n, x0)`` of ``n`` equal, equally spaced contacts.

    See the module docstring for the derivation; equals :func:`viscosity_correction` on
    :func:`uniform_staircase` contacts (same ``n``, any spacing, magnitude and mass).

    Parameters
    ----------
    n : int
        Number of contacts, ``>= 1``.
    start : float or array_like
        Start speed measured from the reference (the staircase's centre) in spacings,
        ``x0 = (V0 - c) / s`` (dimensionless).

    Returns
    -------
    float or ndarray
        ``C``; ``nan`` where the body is already at rest (``x0 = 0`` for odd ``n``,
        ``|x0| <= 1/2`` for even ``n``).
    """
    owner = "staircase_correction"
    n = _check_n(n, owner)
    x0 = as_float_array(start, "start", owner)
    u0 = np.abs(x0)                                   # by symmetry: start below, move up
    stop = 0.0 if n % 2 else 0.5
    moving = u0 > stop
    u_star = u0 + ONE_MINUS_INV_E * (stop - u0)       # |x*|, between stop and u0
    # Mirror to a start below the reference: the path is [-u0, -u*]; contact p_j (j = 1..n)
    # at j - (n + 1)/2; plateau j spans [p_j, p_{j+1}] with force n - 2 j (j = 0..n).
    edges = np.concatenate(([-np.inf], np.arange(1, n + 1) - (n + 1) / 2.0, [np.inf]))
    push = np.abs(n - 2.0 * np.arange(n + 1))
    lo = np.maximum(edges[:-1][None, :], -u0[:, None])
    hi = np.minimum(edges[1:][None, :], -u_star[:, None])
    overlap = np.clip(hi - lo, 0.0, None)
    with np.errstate(divide="ignore", invalid="ignore"):
        # Plateaus of zero force are never crossed on the way to the stop (overlap 0).
        share = np.where(overlap > 0, overlap / np.where(push > 0, push, 1.0)[None, :], 0.0)
    out = np.where(moving, 2.0 * share.sum(axis=1), np.nan)
    return float(out[0]) if np.ndim(start) == 0 else out


def _check_n(n: Any, owner: str) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ParameterError(parameter_message("n", owner, "be an integer >= 1", n))
    return int(n)


def least_squares_correction(n: int, start: Any, window: Any) -> Any:
    """Correction ``C`` of the ``"least_squares"`` time constant of ``n`` equal, equally
    spaced contacts, from the exact ideal trajectory.

    In units where the spacing, the mass and the commanded slope are 1 (``x = (V - c) / s``,
    time in ``m / k``) the ideal startup depends on ``n`` and ``x0`` only. Each start's
    trajectory is simulated exactly (:func:`toolkit.simulate`) over ``[0, window]``, sampled
    at :data:`FIT_SAMPLES` equal steps, and fitted as a record is
    (:func:`~toolkit.predictions._measure.exponential_time_constant`, the settled speed the
    last sample): the fitted ``tau`` is ``C``.

    Parameters
    ----------
    n : int
        Number of contacts, ``>= 1``.
    start : float or array_like
        ``x0 = (V0 - c) / s`` (dimensionless).
    window : float or array_like
        The fit's window in units of ``m / k`` (``> 0``), broadcast against ``start``: a
        record of ``T`` seconds has ``window = T k / m``.

    Returns
    -------
    float or ndarray
        ``C``; ``nan`` where the body is already at rest.
    """
    from ..simulation import SimulationStatus, simulate

    owner = "least_squares_correction"
    n = _check_n(n, owner)
    x0 = as_float_array(start, "start", owner)
    w = as_float_array(window, "window", owner)
    if np.any(w <= 0):
        raise ParameterError(parameter_message("window", owner, "be > 0", np.ravel(window).tolist()))
    x0, w = np.broadcast_arrays(x0, w)
    plant = Plant(uniform_staircase(n, 0.0, 1.0, 0.5), mass=1.0)      # k = 2 f / s = 1
    stop = 0.0 if n % 2 else 0.5
    out = np.full(x0.shape, np.nan)
    for index in np.ndindex(x0.shape):
        if abs(x0[index]) <= stop:
            continue
        grid = np.linspace(0.0, float(w[index]), FIT_SAMPLES)
        run = simulate(plant, float(w[index]), v0=float(x0[index]), t_eval=grid)
        if run.status is not SimulationStatus.SUCCESS:
            raise ParameterError(f"least_squares_correction: the exact run from x0 = {x0[index]} "
                                 f"did not finish: {run.message}")
        out[index] = exponential_time_constant(grid, np.asarray(run.V), 1)[0]
    return float(out.reshape(-1)[0]) if np.ndim(start) == 0 and np.ndim(window) == 0 else out


def startup_correction(definition: str, n: int, start: Any, window: Any = None) -> Any:
    """``C = tau k / m`` of the ideal startup of ``n`` equal, equally spaced contacts under
    one of the time-constant definitions (see the module docstring).

    Parameters
    ----------
    definition : {"least_squares", "crossing_63"}
    n : int
    start : float or array_like
        ``x0 = (V0 - c) / s``.
    window : float or array_like, optional
        The fit's window in units of ``m / k``; needed for ``"least_squares"`` only (the
        crossing rule reads the stop, whatever comes after it).
    """
    definition = check_option(definition, "definition", "startup_correction", TIME_CONSTANTS)
    if definition == "crossing_63":
        return staircase_correction(n, start)
    if window is None:
        raise ParameterError(parameter_message("window", "startup_correction",
                                               "be given for the least_squares definition", window))
    return least_squares_correction(n, start, window)


def uniform_staircase(n: int, center: float, spacing: float, force: float) -> ContactSet:
    """``n`` contacts of magnitude ``force`` (N) at ``center + (j - (n + 1)/2) spacing`` (m/s),
    ``j = 1..n``: the optimal equal-magnitude staircase for a viscous target (its quantiles,
    docs/physics.md section 8), slope ``2 force / spacing``."""
    if not isinstance(n, (int, np.integer)) or n < 1:
        raise ParameterError(parameter_message("n", "uniform_staircase", "be an integer >= 1", n))
    s = as_float(spacing, "spacing", "uniform_staircase", low=0.0, low_open=True)
    c = as_float(center, "center", "uniform_staircase")
    f = as_float(force, "force", "uniform_staircase", low=0.0, low_open=True)
    speeds = c + (np.arange(1, n + 1) - (n + 1) / 2.0) * s
    return ContactSet(speeds, np.full(n, f))


def transition_time(mass: float, v_max: float, total_force: float, fraction: Any) -> Any:
    """``dT = m 2 v_max / (F_tot mu/mu0)``: the ideal crossing time from ``+v_max`` to
    ``-v_max`` under a friction fraction, s (``inf`` at fraction 0).

    Parameters
    ----------
    mass : float, kg
    v_max : float, m/s
    total_force : float, N
    fraction : float or array_like
        ``mu / mu0`` (``>= 0``).
    """
    owner = "transition_time"
    m = as_float(mass, "mass", owner, low=0.0, low_open=True)
    v = as_float(v_max, "v_max", owner, low=0.0, low_open=True)
    F = as_float(total_force, "total_force", owner, low=0.0, low_open=True)
    ratio = as_float_array(fraction, "fraction", owner)
    if np.any(ratio < 0):
        raise ParameterError(parameter_message("fraction", owner, "be >= 0", ratio.tolist()))
    with np.errstate(divide="ignore"):
        out = m * 2.0 * v / (F * ratio)
    return float(out[0]) if np.ndim(fraction) == 0 else out
