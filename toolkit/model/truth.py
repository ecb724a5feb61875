"""Truth and belief: how a simulated world departs from the nominal scene that the estimators
are told (:class:`WorldTruth`), and what an estimator believes beyond that scene
(:class:`ModelPrior`: the prior of what the adaptive filter identifies online).

A scene describes a plant and its encoders; an estimator is built from that description (the
nominal model) and from what the user declares as prior knowledge. The world the records come
from may differ: :class:`WorldTruth` says how (unequal wheels, bearing drag, another motor lag,
motors that wander about their commands, noisy, missing or late encoder reads), every random
part drawn reproducibly from a seed. :func:`realize` turns a nominal :class:`Plant` and
:class:`Sensors` into the true ones (and the motors' wander) for an open- or closed-loop run.
Estimators never read a :class:`TrueWorld`; only simulations and scores do (docs/physics.md
section 10).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import as_float, as_int
from ..errors import ParameterError, ParameterTypeError, parameter_message
from .contacts import ContactSet, unequal_loads
from .motors import Motors
from .plant import Plant
from .sensors import Sensors

__all__ = ["WorldTruth", "TrueWorld", "realize", "seed_streams", "GRID_STREAM", "ModelPrior", "DEFAULT_DRAG", "DEFAULT_LAG",
           "DEFAULT_DRIFT", "DEFAULT_MISSED", "MAX_MISSED_MEAN"]

#: Sub-streams of one seed (``numpy.random.default_rng([seed, stream])``): the wheels' friction
#: draw (the stream scenes used before, so a scene's draw is unchanged), the motors' wander and
#: where the encoders' count grids start (:func:`toolkit.analysis.scenarios.grid_positions`).
#: The sensors draw from ``default_rng(seed)`` itself (missed counts, read noise, jitter).
FRICTION_STREAM, WANDER_STREAM, GRID_STREAM = 1, 2, 3


def seed_streams(seed: Any, owner: str) -> int:
    """``seed`` checked as a non-negative integer (the template error naming it)."""
    return as_int(seed, "seed", owner, low=0)


@dataclass(frozen=True)
class WorldTruth:
    """How the simulated world differs from the nominal scene.

    Parameters
    ----------
    friction_spread : float
        Relative standard deviation of each wheel's true friction magnitude around the
        nominal one, ``>= 0`` (lognormal, mean kept: :func:`~toolkit.model.unequal_loads`).
    drag : float or None, N s/m
        The true bearing drag ``c >= 0``; ``None``: the nominal scene's.
    lag : float or None, s
        The true motor lag ``tau >= 0``; ``None``: the nominal scene's.
    contact_drift : float, m/s per sqrt(s)
        Each motor's speed wanders about its command as an independent random walk of this
        intensity, ``>= 0`` (a step of ``contact_drift sqrt(h)`` per sample period ``h``,
        held over the period and followed through the motor lag).
    read_noise : float, counts
        Standard deviation of an additive read noise on every encoder, rounded to whole
        counts, ``>= 0`` (:class:`~toolkit.model.sensors.Sensors` ``count_noise``).
    missed_count_prob : float
        Probability in ``[0, 1]`` that a counter misses one count transition, for good.
    jitter : float, s
        Standard deviation of the sample-time jitter, ``>= 0``.
    """

    friction_spread: float = 0.0
    drag: float | None = None
    lag: float | None = None
    contact_drift: float = 0.0
    read_noise: float = 0.0
    missed_count_prob: float = 0.0
    jitter: float = 0.0

    def __post_init__(self) -> None:
        owner = "WorldTruth"
        for name in ("friction_spread", "contact_drift", "read_noise", "jitter"):
            object.__setattr__(self, name, as_float(getattr(self, name), name, owner, low=0.0))
        object.__setattr__(self, "missed_count_prob", as_float(
            self.missed_count_prob, "missed_count_prob", owner, low=0.0, high=1.0))
        for name in ("drag", "lag"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, as_float(value, name, owner, low=0.0))
        if self.lag is not None and self.lag > 0 and not math.isfinite(1.0 / self.lag):
            as_float(math.inf, "lag", owner)        # refuses with the template message

    @property
    def is_nominal(self) -> bool:
        """True when the world is the nominal scene itself (nothing departs)."""
        return (self.friction_spread == 0.0 and self.drag is None and self.lag is None
                and self.contact_drift == 0.0 and self.read_noise == 0.0
                and self.missed_count_prob == 0.0 and self.jitter == 0.0)

    def describe(self) -> str:
        """The departures in words with their units (``"nominal"`` when none)."""
        parts = []
        if self.friction_spread:
            parts.append(f"friction spread {self.friction_spread:.0%}")
        if self.drag is not None:
            parts.append(f"drag {self.drag:g} N s/m")
        if self.lag is not None:
            parts.append(f"lag {self.lag * 1e3:g} ms")
        if self.contact_drift:
            parts.append(f"contact drift {self.contact_drift * 1e3:g} mm/s/sqrt(s)")
        if self.read_noise:
            parts.append(f"read noise {self.read_noise:g} count")
        if self.missed_count_prob:
            parts.append(f"missed counts {self.missed_count_prob:g}")
        if self.jitter:
            parts.append(f"jitter {self.jitter * 1e3:g} ms")
        return ", ".join(parts) if parts else "nominal"

    # -- the true objects ------------------------------------------------------------------
    def plant(self, nominal: Plant, seed: int = 0) -> Plant:
        """The true plant: ``nominal`` with the drawn friction magnitudes, drag and lag."""
        owner = "WorldTruth.plant"
        if not isinstance(nominal, Plant):
            raise ParameterTypeError(parameter_message("nominal", owner, "be a Plant", nominal))
        seed = seed_streams(seed, owner)
        contacts = nominal.contacts
        if self.friction_spread > 0:
            rng = np.random.default_rng([seed, FRICTION_STREAM])
            contacts = ContactSet(contacts.speeds, unequal_loads(contacts.forces, self.friction_spread,
                                                                 contacts.n, rng))
        motors = nominal.motors
        if self.lag is not None:
            motors = replace(motors, lag=self.lag) if motors is not None else Motors(lag=self.lag)
        damping = nominal.damping if self.drag is None else self.drag
        return replace(nominal, contacts=contacts, motors=motors, damping=damping)

    def sensors(self, nominal: Sensors) -> Sensors:
        """The true encoders: ``nominal`` with this world's read noise, missed counts and jitter
        (each replacing the nominal figure when this world sets it)."""
        if not isinstance(nominal, Sensors):
            raise ParameterTypeError(parameter_message("nominal", "WorldTruth.sensors", "be a Sensors",
                                                       nominal))
        return replace(nominal,
                       count_noise=self.read_noise or nominal.count_noise,
                       missed_count_prob=self.missed_count_prob or nominal.missed_count_prob,
                       jitter=self.jitter or nominal.jitter)

    def wander(self, samples: int, n: int, period: float, seed: int = 0) -> np.ndarray | None:
        """The motors' wander about their commands at each sample, m/s, shape (samples, n).

        Row ``k`` is held from sample ``k`` to ``k + 1``; row 0 is zero (the motors start on
        their commands). ``None`` without drift.
        """
        owner = "WorldTruth.wander"
        samples = as_int(samples, "samples", owner, low=1)
        n = as_int(n, "n", owner, low=1)
        period = as_float(period, "period", owner, low=0.0, low_open=True)
        if self.contact_drift == 0.0:
            return None
        rng = np.random.default_rng([seed_streams(seed, owner), WANDER_STREAM])
        steps = rng.standard_normal((samples, n)) * (self.contact_drift * math.sqrt(period))
        steps[0] = 0.0
        return np.cumsum(steps, axis=0)


@dataclass(frozen=True, eq=False)
class TrueWorld:
    """The true plant and encoders of a run and the motors' wander (simulation only).

    Attributes
    ----------
    plant : Plant
    sensors : Sensors
    truth : WorldTruth
    seed : int
    """

    plant: Plant
    sensors: Sensors
    truth: WorldTruth
    seed: int

    def wander(self, samples: int) -> np.ndarray | None:
        """:meth:`WorldTruth.wander` over ``samples`` samples at the sensors' rate."""
        return self.truth.wander(samples, self.plant.n, self.sensors.period, self.seed)


