"""Simulate a body on active contacts: one verb, :func:`simulate`, over interchangeable methods.

Methods (``method=``): ``"exact"`` (default; event-driven closed-form segments, exact to
rounding for the Coulomb model), ``"rk45"``, ``"lsoda"``, ``"radau"``, ``"bdf"`` (scipy's
``solve_ivp`` on the ``sign``, ``tanh`` or ``stribeck`` law), ``"moreau"`` (Moreau-Jean time
stepping; the only method that models drive backlash) and ``"casadi"`` (SUNDIALS on the
smoothed model). Also here: :func:`advance` (one held command from an :class:`ExactState`),
:func:`simulate_batch` (many constant-speed scenes), :class:`SampledRun` and
:func:`sampled_batch` (sampled loops in the kernels), :class:`Budget` and the result types.
The methods and their options: docs/physics.md, section 11.
"""

from __future__ import annotations

import importlib
import math
from typing import Any

import numpy as np

from .._compiled import compiled
from ..errors import as_float, as_float_array, check_option, suggestion
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..model import Plant
from ._batch import BatchResult, simulate_batch
from ._reference import BudgetExceeded, Meter
from ._result import Budget, Event, SimulationResult, SimulationStatus, refuse_backlash
from ._exact import clear_cache
from ._sampled import SampledLaw, SampledRun, sampled_batch, sampled_supported
from ._stepper import ExactState, ExactStep, advance
from ._warmup import warm_up

__all__ = ["simulate", "simulate_batch", "BatchResult", "SimulationStatus", "Budget", "Event",
           "SimulationResult", "METHODS", "advance", "ExactState", "ExactStep", "clear_cache", "warm_up",
           "refuse_backlash", "SampledLaw", "SampledRun", "sampled_batch", "sampled_supported"]
__all__ += ["Meter", "BudgetExceeded"]

_SCIPY_OPTIONS = ("friction", "epsilon", "rtol", "atol")

# method -> (module, function, fixed keyword arguments, accepted option names)
_DISPATCH: dict[str, tuple[str, str, dict[str, Any], tuple[str, ...]]] = {
    "exact": ("_exact", "simulate_exact", {}, ()),
    "rk45": ("_scipy", "simulate_scipy", {"solver": "rk45"}, _SCIPY_OPTIONS),
    "lsoda": ("_scipy", "simulate_scipy", {"solver": "lsoda"}, _SCIPY_OPTIONS),
    "radau": ("_scipy", "simulate_scipy", {"solver": "radau"}, _SCIPY_OPTIONS),
    "bdf": ("_scipy", "simulate_scipy", {"solver": "bdf"}, _SCIPY_OPTIONS),
    "moreau": ("_moreau", "simulate_moreau", {}, ("step",)),
    "casadi": ("_casadi", "simulate_casadi", {}, ("integrator", *_SCIPY_OPTIONS)),
}

_DEFAULT_BUDGET = Budget()
_LOADED: dict[str, Any] = {}

#: Names accepted by ``simulate(..., method=...)``.
METHODS: tuple[str, ...] = tuple(_DISPATCH)


def _check_t_eval(t_eval: Any, t_end: float) -> np.ndarray | None:
    if t_eval is None:
        return None
    if isinstance(t_eval, np.ndarray) and t_eval.dtype == np.float64 and t_eval.ndim == 1 and t_eval.size:
        times = t_eval   # the common case: no conversion (copied below only if writeable)
    else:
        times = as_float_array(t_eval, "t_eval", "simulate")
    # One pass, NaN-safe: every comparison with NaN is False, and the two bounds exclude +-inf
    # (the compiled kernel once this process has it: the same test without temporaries).
    core = compiled("core")
    if core is not None:
        ok = core.ordered_within(times, t_end)
    else:
        ok = bool((times[1:] >= times[:-1]).all()) and times[0] >= 0 and times[-1] <= t_end
    if not ok:
        raise ParameterError(parameter_message(
            "t_eval", "simulate", f"be non-decreasing times within [0, t_end = {t_end:g}]",
            times.tolist() if times.size <= 8 else f"[{times.min():g} .. {times.max():g}]"))
    return times


