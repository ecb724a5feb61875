"""The median law (the paper's Fig. 3b): steady speed against the median of random speeds.

Each run draws ``n`` contact speeds uniformly in ``[-v_max, v_max]``, starts the body from
rest and lets it settle; the row holds the numpy median, the settled speed and their ratio.
:class:`MedianLaw` takes the non-idealities as physical parameters (0 = ideal): unequal
wheels, bearing drag, wheel-radius errors, a contact-radius error, motor compliance. The
ideal model's slope and each parameter's meaning: docs/methods.md."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..errors import as_float
from ..errors import ParameterError, parameter_message
from ..model import ContactSet, Motors, Plant
from ..simulation import simulate_batch
from ..sweeps import RunKeys
from ._common import (MAX_CONTACTS, MAX_TIME, SETTLED_TOLERANCE, STREAM_RUN, as_count, check_common,
                      check_compliance, setter, simulate_or_raise, wheels_for_runs)

__all__ = ["MedianLaw", "median_law_slope", "ideal_median_law_slope"]

_OWNER = "MedianLaw"


def median_law_slope(median: Any, speed: Any) -> tuple[float, float]:
    """Least-squares slope of ``speed = slope * median`` through the origin, and its
    standard error (the paper's fit ``y = m x``).

    Parameters
    ----------
    median, speed : array_like of shape (k,), m/s

    Returns
    -------
    slope, stderr : float
        ``slope = sum(x y) / sum(x^2)``; ``stderr = sqrt(sum(r^2) / (k - 1) / sum(x^2))``.
    """
    x, y = np.asarray(median, dtype=float), np.asarray(speed, dtype=float)
    sxx = float(x @ x)
    if x.size < 2 or sxx == 0.0:
        return math.nan, math.nan
    slope = float(x @ y) / sxx
    r = y - slope * x
    return slope, math.sqrt(float(r @ r) / (x.size - 1) / sxx)


def ideal_median_law_slope(n: int = 10) -> float:
    """Population value of the ideal model's median-law slope: the limit of
    :func:`median_law_slope` over infinitely many runs of :class:`MedianLaw` with equal
    loads, ideal motors and no drag (any ``speed_limit``: the slope does not depend on it).

    For even ``n`` the body from rest stops at ``y = clip(0, a, b)`` with ``a = v_(n/2)``,
    ``b = v_(n/2+1)`` the middle order statistics of ``n`` uniform speeds, and
    ``numpy.median`` is ``x = (a + b) / 2``; the least-squares slope through the origin tends
    to ``E[x y] / E[x^2]``, computed here by two-dimensional quadrature of the joint density
    of ``(a, b)`` on ``[-1, 1]``: ``n! / ((k-1)! (n-k-1)!) F(a)^(k-1) (1 - F(b))^(n-k-1) / 4``
    with ``k = n/2`` and ``F(u) = (1 + u) / 2`` (relative error about 1e-10). For odd ``n`` the
    body stops at the median contact: 1.

    Parameters
    ----------
    n : int
        Contacts per run, ``>= 1``.

    Returns
    -------
    float
    """
    n = as_count(n, "n", "ideal_median_law_slope", low=1, high=MAX_CONTACTS)
    if n % 2:
        return 1.0
    from scipy.integrate import dblquad   # only for this number

    k = n // 2
    log_c = math.lgamma(n + 1) - math.lgamma(k) - math.lgamma(n - k)

    def density(b: float, a: float) -> float:
        return math.exp(log_c) * ((1 + a) / 2) ** (k - 1) * ((1 - b) / 2) ** (n - k - 1) / 4

    opts = {"epsabs": 1e-14, "epsrel": 1e-12}
    exx = dblquad(lambda b, a: ((a + b) / 2) ** 2 * density(b, a), -1, 1, lambda a: a, 1, **opts)[0]
    # y = a where a > 0, y = b where b < 0 (the mirror image, same contribution), 0 otherwise
    exy = 2 * dblquad(lambda b, a: (a + b) / 2 * a * density(b, a), 0, 1, lambda a: a, 1, **opts)[0]
    return exy / exx


@dataclass(frozen=True)
class MedianLaw:
    """The median-law experiment (see the module docstring for every parameter).

    Parameters
    ----------
    n : int
        Contacts per run (the paper: 10).
    speed_limit : float, m/s
        Speeds uniform in ``[-speed_limit, speed_limit]`` (the paper's ``v_max = 0.35``).
    acceleration : float, m/s^2
        ``F_tot / m`` (the carousel: 2).
    mass : float, kg
        Moving inertia (sets the force units and, with ``damping``, the drag time constant).
    friction_spread, damping, wheel_radius_bias, wheel_radius_std, contact_radius_error,
    compliance : float
        Non-idealities (module docstring), default 0.
    wheel_seed : int, optional
        Draw the wheels' loads (``friction_spread``) and radius errors (``wheel_radius_std``)
        once from this seed: one carousel for every run.
    settle_time : float, s, optional
        Observation time of each run from rest (default 20 s, a hundred times the ideal
        carousel's longest startup ``2 v_max / (F_tot/m)``). Unequal loads can leave a tiny
        net force, so a run may still move at the end: the ``settled`` column says whether
        the speed changed by more than :data:`SETTLED_TOLERANCE` over the second half.
    """

    n: int = 10
    speed_limit: float = 0.35
    acceleration: float = 2.0
    mass: float = 1.0
    friction_spread: float = 0.0
    damping: float = 0.0
    wheel_radius_bias: float = 0.0
    wheel_radius_std: float = 0.0
    contact_radius_error: float = 0.0
    compliance: float = 0.0
    settle_time: float | None = None
    wheel_seed: int | None = None
    #: The ``experiment`` key of a scene's ``[sweep]``.
    name: ClassVar[str] = "median_law"
    #: Names of :meth:`summarize`'s statistics.
    STATISTICS: ClassVar[tuple[str, ...]] = ("slope", "slope_stderr", "ratio_median", "ratio_iqr",
                                             "settled_fraction")

    def __post_init__(self) -> None:
        set_ = setter(self)
        set_("n", as_count(self.n, "n", _OWNER, low=1, high=MAX_CONTACTS))
        check_common(self, _OWNER, positive=("speed_limit", "acceleration", "mass"),
                     nonneg=("friction_spread", "damping"))
        set_("wheel_radius_std", as_float(self.wheel_radius_std, "wheel_radius_std", _OWNER, low=0.0))
        if not self.wheel_radius_std < 0.5:
            raise ParameterError(parameter_message(
                "wheel_radius_std", _OWNER, "be < 0.5 (a wheel two of its spreads short must still "
                "run forwards)", self.wheel_radius_std))
        for key in ("wheel_radius_bias", "contact_radius_error"):
            value = as_float(getattr(self, key), key, _OWNER)
            if not -0.5 < value < 0.5:
                raise ParameterError(parameter_message(key, _OWNER, "lie in (-0.5, 0.5)", value))
            set_(key, value)
        check_compliance(self, _OWNER, self.acceleration * self.mass / self.n)
        if self.settle_time is not None:
            set_("settle_time", as_float(self.settle_time, "settle_time", _OWNER, low=0.0, low_open=True,
                                         high=MAX_TIME))

    # -- one chunk ------------------------------------------------------------------------
    def draw(self, keys: RunKeys) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Commanded speeds (k, n), actual contact speeds (k, n) and friction magnitudes
        (k, n) of each run of ``keys``, all runs at once. The speeds come from each run's
        own stream; the wheels (radius errors and loads) from ``wheel_seed`` (one carousel,
        :func:`toolkit.experiments.carousel_wheels`, the same in every experiment) or from
        each run's carousel streams (:func:`~toolkit.experiments._common.wheels_for_runs`)."""
        n = self.n
        commanded = keys.uniform(STREAM_RUN, n, -self.speed_limit, self.speed_limit)
        radius, forces = wheels_for_runs(keys, self.wheel_seed, n, self.acceleration * self.mass / n,
                                         self.friction_spread, self.wheel_radius_std)
        actual = commanded * (1.0 + self.wheel_radius_bias + radius)
        return commanded, actual, forces

    def horizon(self) -> float:
        """Observation time of each run, s (``settle_time``, default 20 s)."""
        return 20.0 if self.settle_time is None else self.settle_time

    def run(self, keys: RunKeys) -> dict[str, np.ndarray]:
        """Columns ``median`` (numpy median of the commanded speeds, m/s), ``speed`` (the
        reported settled speed, m/s), ``true_speed`` (m/s), ``ratio`` (``speed / median``)
        and ``settled`` (speed steady over the second half of the run: the speed at half the
        horizon read from the same run's closed form, no second simulation)."""
        commanded, actual, forces = self.draw(keys)
        t_end = self.horizon()
        k = commanded.shape[0]
        if self.compliance == 0.0:
            batch = simulate_batch(actual, forces, self.mass, t_end, v0=0.0, damping=self.damping,
                                   t_probe=0.5 * t_end)
            half, final = batch.probe_speeds, batch.final_speeds
        else:
            half, final = np.empty(k), np.empty(k)
            motors = Motors(compliance=self.compliance)
            for j in range(k):
                plant = Plant(ContactSet(actual[j], forces[j]), self.mass, damping=self.damping,
                              motors=motors)
                result = simulate_or_raise(plant, t_end, f"MedianLaw {keys.label(j)}", v0=0.0,
                                           t_eval=[0.5 * t_end, t_end])
                half[j], final[j] = result.V
        settled = np.abs(final - half) <= SETTLED_TOLERANCE
        median = np.median(commanded, axis=1)
        reported = final / (1.0 + self.contact_radius_error)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = reported / median
        return {"median": median, "speed": reported, "true_speed": final, "ratio": ratio,
                "settled": settled}

    def release_rise(self, keys: RunKeys) -> np.ndarray:
        """Each motor's relative speed rise when the body, held at ``V = 0``, is released
        and settles (the paper's motor characterisation: every motor rose 4.6 +- 2.0 %).

        The wheel's surface speed on a compliant motor is ``w_i = u_i - k F_i`` with ``F_i``
        the contact force of the friction law (:func:`toolkit.model.friction.contact_forces`,
        saturated-linear of width ``k f_i``): held, ``F_i = f_i clip(u_i / (k f_i), -1, 1)``;
        released, the same at the slip ``u_i - V_end`` with ``V_end`` the exact simulation's
        settled speed. The rise is ``|w_released| / |w_held| - 1``: zero for a motor whose
        slip keeps its direction (its load is ``f_i`` before and after), ``2 k f_i / (|u_i| -
        k f_i)`` for one whose slip reverses, in between for one within ``k f_i`` of
        ``V_end``. So this model cannot give every motor the same rise.

        Returns
        -------
        ndarray of shape (runs, n)
            Relative rise of each motor (``nan`` where the held wheel speed is 0).
        """
        from ..model.friction import contact_forces

        _, actual, forces = self.draw(keys)
        k = self.compliance
        rise = np.empty_like(actual)
        motors = Motors(compliance=k) if k > 0 else None
        for j in range(len(keys)):
            plant = Plant(ContactSet(actual[j], forces[j]), self.mass, damping=self.damping, motors=motors)
            end = float(simulate_or_raise(plant, self.horizon(), f"MedianLaw {keys.label(j)}", v0=0.0).V[-1])
            held = actual[j] - k * contact_forces(actual[j], forces[j], compliance=k)
            released = actual[j] - k * contact_forces(actual[j] - end, forces[j], compliance=k)
            with np.errstate(divide="ignore", invalid="ignore"):
                rise[j] = np.where(held != 0.0, np.abs(released) / np.abs(held) - 1.0, math.nan)
        return rise

    def summarize(self, table: Any) -> dict[str, float]:
        """``slope`` and ``slope_stderr`` of speed against median through the origin (the
        paper's fit), ``ratio_median`` and ``ratio_iqr`` of ``speed / median`` (runs with
        ``|median| > 0.1 v_max``), ``settled_fraction``."""
        slope, stderr = median_law_slope(table["median"], table["speed"])
        keep = np.abs(table["median"].to_numpy()) > 0.1 * self.speed_limit
        ratio = table["ratio"].to_numpy()[keep]
        q1, q2, q3 = (np.percentile(ratio, [25, 50, 75]) if ratio.size else (math.nan,) * 3)
        return {"slope": slope, "slope_stderr": stderr, "ratio_median": float(q2),
                "ratio_iqr": float(q3 - q1), "settled_fraction": float(np.mean(table["settled"]))}
