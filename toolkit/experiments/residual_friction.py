"""Residual friction of a friction-fraction split (the paper's Fig. 6) with unequal wheels
and bearing losses.

``5 - n`` of ten contacts at ``+v_max`` and ``5 + n`` at ``-v_max``; each run draws the
wheels' magnitudes with a spread and adds a bearing's friction and drag, reads ``mu/mu0`` as
the paper's rig did, and times the transition ``dT``. What each loss does to the reading,
with the closed forms the tests check: docs/methods.md."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..model import ContactSet, Plant
from ..sweeps import RunKeys
from ._common import MAX_SAMPLES, as_count, check_common, setter, simulate_or_raise, wheels_for_runs

__all__ = ["ResidualFriction"]

_OWNER = "ResidualFriction"
#: Most probe speeds (each reads the force of every contact).
MAX_PROBES = MAX_SAMPLES // 10


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
        Speeds at which the quasi-static force is read, ``1 .. MAX_PROBES``.
    wheel_seed : int, optional
        Draw the wheels once from this seed (one carousel, the same as every experiment's
        with that seed); otherwise each run draws its own.
    """

    n: int = 0
    friction_spread: float = 0.0
    bearing_friction: float = 0.0
    bearing_drag: float = 0.0
    speed_limit: float = 0.35
    acceleration: float = 2.0
    mass: float = 1.0
    probes: int = 64
    wheel_seed: int | None = None
    #: The ``experiment`` key of a scene's ``[sweep]``.
    name: ClassVar[str] = "residual_friction"
    #: Names of :meth:`summarize`'s statistics.
    STATISTICS: ClassVar[tuple[str, ...]] = ("mu_ratio", "mu_ratio_std", "reduction", "dT_median")

    def __post_init__(self) -> None:
        set_ = setter(self)
        set_("n", as_count(self.n, "n", _OWNER, low=0, high=5))
        check_common(self, _OWNER, positive=("speed_limit", "acceleration", "mass"),
                     nonneg=("friction_spread", "bearing_friction", "bearing_drag"))
        set_("probes", as_count(self.probes, "probes", _OWNER, low=1, high=MAX_PROBES))

    @property
    def nominal_force(self) -> float:
        """``F_tot = 10 f``, N."""
        return self.acceleration * self.mass

    def contacts(self, keys: RunKeys, n: int | None = None) -> ContactSet:
        """The wheels of the first run of ``keys`` with ``5 - n`` forwards (default: this
        split), and the bearing as a contact at speed 0 when it has friction."""
        n = self.n if n is None else n
        forces = wheels_for_runs(keys.run(0), self.wheel_seed, 10, self.nominal_force / 10.0,
                                 self.friction_spread)[1][0]
        v = self.speed_limit
        speeds = np.array([v] * (5 - n) + [-v] * (5 + n))
        if self.bearing_friction > 0:
            speeds, forces = np.append(speeds, 0.0), np.append(forces, self.bearing_friction)
        return ContactSet(speeds, forces)

    def probe_speeds(self) -> np.ndarray:
        """The ``probes`` speeds, evenly spread (midpoints) inside ``(-v_max, v_max)``, m/s."""
        return self.speed_limit * (2.0 * (np.arange(self.probes) + 0.5) / self.probes - 1.0)

    def rig_reading(self, contacts: ContactSet) -> float:
        """Mean over the probe speeds of ``|F(V) - c V|``, N."""
        probe = self.probe_speeds()
        return float(np.abs(contacts.force(probe) - self.bearing_drag * probe).mean())

    def run(self, keys: RunKeys) -> dict[str, np.ndarray]:
        """Columns ``mu_ratio`` (quasi-static, over the same rig's ``mu0``), ``mu0`` (the
        rig's reading with every wheel reversed, N), ``band_force`` (net wheel force inside
        the band, N), ``dT`` and ``dT_ideal`` (s; ``inf`` where the body never reaches
        ``-v_max``)."""
        k = len(keys)
        mu, mu0, band, dT = np.empty(k), np.empty(k), np.empty(k), np.empty(k)
        v = self.speed_limit
        ideal = (self.mass * 2.0 * v / (self.nominal_force * self.n / 5.0)) if self.n else math.inf
        for j in range(k):
            run = keys.run(j)
            contacts = self.contacts(run)
            wheels = ContactSet(contacts.speeds[:10], contacts.forces[:10])
            band[j] = float(wheels.force(0.0))
            mu0[j] = self.rig_reading(self.contacts(run, 5))
            mu[j] = self.rig_reading(contacts) / mu0[j]
            dT[j] = self._transition(contacts)
        return {"mu_ratio": mu, "mu0": mu0, "band_force": band, "dT": dT, "dT_ideal": np.full(k, ideal)}

    def _transition(self, contacts: ContactSet) -> float:
        """Exact time from ``+v_max`` to ``-v_max``; ``inf`` if the body never gets there."""
        v = self.speed_limit
        # Weakest downward push on the way: F is non-increasing, so on (-v, v) the force is
        # largest just above -v, F(-v+) = the lower end of the set-valued force at -v (this
        # counts a bearing at speed 0, which pushes upwards below 0); drag adds up to c v.
        down = -float(contacts.force_bounds(-v)[0]) - self.bearing_drag * v
        if down <= 0.0:
            return math.inf
        result = simulate_or_raise(Plant(contacts, self.mass, damping=self.bearing_drag),
                                   4.0 * self.mass * 2.0 * v / down, "ResidualFriction transition", v0=v)
        # The body lands on the contacts at -v_max exactly (an event at that speed).
        reached = [event.time for event in result.events if event.speed <= -v]
        return float(reached[0]) if reached else math.inf

    def summarize(self, table: Any) -> dict[str, float]:
        """``mu_ratio`` mean and std, ``reduction`` (``1 - mu_ratio`` mean) and ``dT`` median."""
        mu = table["mu_ratio"].to_numpy()
        return {"mu_ratio": float(mu.mean()), "mu_ratio_std": float(mu.std(ddof=1)) if mu.size > 1 else 0.0,
                "reduction": float(1.0 - mu.mean()), "dT_median": float(np.median(table["dT"]))}
