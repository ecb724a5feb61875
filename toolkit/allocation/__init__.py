"""Allocation: choose contact speeds that realize a target force-speed behaviour.

One verb, :func:`allocate`, over small frozen targets (:class:`ForceCurve`,
:class:`Viscosity`, :class:`FrictionFraction`, :class:`EquilibriumSpeed`); one module per
method: ``"quantile"`` (the exact construction for equal magnitudes), ``"milp"`` (cvxpy +
HiGHS) and ``"casadi"`` (compliant contacts, continuous patches). Every result reports its
error on the achieved contacts, a lower bound on the best achievable error and the gap
(certified for ``"quantile"`` and ``"milp"``). The methods and their certificates:
docs/methods.md."""

from __future__ import annotations

import time
from typing import Any

from ..errors import as_float, check_option
from ..errors import ParameterError, parameter_message
from ..model import ContactDistribution
from ._evaluate import evaluate_errors
from ._milp import allocate_milp
from ._problem import AllocationProblem, AllocationResult, AllocationStatus, build_problem
from ._projection import Projection
from ._quantile import allocate_quantile, quantile_applies
from ._smooth import allocate_smooth
from .targets import EquilibriumSpeed, ForceCurve, FrictionFraction, Viscosity

__all__ = ["allocate", "AllocationProblem", "AllocationResult", "AllocationStatus",
           "Projection", "ForceCurve", "Viscosity", "FrictionFraction", "EquilibriumSpeed",
           "METHODS", "choose_method", "evaluate_errors"]

METHODS = ("quantile", "milp", "casadi")


def choose_method(problem: AllocationProblem) -> str:
    """The method ``allocate(method=None)`` uses for ``problem``.

    ``"casadi"`` for a continuous :class:`~toolkit.model.ContactDistribution`;
    ``"quantile"`` when every contact has the same magnitude and the same speed box and
    none is fixed, failed or liftable; ``"milp"`` otherwise.
    """
    if isinstance(problem.contacts, ContactDistribution):
        return "casadi"
    return "quantile" if quantile_applies(problem) else "milp"


def allocate(target: Any, contacts: Any, *, speed_limits: Any = None, rate_limit: Any = None,
             dt: Any = None, fixed: Any = None, failed: Any = None, liftable: Any = None,
             method: str | None = None, strict: bool = False,
             time_limit: float = 30.0, compliance: float = 0.0) -> AllocationResult:
    """Choose contact speeds that realize ``target`` as closely as possible (sup norm).

    Parameters
    ----------
    target : ForceCurve, Viscosity, FrictionFraction or EquilibriumSpeed
        The requested force-speed behaviour.
    contacts : ContactSet
        Friction magnitudes ``f_i`` (N) and current speeds ``v0_i`` (m/s), shape (n,). A
        :class:`~toolkit.model.ContactDistribution` goes to the ``"casadi"`` method.
    speed_limits : pair of (float or array_like of shape (n,)), m/s, optional
        Motor limits ``(lo, hi)``, per contact or shared; possibly asymmetric.
    rate_limit : float or array_like of shape (n,), m/s^2, optional
        Largest ``|dv_i/dt|``; with ``dt`` (s) each contact may move at most
        ``rate_limit * dt`` from its current speed.
    dt : float, s, optional
    fixed, failed : boolean mask of shape (n,) or list of indices, optional
        Contacts that keep their current speed (and still push).
    liftable : boolean mask of shape (n,) or list of indices, optional
        Contacts that may be lifted (magnitude 0).
    method : {"quantile", "milp", "casadi"} or None
        None picks one (:func:`choose_method`); the result says which.
    strict : bool
        Refuse unrealizable targets with :class:`~toolkit.errors.ParameterError` instead of
        projecting them.
    time_limit : float, s
        Budget for the MILP; past it the best allocation is returned with its gap.
    compliance : float, (m/s)/N
        Motor compliance ``k`` (torque-speed line): each contact force becomes
        ``f_i clip((v_i - V) / (k f_i), -1, 1)``. ``k > 0`` needs the ``"casadi"`` method
        (chosen when ``method`` is None); 0 (default) is the Coulomb law. The result records
        it (``result.compliance``, ``extra["compliance"]``): its ``contacts`` are the speeds
        and magnitudes to drive with motors of that compliance, and its errors are those of
        the compliant law (``evaluate_errors(result.curve, result.contacts, compliance=k)``).
        For a :class:`~toolkit.model.ContactDistribution` ``speed_limits`` must be a pair
        of scalars (the patch's speed range stays inside), and per-contact arguments
        (``rate_limit``, ``dt``, ``fixed``, ``failed``, ``liftable``) are refused.

    Returns
    -------
    AllocationResult

    Examples
    --------
    >>> from toolkit import ContactSet
    >>> result = allocate(FrictionFraction(0.4, 0.35), ContactSet([0.0] * 10),
    ...                   speed_limits=(-0.35, 0.35))
    >>> sorted(result.speeds.tolist()) == [-0.35] * 7 + [0.35] * 3
    True
    """
    start = time.perf_counter()
    if method is not None:
        check_option(method, "method", "allocate", METHODS)
    problem = build_problem(target, contacts, speed_limits=speed_limits, rate_limit=rate_limit,
                            dt=dt, fixed=fixed, failed=failed, liftable=liftable, strict=strict,
                            time_limit=time_limit)
    compliance = as_float(compliance, "compliance", "allocate", low=0.0)
    chosen = method if method is not None else ("casadi" if compliance > 0 else choose_method(problem))
    checked = method is None and chosen == "quantile"        # choose_method verified it
    if compliance > 0 and chosen != "casadi":
        raise ParameterError(parameter_message(
            "method", "allocate", "be 'casadi' (or None) for compliant contacts (compliance > 0)", chosen))
    if chosen == "casadi":
        return allocate_smooth(problem, compliance=compliance)
    if isinstance(problem.contacts, ContactDistribution):
        raise ParameterError(parameter_message(
            "method", "allocate", "be 'casadi' (or None) for a ContactDistribution", chosen))
    if chosen == "quantile":
        return allocate_quantile(problem, start, checked=checked)
    return allocate_milp(problem, start)
