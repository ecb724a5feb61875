"""The allocation problem and result shared by every allocation method (private).

``build_problem`` turns the arguments of :func:`toolkit.allocation.allocate` into a
validated, frozen :class:`AllocationProblem`: per-contact speed boxes (motor limits
intersected with what the rate limit allows from the current speeds), the masks of fixed,
failed and liftable contacts, and the target reduced to a realizable
:class:`~toolkit.allocation.targets.ForceCurve` (with the :class:`Projection` that got it
there, :mod:`._projection`). Every method returns an :class:`AllocationResult` built by
:func:`make_result`, which measures the errors by evaluating the achieved contacts, never by
trusting a solver.
"""

from __future__ import annotations

import enum
import functools
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import as_float, as_float_array
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..model import ContactDistribution, ContactSet
from ._evaluate import evaluate_errors
from ._projection import Projection, realizable_curve, to_jsonable
from .targets import EquilibriumSpeed, ForceCurve, FrictionFraction, Viscosity

__all__ = ["AllocationProblem", "AllocationResult", "AllocationStatus", "Projection",
           "build_problem", "make_result"]

_OWNER = "allocate"
_PLACEHOLDER = ForceCurve([0.0], [0.0])     # curve slot before the target is reduced
_TARGET_TYPES = (ForceCurve, Viscosity, FrictionFraction, EquilibriumSpeed)


class AllocationStatus(enum.Enum):
    """Outcome of :func:`~toolkit.allocation.allocate`; the value is the message shown to users."""

    OPTIMAL = "optimal: the error equals the certified lower bound (gap within tolerance)"
    FEASIBLE_WITH_GAP = ("feasible: the error exceeds the reported lower bound by the "
                         "reported gap")
    PROJECTED = ("the target was not realizable; it was projected onto the realizable set "
                 "(see 'projection') and the projection was solved to optimality")
    INFEASIBLE = "infeasible: no allocation within the constraints meets the requirement"
    TIME_LIMIT = "the time limit was reached; the best allocation found is returned with its gap"
    SOLVER_ERROR = "the numerical back end failed; see 'message'"


