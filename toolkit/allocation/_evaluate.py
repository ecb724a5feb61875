"""Exact error evaluation of an allocation (private): the sup and L1 distances between the
target curve and the achieved staircase, computed piece by piece between breakpoints (no
sampling, no quadrature error). The definitions: docs/methods.md."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ParameterError, parameter_message
from ..model import ContactSet
from .targets import ForceCurve

__all__ = ["evaluate_errors", "abs_integral", "failure_margin", "margin_requirement",
           "compliant_force", "piecewise_linear_errors", "forced_error"]


def abs_integral(d0: np.ndarray, d1: np.ndarray, width: np.ndarray) -> np.ndarray:
    """Exact ``integral |d(u)| du`` over pieces where ``d`` is linear from ``d0`` to ``d1``.

    Parameters
    ----------
    d0, d1 : ndarray of shape (m,)
        Values at the ends of each piece.
    width : ndarray of shape (m,)
        Lengths of the pieces (>= 0).
    """
    a0, a1 = np.abs(d0), np.abs(d1)
    same = d0 * d1 >= 0
    total = a0 + a1
    # Safe denominator (no errstate context needed: it costs more than the arithmetic).
    crossing = (d0 * d0 + d1 * d1) / (2.0 * np.where(total > 0, total, 1.0))
    return width * np.where(same, 0.5 * total, crossing)


def _interval_distance(lo1: np.ndarray, hi1: np.ndarray, lo2: np.ndarray,
                       hi2: np.ndarray) -> np.ndarray:
    return np.maximum(0.0, np.maximum(lo1 - hi2, lo2 - hi1))


def evaluate_errors(curve: ForceCurve, contacts: ContactSet, compliance: float = 0.0
                    ) -> tuple[float, float]:
    """``(error_sup, error_l1)`` of ``contacts`` against ``curve`` over its band (N, N m/s).

    See the module docstring for the definitions; both are exact. With ``curve.weights``,
    ``error_l1`` is ``sum_k weights[k] * dist(target_k, achieved(V_k))`` instead of the
    integral. Cost ``O((n + k) log(n + k))`` for ``n`` contacts and ``k`` samples.

    Parameters
    ----------
    curve : ForceCurve
    contacts : ContactSet
        Contact speeds (m/s) and magnitudes (N), shape (n,).
    compliance : float, (m/s)/N
        Motor compliance ``k``: 0 (default) is the Coulomb staircase; ``k > 0`` the
        saturated linear law ``f_i clip((v_i - V) / (k f_i), -1, 1)`` of
        ``compliant_force`` (how ``allocate(..., compliance=k)`` measures its errors,
        so its results can be re-evaluated here).
    """
    if compliance != 0.0:
        if not (np.isfinite(compliance) and compliance > 0):
            raise ParameterError(parameter_message("compliance", "evaluate_errors",
                                                   "be finite and >= 0", compliance))
        speeds, forces = contacts.speeds, contacts.forces
        scale = compliance * forces[forces > 0]
        kinks = np.concatenate((speeds[forces > 0] - scale, speeds[forces > 0] + scale))
        return piecewise_linear_errors(
            curve, lambda V: compliant_force(V, speeds, forces, compliance), kinks)
    xs, ys = curve.speeds, curve.forces
    lo, hi = float(xs[0]), float(xs[-1])
    stairs = contacts.staircase()
    levels, plateaus = stairs.levels, stairs.plateaus
    inner = levels[(levels > lo) & (levels < hi)]
    points = np.concatenate((xs, inner))
    points.sort()
    points = points[np.concatenate(([True], points[1:] > points[:-1]))]
    # Target limits at every breakpoint; the achieved force at a point is the interval
    # between the plateaus on its two sides (they differ only at a contact speed, by the
    # stiction forces there: force_bounds read from the same staircase).
    t_left, t_right = curve.value_left(points), curve.value_right(points)
    p_left = plateaus[np.searchsorted(levels, points, side="left")]
    p_right = plateaus[np.searchsorted(levels, points, side="right")]
    point_err = _interval_distance(np.minimum(t_left, t_right), np.maximum(t_left, t_right),
                                   np.minimum(p_left, p_right), np.maximum(p_left, p_right))
    sup = float(point_err.max())
    l1 = 0.0
    if points.size >= 2:
        # Open piece (x0, x1) between breakpoints: plateau p_right(x0), target linear from
        # T(x0+) to T(x1-).
        plateau = p_right[:-1]
        d0 = t_right[:-1] - plateau
        d1 = t_left[1:] - plateau
        sup = max(sup, float(np.max(np.maximum(np.abs(d0), np.abs(d1)))))
        l1 = float(np.sum(abs_integral(d0, d1, np.diff(points))))
    if curve.weights is not None:
        a_lo, a_hi = contacts.force_bounds(xs)
        l1 = float(np.sum(curve.weights * _interval_distance(ys, ys, a_lo, a_hi)))
    return sup, l1


def compliant_force(V: Any, speeds: Any, forces: Any, compliance: float) -> np.ndarray:
    """Net force of compliant contacts, ``sum f_i clip((v_i - V) / (k f_i), -1, 1)``.

    Parameters
    ----------
    V : array_like of shape (m,), m/s
    speeds, forces : array_like of shape (n,), m/s and N
    compliance : float, (m/s)/N, ``> 0``

    Returns
    -------
    ndarray of shape (m,), N
    """
    V = np.asarray(V, dtype=float)[:, None]
    f = np.asarray(forces, dtype=float)
    scale = np.where(f > 0, compliance * f, 1.0)
    ratio = np.clip((np.asarray(speeds, dtype=float) - V) / scale, -1.0, 1.0)
    return np.where(f > 0, f * ratio, 0.0).sum(axis=1)


def piecewise_linear_errors(curve: ForceCurve, force: Any, breakpoints: Any
                            ) -> tuple[float, float]:
    """Exact sup and L1 errors between a continuous piecewise-linear force and a target curve.

    Parameters
    ----------
    curve : ForceCurve
        Linear between samples; a repeated speed is a vertical step.
    force : callable
        ``force(V) -> ndarray``: continuous and linear between ``breakpoints``.
    breakpoints : array_like, m/s
        Every kink of ``force`` (those outside the band are ignored).

    Returns
    -------
    error_sup : float, N
        ``sup |force - target|`` over the band (one-sided limits at the target's steps).
    error_l1 : float, N m/s
        Exact integral of ``|force - target|`` over the band, or with the curve's weights
        ``sum_k w_k |force(V_k) - F_k|``.
    """
    lo, hi = curve.band
    points = np.concatenate((curve.speeds, np.asarray(breakpoints, dtype=float)))
    points = np.unique(np.clip(points, lo, hi))
    achieved = np.asarray(force(points), dtype=float)
    left = achieved - curve.value_left(points)
    right = achieved - curve.value_right(points)
    error_sup = float(np.max(np.maximum(np.abs(left), np.abs(right))))
    if curve.weights is not None:
        error_l1 = float(np.sum(curve.weights * np.abs(np.asarray(force(curve.speeds))
                                                      - curve.forces)))
    elif points.size > 1:
        error_l1 = float(np.sum(abs_integral(right[:-1], left[1:], np.diff(points))))
    else:
        error_l1 = 0.0
    return error_sup, error_l1


def forced_error(curve: ForceCurve, total_force: float, box: tuple[float, float]) -> float:
    """Error (N) that every allocation of speeds in ``box = (L, H)`` (m/s) must make.

    For ``V < L`` every contact is above ``V`` and the force is ``+F_tot``; for ``V > H``
    it is ``-F_tot``. On a non-increasing target the worst points are next to ``L`` and
    ``H``: ``F_tot - T(L-)`` and ``T(H+) + F_tot`` (the band's far end when the whole box
    lies beyond it). 0 when the box covers the band. A certified lower bound for any
    Coulomb contacts (or patch) confined to the box, whatever their magnitudes.
    """
    lo, hi = curve.band
    low, high = box
    if low > hi:                                  # every contact above the band: F = +F_tot
        return float(total_force - curve.value_left(hi))
    if high < lo:                                 # every contact below the band: F = -F_tot
        return float(curve.value_right(lo) + total_force)
    bound = 0.0
    if low > lo:
        bound = max(bound, float(total_force - curve.value_left(low)))
    if high < hi:
        bound = max(bound, float(curve.value_right(high) + total_force))
    return bound


# -- robustness of an equilibrium ---------------------------------------------------------------
def margin_requirement(forces: np.ndarray, margin: int) -> float:
    """``2 * (sum of the margin largest magnitudes)`` (N): the slack ``m`` failures can eat."""
    if margin <= 0:
        return 0.0
    return 2.0 * float(np.sum(np.sort(np.asarray(forces))[::-1][:margin]))


def failure_margin(contacts: ContactSet, speed: float) -> int:
    """Largest ``m`` with ``W >= |U - L| + 2 * (sum of the m largest magnitudes)``.

    ``W``, ``L``, ``U``: total magnitude at, below and above ``speed``. Any ``m`` contacts
    may then stop at any speed and ``speed`` stays in the equilibrium set. Returns -1 when
    ``speed`` is not even an equilibrium (``W < |U - L|``).
    """
    # force_bounds(speed) = [U - L - W, U - L + W] (public API; no private access).
    low, high = (float(x) for x in contacts.force_bounds(float(speed)))
    slack = 0.5 * (high - low) - abs(0.5 * (high + low))
    tol = contacts.tie_tolerance
    if slack < -tol:
        return -1
    ordered = np.sort(contacts.forces[contacts.forces > 0])[::-1]
    used = 2.0 * np.cumsum(ordered)
    return int(np.searchsorted(used, slack + tol, side="right"))
