"""Residual friction of a friction-fraction split (the paper's Fig. 6) with unequal wheels
and bearing losses.

``5 - n`` of ten contacts run at ``+v_max`` and ``5 + n`` at ``-v_max``. For a body inside
``(-v_max, v_max)`` the ideal net force is ``-(n/5) F_tot``: ``mu/mu0 = n/5``, so at ``n = 0``
friction vanishes (the paper measured a 91 +- 4 % reduction, not 100 %). Each run here draws
the wheels' friction magnitudes with a relative spread and adds the carousel's own losses:

- unequal wheels: ``f_i`` lognormal with mean ``f`` and relative std ``friction_spread``; the
  band force becomes ``sum_{+} f_i - sum_{-} f_i``, whose variance is ``friction_spread^2 *
  10 f^2`` at ``n = 0`` (the closed form the tests check against);
- bearing friction (Coulomb, N): a contact that never moves, speed 0, magnitude
  ``bearing_friction`` (the same friction law, so it is added to the :class:`ContactSet`);
- bearing drag ``c`` (N s/m): ``-c V``.

``mu_ratio`` is measured as the paper did, quasi-statically: the mean over the band of the
magnitude of the force a rig must apply to hold each speed, ``|F(V) - c V|``, divided by
the nominal ``F_tot = 10 f`` (``probe`` speeds evenly spread inside ``(-v_max, v_max)``).
``dT`` is the exact simulator's time from ``+v_max`` to ``-v_max`` (the body released at
``+v_max`` on this split), against ``dT_ideal = m 2 v_max / (F_tot n/5)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .._validation import as_float, as_int
from ..errors import ParameterError, SolverError, parameter_message
from ..model import ContactSet, Plant, unequal_loads
from ..simulation import SimulationStatus, simulate

__all__ = ["ResidualFriction"]

_OWNER = "ResidualFriction"


@dataclass(frozen=True)
class ResidualFriction:
    """Friction fraction with non-idealities (see the module docstring).

    Parameters
    ----------
    n : int
        Contacts reversed, ``0 .. 5`` (``5 - n`` at ``+v_max``, ``5 + n`` at ``-v_max``).
    friction_spread : float
        Relative std of each wheel's friction magnitude.
    bearing_friction : float, N
        Coulomb friction of the carousel's bearing.
    bearing_drag : float, N s/m
    speed_limit : float, m/s
    acceleration : float, m/s^2
        Nominal ``F_tot / m``.
    mass : float, kg
    probes : int
        Speeds at which the quasi-static force is read.
    """

    n: int = 0
    friction_spread: float = 0.0
    bearing_friction: float = 0.0
    bearing_drag: float = 0.0
    speed_limit: float = 0.35
    acceleration: float = 2.0
    mass: float = 1.0
    probes: int = 64
    name: str = "residual_friction"
    #: Names of :meth:`summarize`'s statistics.
    STATISTICS: ClassVar[tuple[str, ...]] = ("mu_ratio", "mu_ratio_std", "reduction", "dT_median")

    def __post_init__(self) -> None:
        set_ = lambda key, value: object.__setattr__(self, key, value)  # noqa: E731
        set_("n", as_int(self.n, "n", _OWNER, low=0))
        if self.n > 5:
            raise ParameterError(parameter_message("n", _OWNER, "be <= 5", self.n))
        for key in ("friction_spread", "bearing_friction", "bearing_drag"):
            set_(key, as_float(getattr(self, key), key, _OWNER, low=0.0))
        for key in ("speed_limit", "acceleration", "mass"):
            set_(key, as_float(getattr(self, key), key, _OWNER, low=0.0, low_open=True))
        set_("probes", as_int(self.probes, "probes", _OWNER, low=1))

    @property
    def nominal_force(self) -> float:
        """``F_tot = 10 f``, N."""
        return self.acceleration * self.mass

    def contacts(self, seed: np.random.SeedSequence) -> ContactSet:
        """The run's wheels (and the bearing as a contact at speed 0 when it has friction)."""
        rng = np.random.default_rng(seed)
        forces = unequal_loads(self.nominal_force / 10.0, self.friction_spread, 10, rng)
        v = self.speed_limit
        speeds = np.array([v] * (5 - self.n) + [-v] * (5 + self.n))
        if self.bearing_friction > 0:
            speeds, forces = np.append(speeds, 0.0), np.append(forces, self.bearing_friction)
        return ContactSet(speeds, forces)

    def run(self, seeds: list[np.random.SeedSequence]) -> dict[str, np.ndarray]:
        """Columns ``mu_ratio`` (quasi-static), ``band_force`` (net wheel force inside the
        band, N), ``dT`` and ``dT_ideal`` (s; ``inf`` where the body never reaches
        ``-v_max``)."""
        k = len(seeds)
        v = self.speed_limit
        probe = v * (2.0 * (np.arange(self.probes) + 0.5) / self.probes - 1.0)
        mu, band, dT = np.empty(k), np.empty(k), np.empty(k)
        ideal = (self.mass * 2.0 * v / (self.nominal_force * self.n / 5.0)) if self.n else math.inf
        for j, seq in enumerate(seeds):
            contacts = self.contacts(seq)
            wheels = ContactSet(contacts.speeds[:10], contacts.forces[:10])
            band[j] = float(wheels.force(0.0))
            rig = np.abs(contacts.force(probe) - self.bearing_drag * probe)
            mu[j] = float(rig.mean()) / self.nominal_force
            dT[j] = self._transition(contacts)
        return {"mu_ratio": mu, "band_force": band, "dT": dT, "dT_ideal": np.full(k, ideal)}

    def _transition(self, contacts: ContactSet) -> float:
        """Exact time from ``+v_max`` to ``-v_max``; ``inf`` if the body never gets there."""
        v = self.speed_limit
        down = -float(contacts.force(0.0)) - self.bearing_drag * v   # weakest downward force on the way
        if down <= 0.0:
            return math.inf
        result = simulate(Plant(contacts, self.mass, damping=self.bearing_drag),
                          4.0 * self.mass * 2.0 * v / down, v0=v)
        if result.status is not SimulationStatus.SUCCESS:
            raise SolverError(f"ResidualFriction transition: {result.message}")
        # The body lands on the contacts at -v_max exactly (an event at that speed).
        reached = [event.time for event in result.events if event.speed <= -v]
        return float(reached[0]) if reached else math.inf

    def summarize(self, table: Any) -> dict[str, float]:
        """``mu_ratio`` mean and std, ``reduction`` (``1 - mu_ratio`` mean) and ``dT`` median."""
        mu = table["mu_ratio"].to_numpy()
        return {"mu_ratio": float(mu.mean()), "mu_ratio_std": float(mu.std(ddof=1)) if mu.size > 1 else 0.0,
                "reduction": float(1.0 - mu.mean()), "dT_median": float(np.median(table["dT"]))}
