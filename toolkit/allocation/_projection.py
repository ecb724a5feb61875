"""Projection of unrealizable allocation targets onto the realizable set (private).

A Coulomb staircase is non-increasing, stays within ``+-F_tot`` and can only step where
some contact can be put. :func:`realizable_curve` reduces a target to a curve that meets
those rules, refusing it (``strict=True``) or projecting it and recording how in a
:class:`Projection`. Imports go one way: ``targets`` <- ``_evaluate`` <- ``_projection``
<- ``_problem`` <- the methods.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ParameterError, parameter_message
from ._evaluate import abs_integral
from .targets import EquilibriumSpeed, ForceCurve

__all__ = ["Projection", "realizable_curve", "to_jsonable"]


@dataclass(frozen=True, eq=False)
class Projection:
    """How an unrealizable target was changed before solving.

    Attributes
    ----------
    requested : ForceCurve
        The target as requested (sampled), possibly with non-finite values.
    curve : ForceCurve
        The realizable curve that was solved (non-increasing, finite, within ``+-F_tot``).
    distance_sup : float, N
        ``max_k |requested_k - curve_k|`` over the requested samples (``inf`` when a
        requested value is infinite; dropped NaN samples do not count).
    distance_l1 : float, N m/s
        Trapezoid integral of ``|requested - curve|`` over the finite samples.
    reasons : tuple of str
        What was wrong, e.g. ``"forces beyond +-F_tot"``, ``"increasing"``.
    """

    requested: ForceCurve
    curve: ForceCurve
    distance_sup: float
    distance_l1: float
    reasons: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary."""
        return to_jsonable({"reasons": list(self.reasons), "distance_sup": self.distance_sup,
                          "distance_l1": self.distance_l1, "speeds": self.curve.speeds,
                          "forces": self.curve.forces})


def to_jsonable(value: Any) -> Any:
    """``value`` made JSON-able (the one place non-finite floats are handled here).

    Arrays and tuples become lists, numpy scalars Python ones, and ``inf``/``-inf``/``nan``
    the strings ``"inf"``/``"-inf"``/``"nan"`` (``json`` would otherwise write the
    non-standard tokens ``Infinity``/``NaN``), recursively through dicts and lists.
    """
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [to_jsonable(v) for v in (value.tolist() if isinstance(value, np.ndarray)
                                       else value)]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (np.integer, int)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        return float(value) if np.isfinite(value) else str(float(value))
    return value


def _insert_crossings(xs: np.ndarray, ys: np.ndarray, level: float
                      ) -> tuple[np.ndarray, np.ndarray]:
    d0, d1 = ys[:-1] - level, ys[1:] - level
    cross = np.flatnonzero((d0 * d1 < 0) & (xs[1:] > xs[:-1]))
    if cross.size == 0:
        return xs, ys
    share = d0[cross] / (d0[cross] - d1[cross])
    # Kept within its interval: the interpolation may round one ulp past an end.
    new_x = np.clip(xs[cross] + share * (xs[cross + 1] - xs[cross]), xs[cross], xs[cross + 1])
    return (np.insert(xs, cross + 1, new_x), np.insert(ys, cross + 1, np.full(cross.size, level)))


def _trapezoid_weights(xs: np.ndarray) -> np.ndarray:
    widths = np.diff(xs)
    weights = np.zeros_like(xs)
    weights[:-1] += 0.5 * widths
    weights[1:] += 0.5 * widths
    floor = 1e-9 * max(float(weights.max()), 1.0)
    return np.maximum(weights, floor)


def _refuse(name: str, rule: str, value: Any) -> ParameterError:
    return ParameterError(parameter_message(name, "allocate", rule + " (strict=True)", value))


