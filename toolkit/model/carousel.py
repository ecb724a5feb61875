"""The paper's reference carousel: its hardware constants and the startup scene built on them.

The values are those of docs/physics.md section 5 and of the scene files ``designs/carousel.toml``
and ``designs/startup11.toml`` (Shah & Gravish, arXiv 2501.09746): wheels of radius 0.045 m
touching the ground 0.266 m from the axis, 48-count motor encoders behind a 74.83:1 gearbox
(3591.84 counts per wheel turn), an 8192-count central encoder, 50 Hz sampling and commands,
contact speeds within +-0.35 m/s, and ``F_tot / m = 2 m/s^2`` (the paper's transition time,
docs/physics.md section 6). The non-idealities (the motors' lag, the gearbox backlash) are
read from :data:`toolkit.model.parameters.PARAMETERS`, their one source.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import as_float, as_int
from .contacts import ContactSet
from .motors import Motors
from .parameters import PARAMETERS
from .plant import Plant
from .sensors import Encoder, Sensors

__all__ = ["CarouselHardware", "CAROUSEL", "CAROUSEL_ACCELERATION", "CAROUSEL_SPEED_LIMIT",
           "carousel_startup_plant"]


@dataclass(frozen=True)
class CarouselHardware:
    """Constants of the paper's carousel (SI units).

    Attributes
    ----------
    contact_radius : float, m
        Centre to contact ``L``.
    wheel_radius : float, m
    wheel_counts_per_rev : float
        Wheel encoder counts per wheel turn (48 CPR x 74.83:1).
    wheel_backlash : float, m
        Gearbox backlash at the contact.
    central_counts_per_rev : float
        Central (AMT103-V) encoder counts per carousel turn.
    rate : float, Hz
        Sampling rate of every encoder and of the motor commands.
    speed_limit : float, m/s
        ``v_max``: contact speeds within ``[-v_max, v_max]``.
    motor_lag : float, s
        First-order time constant of the motors (settle to 2 %, ``4 tau``, in ~30 ms).
    acceleration : float, m/s^2
        ``F_tot / m``, fitted to ``dT = 0.35 s`` for ``2 v_max = 0.7 m/s``.
    n_wheels : int
        Contacts (wheels on hinged spokes, equal normal load).
    wheel_force : float, N
        Friction magnitude of one wheel. The paper gives neither it nor the inertia: only
        ``F_tot / m`` matters without drag, and 1 N per wheel is the reference scenes'
        choice of units.
    inertia : float, kg m^2
        Moving inertia about the axis, chosen (6 digits) so that ``m = I / L^2`` = 5 kg gives
        ``F_tot / m`` = 2 m/s^2 with ``wheel_force``.
    """

    contact_radius: float = 0.266
    wheel_radius: float = 0.045
    wheel_counts_per_rev: float = 3591.84
    wheel_backlash: float = PARAMETERS["wheel_backlash"].value
    central_counts_per_rev: float = 8192.0
    rate: float = 50.0
    speed_limit: float = 0.35
    motor_lag: float = PARAMETERS["motor_lag"].value
    acceleration: float = PARAMETERS["acceleration"].value
    n_wheels: int = 10
    wheel_force: float = 1.0
    inertia: float = 0.353780

    @property
    def moving_mass(self) -> float:
        """Moving inertia at the contacts, kg: ``inertia / contact_radius**2`` (5.000 kg)."""
        return self.inertia / self.contact_radius**2

    def motors(self) -> Motors:
        """The motors: lag ``motor_lag``, commands clipped to ``+-`` :attr:`speed_limit`."""
        return Motors(lag=self.motor_lag, speed_limits=(-self.speed_limit, self.speed_limit))

    def sensors(self, n_wheels: int | None = None, **noise: float) -> Sensors:
        """The encoders (the central one, one per wheel) sampled at ``rate``; ``noise``
        takes :class:`~toolkit.model.sensors.Sensors`' ``missed_count_prob``, ``count_noise``
        and ``jitter``."""
        return Sensors(Encoder(self.central_counts_per_rev, self.contact_radius, self.rate),
                       Encoder(self.wheel_counts_per_rev, self.wheel_radius, self.rate, self.wheel_backlash),
                       self.n_wheels if n_wheels is None else n_wheels, **noise)


#: The paper's carousel.
CAROUSEL = CarouselHardware()
#: ``F_tot / m`` of the reference carousel, m/s^2 (docs/physics.md section 6).
CAROUSEL_ACCELERATION = CAROUSEL.acceleration
#: Contact speed limit ``v_max`` of the reference carousel, m/s (docs/physics.md section 5).
CAROUSEL_SPEED_LIMIT = CAROUSEL.speed_limit


def carousel_startup_plant(seed: int = 0, *, n: int = 11, mass: float = 1.0) -> Plant:
    """The carousel startup scene of the work-precision comparison: ``n`` random speeds, equal loads, from rest.

    Speeds are uniform in ``[-v_max, v_max]`` with ``v_max = 0.35`` m/s; the contacts carry
    equal magnitudes with ``F_tot / m = 2`` m/s^2 (the paper's transition time, docs/physics.md
    section 6). Without drag or external force the motion depends on ``F_tot / m`` only, so
    ``mass`` just sets the units of the forces. Ideal motors (add
    ``motors=CAROUSEL.motors()`` with :func:`dataclasses.replace` for the lag).

    Parameters
    ----------
    seed : int
        Seed of ``numpy.random.default_rng``.
    n : int
        Number of contacts, ``>= 1``.
    mass : float, kg
        Moving inertia, ``> 0``.

    Returns
    -------
    Plant
    """
    seed = as_int(seed, "seed", "carousel_startup_plant", low=0)
    n = as_int(n, "n", "carousel_startup_plant", low=1)
    mass = as_float(mass, "mass", "carousel_startup_plant", low=0.0, low_open=True)
    rng = np.random.default_rng(seed)
    speeds = rng.uniform(-CAROUSEL_SPEED_LIMIT, CAROUSEL_SPEED_LIMIT, n)
    forces = np.full(n, CAROUSEL_ACCELERATION * mass / n)
    return Plant(ContactSet(speeds, forces), mass=mass)
