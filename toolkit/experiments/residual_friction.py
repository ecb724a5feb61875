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

``mu_ratio`` is measured as the paper did, quasi-statically and on the same rig: the mean
over the band of the magnitude of the force a rig must apply to hold each speed, ``|F(V) - c
V|`` (``probes`` speeds evenly spread inside ``(-v_max, v_max)``), divided by the same reading
with all ten wheels reversed (``n = 5``) on the same carousel, ``mu0``. On the symmetric probe
band the bearing's ``-F_b sign(V)`` and the drag's ``-c V`` cancel in ``mu0`` (while ``F_b +
c v_max < sum f_i``), so ``mu0 = sum f_i``, each carousel's own total, not the nominal
``F_tot``. Drag does **not** average out of ``mu``: at ``n = 0`` the wheels' force in the band
is ``sum_+ f_i - sum_- f_i`` and the rig reads ``|band - c V|``; with equal wheels that is
``c |V|``, whose mean over an even number of midpoint probes is ``c v_max / 2`` exactly, so
``mu/mu0 = c v_max / (2 F_tot)`` (0.044 at ``c = 0.5`` N s/m on the carousel): drag is a third
explanation of a residual friction, next to unequal wheels and a Coulomb bearing.

``dT`` is the exact simulator's time from ``+v_max`` to ``-v_max`` (the body released at
``+v_max`` on this split), against ``dT_ideal = m 2 v_max / (F_tot n/5)``. With a bearing
``F_b`` at ``n >= 1`` and equal wheels the closed form is ``m v_max / (F_n + F_b) + m v_max /
(F_n - F_b)`` with ``F_n = (n/5) F_tot`` (the bearing helps above 0 and brakes below).

The wheels come from :func:`toolkit.experiments.carousel_wheels` (radius normals first, then
loads): ``wheel_seed`` gives the same carousel as every other experiment with that seed,
wheel ``i`` at ``+v_max`` for ``i < 5 - n``. Which wheels go forwards matters: one
carousel's residual depends on its split.
"""

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