def realizable_curve(target: Any, total: float, reach: tuple[float, float] | None,
                     v0: np.ndarray | None, strict: bool
                     ) -> tuple[ForceCurve, Projection | None]:
    """Reduce an allocation target to a realizable curve, projecting or refusing.

    Parameters
    ----------
    target : ForceCurve, Viscosity, FrictionFraction or EquilibriumSpeed
    total : float, N
        ``F_tot`` of the contacts.
    reach : (float, float) or None, m/s
        Slowest and fastest speed any contact can be given (the union of the per-contact
        boxes); None for a continuous distribution (no individual contacts).
    v0 : ndarray of shape (n,) or None, m/s
        Current contact speeds (None for a distribution).
    strict : bool
        Refuse (:class:`~toolkit.errors.ParameterError`) instead of projecting.

    Rules (each refused with ``strict=True``, otherwise projected and listed in
    ``Projection.reasons``):

    - NaN forces: the samples are dropped (a curve with no finite sample is always refused);
      ``+-inf`` forces are clipped to ``+-F_tot`` ("non-finite values").
    - ``|F| > F_tot``: clipped to ``+-F_tot``, with the crossing speeds inserted so the
      clipped curve is exactly the pointwise clip of the piecewise-linear one.
    - Increasing anywhere: replaced by the weighted isotonic (non-increasing) regression of
      the samples (trapezoid weights), ``scipy.optimize.isotonic_regression``.
    - :class:`EquilibriumSpeed` with ``speed`` beyond every contact's reach: moved to the
      nearest reachable speed.

    A band that extends beyond the speeds the contacts can reach is *not* changed (the
    force there can only be ``+-F_act``); it is refused with ``strict=True`` and otherwise
    its forced error enters the certified bound.
    """
    discrete = reach is not None
    reasons: list[str] = []
    if reach is None:
        reach = (-np.inf, np.inf)
    if isinstance(target, EquilibriumSpeed):
        speed = target.speed
        if not reach[0] <= speed <= reach[1]:
            if strict:
                raise _refuse("target", f"ask for an equilibrium speed the contacts can reach "
                              f"[{reach[0]:g}, {reach[1]:g}] m/s", speed)
            speed = float(np.clip(speed, *reach))
            reasons.append("equilibrium speed beyond the limits")
        limits = reach if np.all(np.isfinite(reach)) else None
        if limits is None and discrete:
            limits = (min(float(v0.min()), speed) - 1.0, max(float(v0.max()), speed) + 1.0)
        requested = target.to_curve(total, limits)
        curve = EquilibriumSpeed(speed, target.margin).to_curve(total, limits)
        if not reasons:
            return curve, None
        # The two steps differ by 2 F_tot between the requested and the projected speed.
        return curve, Projection(requested, curve, 2.0 * total,
                                 2.0 * total * abs(speed - target.speed), tuple(reasons))
    requested = target.to_curve(total, None)
    lo, hi = requested.band
    if strict and discrete and (lo < reach[0] or hi > reach[1]):
        raise _refuse("target", f"have its band of speeds within the contacts' reach "
                      f"[{reach[0]:g}, {reach[1]:g}] m/s", (lo, hi))
    xs, ys = requested.speeds, requested.forces
    nan = np.isnan(ys)
    if nan.all():
        raise ParameterError(parameter_message(
            "target", "allocate", "have at least one finite force sample", ys.tolist()))
    if not np.isfinite(ys).all():
        if strict:
            raise _refuse("target", "have finite forces",
                          float(ys[~np.isfinite(ys)][0]))
        reasons.append("non-finite values")
        xs, ys = xs[~nan], ys[~nan]
        ys = np.where(np.isinf(ys), np.sign(ys) * total, ys)
    if ys.max() > total or ys.min() < -total:
        if strict:
            raise _refuse("target", f"stay within +-F_tot = +-{total:g} N",
                          float(ys[np.argmax(np.abs(ys))]))
        reasons.append("forces beyond +-F_tot")
        for level in (total, -total):
            xs, ys = _insert_crossings(xs, ys, level)
        ys = np.clip(ys, -total, total)
    if (ys[1:] > ys[:-1]).any():
        if strict:
            i = int(np.flatnonzero(np.diff(ys) > 0)[0])
            raise _refuse("target", "be non-increasing in speed (a staircase of Coulomb "
                          "contacts can only decrease)",
                          f"F={ys[i]:g} N at V={xs[i]:g} m/s rising to {ys[i + 1]:g} N "
                          f"at V={xs[i + 1]:g} m/s")
        from scipy.optimize import isotonic_regression  # scipy.optimize: 0.3 s, only for projections

        reasons.append("increasing")
        ys = isotonic_regression(ys, weights=_trapezoid_weights(xs), increasing=False).x
    if not reasons:
        return requested, None
    curve = ForceCurve(xs, ys, requested.weights if xs.size == requested.speeds.size else None)
    # Distances measured at the projected curve's samples (a superset of the finite
    # requested samples), where both curves are linear in between.
    with np.errstate(invalid="ignore"):
        req_left, req_right = requested.value_left(xs), requested.value_right(xs)
    diff = np.where(np.isnan(req_left), 0.0, req_left - ys)
    sup = float(np.max(np.abs(np.where(np.isnan(requested.forces), 0.0,
                                       requested.forces - curve.value_left(requested.speeds)))))
    sup = max(sup, float(np.max(np.abs(diff))))
    diff_r = np.where(np.isnan(req_right), 0.0, req_right - ys)
    finite = np.isfinite(diff) & np.isfinite(diff_r)
    l1 = float(np.sum(abs_integral(diff_r[:-1], diff[1:], np.diff(xs)))) if np.all(finite) \
        else float("inf")
    return curve, Projection(requested, curve, sup, l1, tuple(reasons))