def realize(plant: Plant, sensors: Sensors, truth: WorldTruth | None = None, seed: int = 0) -> TrueWorld:
    """The true world of a nominal ``plant`` and ``sensors`` under ``truth``, drawn from ``seed``.

    Parameters
    ----------
    plant : Plant
        The nominal plant (what the scene declares and the estimators are told).
    sensors : Sensors
        The nominal encoders.
    truth : WorldTruth, optional
        How the world departs (default: not at all).
    seed : int
        Draws the wheels' friction and the motors' wander (``default_rng([seed, 1])`` and
        ``[seed, 2]``); the sensors' own draws use ``default_rng(seed)``.
    """
    owner = "realize"
    truth = WorldTruth() if truth is None else truth
    if not isinstance(truth, WorldTruth):
        raise ParameterTypeError(parameter_message("truth", owner, "be a WorldTruth or None", truth))
    if not isinstance(sensors, Sensors):
        raise ParameterTypeError(parameter_message("sensors", owner, "be a Sensors", sensors))
    seed = seed_streams(seed, owner)
    return TrueWorld(truth.plant(plant, seed), truth.sensors(sensors), truth, seed)


# -- belief -----------------------------------------------------------------------------------


def _range(value: Any, name: str, owner: str, high: float = math.inf) -> tuple[float, float] | None:
    if value is None:
        return None
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
        raise ParameterTypeError(parameter_message(name, owner, "be a pair (low, high) or None", value))
    lo = as_float(value[0], name, owner, low=0.0, high=high)
    hi = as_float(value[1], name, owner, low=0.0, high=high)
    if not lo <= hi:
        raise ParameterError(parameter_message(name, owner, "satisfy low <= high", value))
    return lo, hi