def simulate(plant: Plant, t_end: float, *, v0: float = 0.0, method: str = "exact",
             t_eval: Any = None, budget: Budget | None = None, **options: Any) -> SimulationResult:
    """Simulate the body speed ``V(t)`` of a plant from ``V(0) = v0`` to ``t_end``.

    Parameters
    ----------
    plant : Plant
        Or a plant of another kind that simulates itself (a ``simulate(t_end, **arguments)``
        method taking these arguments): a :class:`toolkit.planar.PlanarPlant` is simulated by
        :func:`toolkit.planar.simulation.simulate_planar`, with ``v0`` a 2-vector, and
        returns its own result. This package imports none of them.
    t_end : float, s
        Horizon, ``> 0``.
    v0 : float, m/s
        Initial body speed.
    method : str
        One of ``METHODS``; see the module docstring.
    t_eval : array_like of shape (T,), s, optional
        Non-decreasing times in ``[0, t_end]`` at which to report ``V``. ``None``: the exact
        method reports its event times (plus 0 and ``t_end``), the others their own steps
        (at most ``budget.max_samples`` of them, a decimated record beyond; casadi its grid).
    budget : Budget, optional
        Wall-clock, step, event-rate and memory (``max_samples``) limits (default
        ``Budget()``): no method stores more than its budget allows, whatever ``t_end``.
    **options
        Method options (see the module docstring); unknown names are refused.

    Returns
    -------
    SimulationResult
        Always returned, also when a budget stops the run (see ``status``).

    Examples
    --------
    >>> from toolkit import ContactSet
    >>> plant = Plant(ContactSet([-1.0, 0.5, 2.0]), mass=1.0)
    >>> result = simulate(plant, 2.0)
    >>> float(result.V[-1])
    0.5
    """
    if not isinstance(plant, Plant):
        own = getattr(type(plant), "simulate", None)
        if callable(own):                # a plant of another kind (planar) simulates itself
            return own(plant, t_end, v0=v0, method=method, t_eval=t_eval, budget=budget, **options)
        raise ParameterTypeError(parameter_message("plant", "simulate", "be a Plant", plant))
    if not (type(t_end) is float and 0.0 < t_end < math.inf):
        t_end = as_float(t_end, "t_end", "simulate", low=0.0, low_open=True)
    if not (type(v0) is float and math.isfinite(v0)):
        v0 = as_float(v0, "v0", "simulate")
    if method not in _DISPATCH:
        check_option(method, "method", "simulate", METHODS)
    budget = _DEFAULT_BUDGET if budget is None else budget
    if not isinstance(budget, Budget):
        raise ParameterTypeError(parameter_message("budget", "simulate", "be a Budget", budget))
    if method != "moreau" and plant.motors is not None and plant.motors.backlash > 0:
        refuse_backlash(plant, f"simulate(method={method!r})")
    module, function, fixed, accepted = _DISPATCH[method]
    for name in options:
        if name not in accepted:
            rule = (f"only name the options {list(accepted)} of method {method!r}" if accepted
                    else f"be empty: method {method!r} takes no options")
            raise ParameterError(parameter_message("options", "simulate", rule, name)
                                 + suggestion(name, accepted))
    fn = _LOADED.get(method)
    if fn is None:                       # import the method's module on first use only
        fn = _LOADED[method] = getattr(importlib.import_module(f"{__name__}.{module}"), function)
    times = None if t_eval is None else _check_t_eval(t_eval, t_end)
    if fixed or options:
        return fn(plant, t_end, v0=v0, t_eval=times, budget=budget, **fixed, **options)
    return fn(plant, t_end, v0=v0, t_eval=times, budget=budget)