@dataclass(frozen=True, eq=False)
class AllocationProblem:
    """A validated allocation problem (built by ``build_problem``).

    Attributes
    ----------
    target : ForceCurve, Viscosity, FrictionFraction or EquilibriumSpeed
        The request as given.
    contacts : ContactSet or ContactDistribution
        Friction magnitudes ``f_i`` (N) and current speeds ``v0_i`` (m/s).
    lower, upper : ndarray of shape (n,), m/s
        Motor speed limits per contact (``-inf``/``inf`` when unlimited); for a
        :class:`~toolkit.model.ContactDistribution`, shape (1,): the scalar limits of the
        patch's speed range.
    max_change : ndarray of shape (n,) or None, m/s
        Largest allowed ``|v_i - v0_i|`` (``rate_limit * dt``), or None.
    fixed, failed, liftable : ndarray of shape (n,), bool
        Fixed and failed contacts keep their current speeds and still push; liftable
        contacts may be set to magnitude 0 (a fixed or failed contact is never lifted).
    strict : bool
        Refuse unrealizable targets instead of projecting them.
    time_limit : float, s
        Wall-clock budget for iterative solvers.
    curve : ForceCurve
        The realizable target curve the errors are measured against.
    projection : Projection or None
        How the request was changed to get ``curve`` (None if it was realizable).
    notes : tuple of str
        Non-fatal adjustments (e.g. a contact whose box was empty).
    """

    target: Any
    contacts: Any
    lower: np.ndarray
    upper: np.ndarray
    max_change: np.ndarray | None
    fixed: np.ndarray
    failed: np.ndarray
    liftable: np.ndarray
    strict: bool
    time_limit: float
    curve: ForceCurve
    projection: Projection | None = None
    notes: tuple[str, ...] = ()

    @property
    def n(self) -> int:
        """Number of discrete contacts (0 for a continuous distribution)."""
        return int(self.contacts.n) if isinstance(self.contacts, ContactSet) else 0

    @property
    def forces(self) -> np.ndarray:
        """Friction magnitudes ``f_i`` (N), shape (n,)."""
        return self.contacts.forces

    @property
    def total_force(self) -> float:
        """``F_tot`` with every contact down, N."""
        return float(self.contacts.total_force)

    def boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-contact allowed speeds ``[lo_i, hi_i]`` (m/s), each of shape (n,), read-only.

        Motor limits intersected with ``v0_i +- max_change_i``; fixed and failed contacts
        get ``[v0_i, v0_i]``. A box that would be empty (current speed outside the limits
        and too far to reach them) becomes the reachable point nearest to the limits.
        Computed once per problem (the problem is immutable).
        """
        return self._boxes

    @functools.cached_property
    def _boxes(self) -> tuple[np.ndarray, np.ndarray]:
        v0 = self.contacts.speeds
        lo, hi = self.lower.copy(), self.upper.copy()
        if self.max_change is not None:
            reach_lo, reach_hi = v0 - self.max_change, v0 + self.max_change
            lo2, hi2 = np.maximum(lo, reach_lo), np.minimum(hi, reach_hi)
            empty = lo2 > hi2
            nearest = np.clip(np.clip(v0, self.lower, self.upper), reach_lo, reach_hi)
            lo = np.where(empty, nearest, lo2)
            hi = np.where(empty, nearest, hi2)
        frozen = self.fixed | self.failed
        lo = np.where(frozen, v0, lo)
        hi = np.where(frozen, v0, hi)
        lo.setflags(write=False)
        hi.setflags(write=False)
        return lo, hi

    @property
    def can_lift(self) -> np.ndarray:
        """Contacts that may be lifted: liftable and neither fixed nor failed, shape (n,)."""
        return self.liftable & ~self.fixed & ~self.failed


@dataclass(frozen=True, eq=False)
class AllocationResult:
    """What an allocation achieved, with a certificate of how good it is.

    Attributes
    ----------
    speeds : ndarray of shape (n,), m/s
        Commanded contact speeds (lifted contacts keep their current speed).
    contacts : ContactSet
        The achieved contacts; lifted ones have magnitude 0.
    active : ndarray of shape (n,), bool
        False for lifted contacts.
    error_sup : float, N
        ``sup_V dist(F_target(V), F_achieved(V))`` over the target's band, where at a
        contact speed the achieved force is the interval ``force_bounds(V)`` (and at a
        vertical step of the target the target is an interval): the distance between the
        target value and that interval. Computed exactly from the achieved contacts.
    error_l1 : float, N m/s
        ``integral |F_achieved - F_target| dV`` over the band, exact (or the weighted sum
        at the samples when the target curve has weights).
    bound : float, N
        Lower bound on the best achievable ``error_sup`` under the constraints: certified
        for the ``"quantile"`` and ``"milp"`` methods; for ``"casadi"`` 0 (uncertified,
        said in ``message``) except the error forced by a patch's speed limits.
    gap : float, N
        ``max(0, error_sup - bound)``: a valid bound never exceeds an achieved error, so a
        negative difference can only be rounding (of the order of the solver tolerances)
        and is reported as 0.
    method : str
        The solver that produced the speeds.
    status : AllocationStatus
    message : str
        Human explanation (status message plus details).
    wall_time : float, s
    projection : Projection or None
    curve : ForceCurve or None
        The realizable target curve the errors are measured against.
    extra : dict
        Method-specific JSON-able details (e.g. solver statistics).
    compliance : float, (m/s)/N
        Motor compliance ``k`` the allocation was made for (``allocate(..., compliance=k)``),
        0 for Coulomb contacts. With ``k > 0``, ``contacts`` holds the speeds and magnitudes
        to drive with motors of that compliance; the errors are those of the compliant law
        (``evaluate_errors(curve, contacts, compliance=k)`` reproduces them), not of the
        Coulomb staircase of ``contacts``.
    """

    speeds: np.ndarray
    contacts: Any
    active: np.ndarray
    error_sup: float
    error_l1: float
    bound: float
    gap: float
    method: str
    status: AllocationStatus
    message: str
    wall_time: float
    projection: Projection | None = None
    curve: ForceCurve | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    compliance: float = 0.0

    def __post_init__(self) -> None:
        for name in ("speeds", "active"):
            array = np.array(getattr(self, name))
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary: ``speeds``, ``error_sup``, ``error_l1``, ``bound``, ``gap``,
        ``method``, ``status``, ``wall_time``, ``message``, ``active``, ``forces``,
        ``compliance``, ``projection``, ``extra``."""
        return to_jsonable({
            "speeds": self.speeds,
            "active": self.active,
            "forces": np.asarray(getattr(self.contacts, "forces", [])),
            "error_sup": self.error_sup,
            "error_l1": self.error_l1,
            "bound": self.bound,
            "gap": self.gap,
            "method": self.method,
            "status": self.status.name,
            "message": self.message,
            "wall_time": float(self.wall_time),
            "compliance": self.compliance,
            "projection": None if self.projection is None else self.projection.to_dict(),
            "extra": self.extra,
        })


