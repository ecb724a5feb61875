"""Friction laws of one contact: the force ``phi(s)`` as a function of slip ``s = v_i - V``.

:func:`contact_forces` is the only place the laws are written, once, over an array
namespace (numpy arrays or casadi expressions): ``"sign"`` (Coulomb, set-valued at 0, its
midpoint returned), ``"tanh"``, ``"stribeck"`` (a breakaway hump of peak ratio
:data:`STRIBECK_PEAK`) and the saturated linear law of compliant motors. The laws written
out: docs/methods.md."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import as_float, check_option
from ._xp import ops
from ..laws import tie_tolerance

__all__ = ["FRICTION_LAWS", "STRIBECK_PEAK", "STRIBECK_SPEED", "contact_forces",
           "compliant_breakpoints", "compliant_zero_set"]

#: Friction laws accepted by :func:`contact_forces`.
FRICTION_LAWS = ("sign", "tanh", "stribeck")

#: Smoothed Stribeck law: peak (breakaway) force over the Coulomb force ...
STRIBECK_PEAK = 1.5
#: ... and Stribeck speed in units of the smoothing width ``epsilon``.
STRIBECK_SPEED = 3.0


def contact_forces(slip: Any, forces: Any, *, law: str = "sign", epsilon: float = 0.0,
                   compliance: float = 0.0, xp: Any = np, owner: str = "contact_forces") -> Any:
    """Force of each contact on the body for slips ``s = v_i - V``.

    Parameters
    ----------
    slip : array_like of shape (..., n), m/s (or a casadi expression of shape (n, 1))
        ``v_i - V`` of each contact.
    forces : ndarray of shape (n,), N
        Friction magnitudes ``f_i >= 0`` (numbers, also when ``xp`` is casadi).
    law : {"sign", "tanh", "stribeck"}
    epsilon : float, m/s
        Smoothing width, ``> 0`` for ``"tanh"`` and ``"stribeck"`` (ignored otherwise).
    compliance : float, (m/s)/N
        Motor compliance ``k``; ``> 0`` selects the saturated linear law for every ``law``.
    xp : module
        ``numpy`` or ``casadi``.
    owner : str
        The caller's name, for error messages.

    Returns
    -------
    ndarray of shape (..., n), N (or a casadi expression of shape (n, 1))
    """
    if law != "sign":                       # (the default needs no check: per-sample callers)
        check_option(law, "friction", owner, FRICTION_LAWS)
    o = ops(xp)
    forces = np.asarray(forces, dtype=float)
    f = forces if xp is np else o.const(forces)
    if compliance > 0:
        # k f_i = 0 only where f_i = 0: divide by 1 there (the force is 0 anyway).
        scale = o.const(np.where(forces > 0, compliance * forces, 1.0))
        with np.errstate(over="ignore", invalid="ignore"):
            return f * o.fmin(o.fmax(slip / scale, -1.0), 1.0)
    if law == "sign":
        return f * o.sign(slip)
    eps = as_float(epsilon, "epsilon", owner, low=0.0, low_open=True)
    with np.errstate(over="ignore"):     # slip / eps = +-inf: tanh = +-1, exp(-inf) = 0
        smooth = o.tanh(slip / eps)
        if law == "tanh":
            return f * smooth
        hump = o.exp(-(slip / (STRIBECK_SPEED * eps)) ** 2)
    return f * smooth * (1.0 + (STRIBECK_PEAK - 1.0) * hump)


def compliant_breakpoints(speeds: np.ndarray, forces: np.ndarray, k: float) -> tuple[
        np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """The force-speed map ``F(V) = sum f_i clip((v_i - V)/(k f_i), -1, 1)`` of compliant
    contacts: continuous, piecewise linear, non-increasing.

    Parameters
    ----------
    speeds : ndarray of shape (n,), m/s
    forces : ndarray of shape (n,), N
    k : float, (m/s)/N
        Compliance, ``> 0`` (Plant makes sure ``k f_i`` is above the speeds' rounding).

    Returns
    -------
    x : ndarray of shape (K,), m/s
        Distinct saturation limits ``v_i +- k f_i`` of the contacts with ``f_i > 0``, ascending.
    at_x : ndarray of shape (K,), N
        ``F(x)``, snapped to 0 within ``4 (K + 1) eps F_tot``.
    first : ndarray of shape (K,), int
        The lowest index of the contacts saturating at each limit.
    slope : ndarray of shape (K + 1,), N s/m
        ``dF/dV`` inside interval ``j`` = ``(x[j-1], x[j])`` (0 below and above all limits).
    total : float, N
        ``F_tot`` of the contacts with ``f_i > 0``.
    """
    active = np.flatnonzero(forces > 0)
    v, fa = speeds[active], forces[active]
    points = np.concatenate((v - k * fa, v + k * fa))
    change = np.concatenate((np.full(v.size, -1.0 / k), np.full(v.size, 1.0 / k)))
    owner = np.concatenate((active, active))
    order = np.lexsort((owner, points))
    points, change, owner = points[order], change[order], owner[order]
    new = np.concatenate(([True], points[1:] != points[:-1]))
    group = np.cumsum(new) - 1
    x = points[new]
    change = np.bincount(group, weights=change, minlength=x.size)
    total = float(np.sum(fa))
    slope = np.concatenate(([0.0], np.cumsum(change)))           # slope inside interval j
    slope[-1] = 0.0                                                # exactly flat above all
    at_x = total + np.concatenate(([0.0], np.cumsum(slope[1:-1] * np.diff(x))))
    tol = tie_tolerance(x.size, total)
    at_x = np.where(np.abs(at_x) <= tol, 0.0, at_x)
    return x, at_x, owner[new], slope, total


def compliant_zero_set(speeds: np.ndarray, forces: np.ndarray, k: float) -> tuple[float, float]:
    """Zero set of ``F(V) = sum f_i clip((v_i - V)/(k f_i), -1, 1)`` (continuous,
    non-increasing): ``(lo, hi)`` in m/s, ``lo == hi`` for a single point."""
    x, values, _, _, _ = compliant_breakpoints(speeds, forces, k)
    zero = np.flatnonzero(values == 0.0)
    if zero.size:
        return float(x[zero[0]]), float(x[zero[-1]])
    j = int(np.flatnonzero(values < 0.0)[0])           # F(x[j-1]) > 0 > F(x[j])
    share = values[j - 1] / (values[j - 1] - values[j])
    point = float(x[j - 1] + share * (x[j] - x[j - 1]))
    return point, point
