"""Minimum braking time in closed form: all contacts commanded to one speed limit (bang-bang).

For braking with every contact pushing backward the optimum is bang-bang (all contacts at the
lowest speed); :func:`braking_time` gives the resulting minimum time in closed form
(including the motor lag), a lower bound for every schedule within the speed limits.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from ..errors import as_float
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..model import ContactSet, Motors, Plant, lag_memory

__all__ = ["braking_time"]


def _first_crossing(A: float, c: float, a: float, tau: float) -> float:
    """First ``s >= 0`` with ``lo + A exp(-s/tau) = V + a s`` where ``c = V - lo > 0``.

    ``A > c`` (the contact starts above the body). With ``x = s / tau`` and ``b = a tau``
    this is ``A e^{-x} = c + b x``, i.e. ``y e^y = (A/b) e^{c/b}`` for ``y = x + c/b``
    (Lambert W: branch 0 for ``b > 0``, branch -1 for ``b < 0``); solved here by bisection
    on the convex function ``A e^{-x} - c - b x``, to the last bit. ``inf`` if never.
    """
    b = a * tau
    if b == 0.0:
        return tau * math.log(A / c)

    def gap(x: float) -> float:
        return A * lag_memory(x, 1.0)[0] - c - b * x       # (the motor law in units of tau)

    if b > 0:
        hi = math.log(A / c) + 1.0                 # gap(hi) < 0: A e^{-x} < c there
        while gap(hi) > 0:
            hi *= 2.0
        return tau * brentq(gap, 0.0, hi, xtol=1e-300, rtol=4 * np.finfo(float).eps)
    x_min = math.log(A / -b) if A > -b else 0.0    # minimum of the convex gap
    if gap(x_min) > 0:
        return math.inf
    return tau * brentq(gap, 0.0, x_min, xtol=1e-300, rtol=4 * np.finfo(float).eps)


def braking_time(plant: Plant, v0: float, target_speed: float, *, command: float | None = None,
                 hold: float = 0.0) -> float:
    """Minimum time for the body to reach ``target_speed`` with commands bounded by ``command``.

    Every contact is commanded to ``command`` (default: the motors' lower speed limit when
    braking, the upper one when speeding up) from ``t = hold`` on; before that the motors
    hold the plant's current commands and the body must be at equilibrium there. Between
    events the body moves linearly (no drag, no external force) and each contact above it
    decays exponentially towards ``command`` (lag ``tau``); a contact's crossing time is the
    root of ``lo + A e^{-s/tau} = V + a s`` (a Lambert-W equation, see
    :func:`_first_crossing`). Afterwards the body decelerates at ``F_tot / m``:

        T = hold + m (v0 - target) / F_tot + (2 / F_tot) sum_i f_i t_i*

    with ``t_i*`` the time contact ``i`` spends above the body (0 with ideal motors).

    By the comparison principle (the force is non-decreasing in each contact speed and
    non-increasing in ``V``) no schedule whose commands stay on the ``command`` side
    reaches ``target_speed`` earlier: this is a lower bound and the bang-bang optimum.

    Parameters
    ----------
    plant : Plant
        Contacts (magnitudes, current commands), mass and motors (lag only; a finite rate
        limit must not bind: ``|command - v_i| <= r tau``). ``damping`` and
        ``external_force`` must be 0.
    v0, target_speed : float, m/s
    command : float, optional, m/s
    hold : float, s
        Delay before the commands switch (one controller period when the motors lag).

    Returns
    -------
    float, s

    Raises
    ------
    ParameterError
        When an assumption above fails, or ``target_speed`` is within ``F_tot tau / m`` of
        ``command`` (a contact could then re-cross the body: no closed form).
    """
    owner = "braking_time"
    if not isinstance(plant, Plant):
        raise ParameterTypeError(parameter_message("plant", owner, "be a Plant", plant))
    v0 = as_float(v0, "v0", owner)
    target = as_float(target_speed, "target_speed", owner)
    hold = as_float(hold, "hold", owner, low=0.0)
    if plant.damping != 0 or plant.external(0.0) != 0 or plant.switching_times().size:
        raise ParameterError(parameter_message(
            "plant", owner, "have no damping, no external force and constant commands",
            plant))
    sign = 1.0 if v0 >= target else -1.0             # mirror speeding up into braking
    motors = plant.motors or Motors()
    lo_lim, hi_lim = motors.speed_limits
    if command is None:
        command = lo_lim if sign > 0 else hi_lim
    command = as_float(command, "command", owner)
    forces = plant.contacts.forces
    w = sign * plant.initial_speeds()
    V, lo, goal = sign * v0, sign * command, sign * target
    total = float(forces.sum())
    a_tot = total / plant.mass
    tau = motors.lag
    if V == goal:
        return 0.0
    if hold > 0 and not _at_equilibrium(w, forces, V):
        raise ParameterError(parameter_message(
            "v0", owner, "lie in the equilibrium set of the current commands when hold > 0",
            v0))
    if not goal > lo + a_tot * tau:
        raise ParameterError(parameter_message(
            "target_speed", owner, f"lie beyond command + F_tot tau / m = "
            f"{sign * (lo + a_tot * tau):g} m/s (farther from the command)", target_speed))
    if math.isfinite(motors.rate_limit) and np.any(np.abs(w - lo) > motors.rate_limit * tau):
        raise ParameterError(parameter_message(
            "plant", owner, "have a rate limit that does not bind (|command - v_i| <= r tau)",
            motors.rate_limit))
    t = hold
    active = forces > 0
    w, f = np.sort(w[active]), forces[active][np.argsort(w[active])]
    if tau == 0:                                       # ideal motors: all jump below the body
        return t + (V - goal) / a_tot
    amplitude = w - lo                                 # contact speed = lo + amplitude e^{-s/tau}
    crossed = w < V
    tied = w == V
    if np.any(tied):
        # Tied contacts leave the body at once when they drop faster than it can follow.
        others = float(f[w > V].sum() - f[w < V].sum())
        if plant.mass * (V - lo) / tau > float(f[tied].sum()) - others:
            crossed |= tied
        else:
            raise ParameterError(parameter_message(
                "plant", owner, "have motors faster than the body (a tied contact must drop "
                "below it at once)", f"lag {tau:g} s"))
    s_total = 0.0                                      # time since the switch
    while not np.all(crossed):
        accel = float(f[~crossed].sum() - f[crossed].sum()) / plant.mass
        j = int(np.flatnonzero(~crossed)[0])           # lowest contact still above the body
        s = _first_crossing(amplitude[j] * lag_memory(s_total, tau)[0], V - lo, accel, tau)
        if accel < 0 and V + accel * s <= goal:        # the body gets there first
            return t + (goal - V) / accel
        if not math.isfinite(s):
            raise ParameterError(parameter_message(
                "target_speed", owner, "be reachable with these motors", target_speed))
        V += accel * s
        t += s
        s_total += s
        crossed |= amplitude == amplitude[j]           # equal speeds cross together
    return t + (V - goal) / a_tot


def _at_equilibrium(speeds: np.ndarray, forces: np.ndarray, V: float) -> bool:
    lo, hi = ContactSet(speeds, forces).equilibrium()
    return lo <= V <= hi
