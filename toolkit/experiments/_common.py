"""What the paper's experiments share (private): the carousel's wheels drawn in one fixed
order, the settled tolerance, bounds on sizes and the "simulate or raise" step.

One carousel per ``wheel_seed``
-------------------------------
:func:`carousel_wheels` draws a carousel's wheels from one generator in a fixed order: first
``n`` standard normals for the wheels' radius errors (always drawn, even when
``radius_std = 0``), then the ``n`` friction magnitudes (:func:`toolkit.model.unequal_loads`,
which draws ``n`` normals when ``spread > 0``). Every experiment that takes a ``wheel_seed``
builds its wheels with ``carousel_wheels(numpy.random.default_rng(wheel_seed), ...)``, so one
``wheel_seed`` (with the same ``n``, ``friction_spread`` and mean load) is one carousel in all
four experiments. Without a ``wheel_seed`` each run draws its own carousel from streams of
its own (:class:`toolkit.sweeps.RunKeys`: :data:`STREAM_RADIUS` and :data:`STREAM_LOADS`,
independent of the run's speeds, :data:`STREAM_RUN`), all runs of a chunk at once.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ..errors import as_float, as_int
from ..errors import ParameterError, SolverError, parameter_message
from ..model import unequal_loads

#: A run counts as settled when its speed changed by at most this over the checked
#: interval, m/s (exact simulation: a settled body's speed does not change at all).
SETTLED_TOLERANCE = 1e-9
#: The random streams of a run (:class:`toolkit.sweeps.RunKeys`): its own scene (speeds,
#: amplitudes ...), its carousel's wheel radius errors, its carousel's loads.
STREAM_RUN, STREAM_RADIUS, STREAM_LOADS = 0, 1, 2
#: Most contacts one run may have.
MAX_CONTACTS = 10_000
#: Most samples (command steps, probe speeds) one run may build.
MAX_SAMPLES = 10_000_000
#: Largest relative spread of the wheels' friction (a lognormal with sigma = 2.15).
MAX_SPREAD = 10.0
#: Largest speed limit, m/s (far above any carousel; keeps products of speeds finite).
MAX_SPEED = 1e3
#: Largest ``F_tot / m``, m/s^2, mass (kg), drag (N s/m) and observation time (s).
MAX_ACCELERATION, MAX_MASS, MAX_DAMPING, MAX_TIME = 1e6, 1e9, 1e9, 1e6


def setter(obj: Any) -> Callable[[str, Any], None]:
    """``set_(key, value)`` for a frozen dataclass's ``__post_init__``."""
    return lambda key, value: object.__setattr__(obj, key, value)


def as_count(value: Any, name: str, owner: str, *, low: int, high: int) -> int:
    """An integer in ``[low, high]``, the error naming ``name`` and the rule."""
    result = as_int(value, name, owner, low=low)
    if result > high:
        raise ParameterError(parameter_message(name, owner, f"be <= {high}", value))
    return result


def check_common(obj: Any, owner: str, *, positive: tuple[str, ...] = (), nonneg: tuple[str, ...] = ()) -> None:
    """Check and store the usual physical parameters by name, each within its bound:
    ``speed_limit`` <= :data:`MAX_SPEED`, ``acceleration``, ``mass``, ``damping``/``bearing_drag``,
    ``settle_time``/``window``, ``friction_spread`` <= :data:`MAX_SPREAD`; other names unbounded
    above (finite)."""
    highs = {"speed_limit": MAX_SPEED, "acceleration": MAX_ACCELERATION, "mass": MAX_MASS,
             "damping": MAX_DAMPING, "bearing_drag": MAX_DAMPING, "settle_time": MAX_TIME,
             "window": MAX_TIME, "friction_spread": MAX_SPREAD}
    set_ = setter(obj)
    for key in positive:
        set_(key, as_float(getattr(obj, key), key, owner, low=0.0, low_open=True, high=highs.get(key)))
    for key in nonneg:
        set_(key, as_float(getattr(obj, key), key, owner, low=0.0, high=highs.get(key)))
    if getattr(obj, "wheel_seed", None) is not None:
        set_("wheel_seed", as_count(obj.wheel_seed, "wheel_seed", owner, low=0, high=2**63 - 1))


def check_compliance(obj: Any, owner: str, load: float) -> None:
    """``compliance`` ``k >= 0`` with the droop ``k f`` at most the speed limit (``load`` =
    the mean wheel load ``f``, N): a larger droop would leave no contact speed."""
    value = as_float(obj.compliance, "compliance", owner, low=0.0)
    if value * load > obj.speed_limit:
        raise ParameterError(parameter_message(
            "compliance", owner, f"droop a wheel by at most the speed limit: compliance * f <= "
            f"speed_limit, so <= {obj.speed_limit / load:g} (m/s)/N at f = {load:g} N", value))
    object.__setattr__(obj, "compliance", value)


def carousel_wheels(rng: np.random.Generator, n: int, mean_load: float, friction_spread: float = 0.0,
                    radius_std: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """One carousel's wheels, drawn in the fixed order of the module docstring.

    Parameters
    ----------
    rng : numpy.random.Generator
    n : int
        Wheels.
    mean_load : float, N
        Mean friction magnitude per wheel.
    friction_spread : float
        Relative std of each wheel's friction (lognormal, :func:`toolkit.model.unequal_loads`).
    radius_std : float
        Relative std of each wheel's radius.

    Returns
    -------
    radius_error : ndarray of shape (n,)
        Each wheel's relative radius error ``radius_std * z_i``.
    loads : ndarray of shape (n,), N
    """
    radius_error = radius_std * rng.standard_normal(n)
    return radius_error, unequal_loads(mean_load, friction_spread, n, rng)


def wheels_for_runs(keys: Any, wheel_seed: int | None, n: int, mean_load: float,
                    friction_spread: float = 0.0, radius_std: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Radius errors and loads of each run of ``keys`` (:class:`toolkit.sweeps.RunKeys`),
    shape (runs, n) each: one carousel (``wheel_seed``) for every run, or each run its own,
    from its streams :data:`STREAM_RADIUS` (``radius_std`` times standard normals) and
    :data:`STREAM_LOADS` (the lognormal loads of :func:`toolkit.model.unequal_loads`)."""
    runs = len(keys)
    if wheel_seed is not None:
        radius, loads = carousel_wheels(np.random.default_rng(wheel_seed), n, mean_load, friction_spread,
                                        radius_std)
        return np.tile(radius, (runs, 1)), np.tile(loads, (runs, 1))
    radius = (radius_std * keys.normal(STREAM_RADIUS, n) if radius_std > 0.0
              else np.zeros((runs, n)))
    loads = (unequal_loads(mean_load, friction_spread, n, normals=keys.normal(STREAM_LOADS, n))
             if friction_spread > 0.0 else np.full((runs, n), float(mean_load)))
    return radius, loads


def simulate_or_raise(plant: Any, t_end: float, what: str, **options: Any) -> Any:
    """:func:`toolkit.simulate` that raises :class:`~toolkit.errors.SolverError` (naming
    ``what``, e.g. the run) unless the run succeeded."""
    from ..simulation import SimulationStatus, simulate

    result = simulate(plant, t_end, **options)
    if result.status is not SimulationStatus.SUCCESS:
        raise SolverError(f"{what}: {result.message}")
    return result