@dataclass(frozen=True)
class ModelPrior:
    """The estimator's prior knowledge of how the plant departs from the nominal scene.

    Parameters
    ----------
    friction_spread : float
        Prior relative standard deviation of each wheel's friction magnitude about the
        nominal one, ``>= 0`` (the wheels of a real carousel differ: the default 0.3 covers
        the paper's residual friction). 0 trusts the nominal magnitudes.
    drag_range : tuple of 2 floats or None, N s/m
        The bearing drag lies in ``[low, high]`` (uniform prior); ``None``: the nominal
        scene's drag up to that plus ``DEFAULT_DRAG``.
    lag_range : tuple of 2 floats or None, s
        The motor lag lies in ``[low, high]``; the estimator identifies it from the wheel
        counts after each command change. ``None``: 0 to ``DEFAULT_LAG`` (or the nominal
        lag, if larger).
    contact_drift : float or None, m/s per sqrt(s)
        Prior intensity of the motors' speed wander (a random walk about the command);
        ``None``: ``DEFAULT_DRIFT``; the filter adapts it from the wheel counts.
    missed_count_prob : float
        The central encoder misses each count transition with this probability, in
        ``[0, 0.5]`` (default 0: not expected); the default ``kalman`` then reports the
        position with the count offset's mean and variance (docs/physics.md section 10).
    missed_count_mean : float or None
        Not told the rate (``missed_count_prob`` 0), the prior mean of the rate the default
        ``kalman`` identifies online, in ``(0, 0.01]`` (its prior std is ``sqrt(2)`` times it:
        :class:`toolkit.estimation.MissedCountRate`); ``None``: ``DEFAULT_MISSED``.
    """

    friction_spread: float = 0.3
    drag_range: tuple[float, float] | None = None
    lag_range: tuple[float, float] | None = None
    contact_drift: float | None = None
    missed_count_prob: float = 0.0
    missed_count_mean: float | None = None

    def __post_init__(self) -> None:
        owner = "ModelPrior"
        if self.missed_count_mean is not None:
            object.__setattr__(self, "missed_count_mean", as_float(
                self.missed_count_mean, "missed_count_mean", owner, low=0.0, high=MAX_MISSED_MEAN, low_open=True))
        object.__setattr__(self, "missed_count_prob", as_float(self.missed_count_prob, "missed_count_prob", owner,
                                                               low=0.0, high=0.5))
        object.__setattr__(self, "friction_spread", as_float(self.friction_spread, "friction_spread", owner,
                                                             low=0.0, high=10.0))
        object.__setattr__(self, "drag_range", _range(self.drag_range, "drag_range", owner))
        object.__setattr__(self, "lag_range", _range(self.lag_range, "lag_range", owner, high=10.0))
        if self.contact_drift is not None:
            object.__setattr__(self, "contact_drift", as_float(self.contact_drift, "contact_drift", owner,
                                                               low=0.0))


#: Default width of the drag prior above the nominal drag, N s/m.
DEFAULT_DRAG = 2.0
#: Default upper end of the motor-lag prior, s.
DEFAULT_LAG = 0.05
#: Default prior intensity of the motors' wander, m/s per sqrt(s).
DEFAULT_DRIFT = 1e-4
#: Default prior mean of the encoders' missed-count rate when it is not told (per count
#: transition; the prior's std is sqrt(2) times it: :class:`toolkit.estimation.MissedCountRate`).
DEFAULT_MISSED = 1e-3
#: Largest prior mean of an untold missed-count rate: the top of the grid of rates the ridden
#: wheel's check weighs (:class:`toolkit.estimation.MissedCountRate`).
MAX_MISSED_MEAN = 1e-2