# -- building ----------------------------------------------------------------------------------
def _per_contact(value: Any, name: str, n: int) -> np.ndarray:
    if isinstance(value, (float, int, np.floating, np.integer)) and not isinstance(value, bool):
        scalar = float(value)                     # the common case, without array checks
        if np.isnan(scalar):
            raise ParameterError(parameter_message(name, _OWNER, "not contain NaN", value))
        return np.full(n, scalar)
    array = as_float_array(value, name, _OWNER, finite=False)
    if np.any(np.isnan(array)):
        raise ParameterError(parameter_message(name, _OWNER, "not contain NaN", value))
    if array.size == 1:
        array = np.full(n, float(array[0]))
    if array.size != n:
        raise ParameterError(parameter_message(
            name, _OWNER, f"be a scalar or have one entry per contact ({n})",
            f"an array of length {array.size}"))
    return array


def _mask(value: Any, name: str, n: int) -> np.ndarray:
    """A boolean mask of shape (n,) from a mask or a list of integral contact indices."""
    if value is None:
        return np.zeros(n, dtype=bool)
    array = np.asarray(value)
    if array.dtype == bool:
        if array.shape != (n,):
            raise ParameterError(parameter_message(
                name, _OWNER, f"be a boolean mask of shape ({n},)", f"shape {array.shape}"))
        return array.copy()
    # An index list: integral values only (1.5 is not contact 1), each in [0, n - 1].
    try:
        index = np.asarray(value, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ParameterTypeError(parameter_message(
            name, _OWNER, "be a boolean mask or a list of contact indices", value)) from None
    if np.any(~np.isfinite(index)) or np.any(index != np.round(index)):
        raise ParameterError(parameter_message(
            name, _OWNER, "hold integral contact indices (or be a boolean mask)", value))
    if np.any((index < 0) | (index >= n)):
        raise ParameterError(parameter_message(
            name, _OWNER, f"hold contact indices in [0, {n - 1}]", value))
    mask = np.zeros(n, dtype=bool)
    mask[index.astype(int)] = True
    return mask


def _limits(speed_limits: Any, n: int) -> tuple[np.ndarray, np.ndarray]:
    if speed_limits is None:
        return np.full(n, -np.inf), np.full(n, np.inf)
    if isinstance(speed_limits, (str, bytes)) or not hasattr(speed_limits, "__len__") \
            or len(speed_limits) != 2:
        raise ParameterTypeError(parameter_message(
            "speed_limits", _OWNER, "be a pair (lo, hi) of scalars or per-contact arrays (m/s)",
            speed_limits))
    lower = _per_contact(speed_limits[0], "speed_limits", n)
    upper = _per_contact(speed_limits[1], "speed_limits", n)
    bad = ~(lower <= upper)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ParameterError(parameter_message(
            "speed_limits", _OWNER, "satisfy lo <= hi for every contact",
            f"lo={lower[i]:g} > hi={upper[i]:g} for contact {i}"))
    return lower, upper


def _patch_limits(speed_limits: Any, *per_contact: Any) -> tuple[np.ndarray, np.ndarray]:
    """Scalar limits ``(lo, hi)`` (shape (1,) each) for a ContactDistribution's speed range.

    A patch has no individual contacts: per-contact limits, rate limits and masks are
    refused (``per_contact``: rate_limit, dt, fixed, failed, liftable).
    """
    for name, value in zip(("rate_limit", "dt", "fixed", "failed", "liftable"), per_contact):
        if value is not None:
            raise ParameterError(parameter_message(
                name, _OWNER, "be None for a ContactDistribution (a patch has no individual "
                "contacts)", value))
    if speed_limits is not None and not isinstance(speed_limits, (str, bytes)) \
            and hasattr(speed_limits, "__len__") and len(speed_limits) == 2:
        for value in speed_limits:
            if np.size(value) != 1:
                raise ParameterError(parameter_message(
                    "speed_limits", _OWNER, "be a pair of scalars (lo, hi) for a "
                    "ContactDistribution (a patch has no individual contacts)", speed_limits))
    return _limits(speed_limits, 1)


def build_problem(target: Any, contacts: Any, *, speed_limits: Any = None,
                  rate_limit: Any = None, dt: Any = None, fixed: Any = None,
                  failed: Any = None, liftable: Any = None, strict: bool = False,
                  time_limit: float = 30.0) -> AllocationProblem:
    """Validate the arguments of :func:`~toolkit.allocation.allocate` into a problem.

    Raises
    ------
    ParameterTypeError, ParameterError
        Wrong types or values; with ``strict=True`` also unrealizable targets
        (see :func:`toolkit.allocation._projection.realizable_curve`).
    """
    if not isinstance(target, _TARGET_TYPES):
        raise ParameterTypeError(parameter_message(
            "target", _OWNER,
            "be a ForceCurve, Viscosity, FrictionFraction or EquilibriumSpeed", target))
    if not isinstance(contacts, (ContactSet, ContactDistribution)):
        raise ParameterTypeError(parameter_message(
            "contacts", _OWNER, "be a ContactSet (or a ContactDistribution)", contacts))
    if not isinstance(strict, bool):
        raise ParameterTypeError(parameter_message("strict", _OWNER, "be True or False", strict))
    time_limit = as_float(time_limit, "time_limit", _OWNER, low=0.0, low_open=True)
    n = contacts.n if isinstance(contacts, ContactSet) else 0
    if n == 0:
        lower, upper = _patch_limits(speed_limits, rate_limit, dt, fixed, failed, liftable)
    else:
        lower, upper = _limits(speed_limits, n)
    max_change = None
    if (rate_limit is None) != (dt is None):
        missing = "dt" if dt is None else "rate_limit"
        raise ParameterError(parameter_message(
            missing, _OWNER, "be given together with "
            + ("'rate_limit'" if missing == "dt" else "'dt'"), None))
    if rate_limit is not None:
        rate = _per_contact(rate_limit, "rate_limit", n)
        if np.any(rate < 0):
            raise ParameterError(parameter_message("rate_limit", _OWNER, "be >= 0",
                                                   float(rate[rate < 0][0])))
        step = as_float(dt, "dt", _OWNER, low=0.0, low_open=True)
        max_change = rate * step
    fixed_m, failed_m, lift_m = (_mask(fixed, "fixed", n), _mask(failed, "failed", n),
                                 _mask(liftable, "liftable", n))
    notes: list[str] = []
    if n:
        v0 = contacts.speeds
        outside = (v0 < lower) | (v0 > upper)
        if np.any(outside & (fixed_m | failed_m)):
            i = int(np.flatnonzero(outside & (fixed_m | failed_m))[0])
            notes.append(f"contact {i} is fixed/failed at {v0[i]:g} m/s, outside its limits")
        if max_change is not None:
            far = (np.maximum(lower - v0, v0 - upper) > max_change) & ~(fixed_m | failed_m)
            if np.any(far):
                i = int(np.flatnonzero(far)[0])
                if strict:
                    raise ParameterError(parameter_message(
                        "rate_limit", _OWNER,
                        "let every contact reach its speed limits within dt (strict=True)",
                        f"contact {i} at {v0[i]:g} m/s cannot reach "
                        f"[{lower[i]:g}, {upper[i]:g}]"))
                notes.append(f"{int(far.sum())} contact(s) cannot reach their speed limits "
                             "within dt; they go as near as the rate limit allows")
    problem = AllocationProblem(target, contacts, lower, upper, max_change, fixed_m, failed_m,
                                lift_m, strict, time_limit, _PLACEHOLDER, None, tuple(notes))
    reach = v0 = None
    if n:
        lo, hi = problem.boxes()
        reach, v0 = (float(np.min(lo)), float(np.max(hi))), contacts.speeds
    curve, projection = realizable_curve(target, problem.total_force, reach, v0, strict)
    return AllocationProblem(target, contacts, lower, upper, max_change, fixed_m, failed_m,
                             lift_m, strict, time_limit, curve, projection, tuple(notes))


def make_result(problem: AllocationProblem, speeds: np.ndarray, active: np.ndarray,
                bound: float, method: str, start: float, *,
                status: AllocationStatus | None = None, detail: str = "",
                extra: dict[str, Any] | None = None,
                gap_tolerance: float = 1e-9) -> AllocationResult:
    """Evaluate an allocation and package it with its certificate.

    Parameters
    ----------
    problem : AllocationProblem
    speeds : ndarray of shape (n,), m/s
        Proposed speeds; clipped into the boxes (solver tolerances) before evaluation.
    active : ndarray of shape (n,), bool
    bound : float, N
        Certified lower bound on the optimal ``error_sup``.
    method : str
    start : float
        ``time.perf_counter()`` when the method started.
    status : AllocationStatus, optional
        Forced status (e.g. ``TIME_LIMIT``); otherwise chosen from the gap.
    detail : str
        Appended to the message.
    gap_tolerance : float
        Relative (to ``F_tot``) gap under which the result counts as optimal.
    """
    lo, hi = problem.boxes()
    speeds = np.minimum(np.maximum(np.asarray(speeds, dtype=float), lo), hi)
    active = np.asarray(active, dtype=bool)
    forces = np.where(active, problem.forces, 0.0)
    achieved = ContactSet(speeds, forces)
    error_sup, error_l1 = evaluate_errors(problem.curve, achieved)
    # A certified bound is <= every achievable error, so error < bound is rounding only.
    gap = max(error_sup - bound, 0.0)
    if status is None:
        if gap <= gap_tolerance * max(problem.total_force, 1.0):
            status = (AllocationStatus.PROJECTED if problem.projection is not None
                      else AllocationStatus.OPTIMAL)
        else:
            status = AllocationStatus.FEASIBLE_WITH_GAP
    parts = [status.value]
    if detail:
        parts.append(detail)
    parts.extend(problem.notes)
    wall = time.perf_counter() - start
    return AllocationResult(speeds, achieved, active, float(error_sup), float(error_l1),
                            float(bound), float(gap), method, status, "; ".join(parts), wall,
                            problem.projection, problem.curve, dict(extra or {}))
