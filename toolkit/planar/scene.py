"""A planar scene's objects and its study: what ``active-contacts run`` does with ``[planar]``.

:func:`build_planar` turns the form-checked ``[planar]`` section (any object with its fields:
:class:`toolkit.scenes.spec.PlanarSpec`) into a :class:`PlanarSceneObjects` (the plant and
its start); constructors refuse bad values with :class:`~toolkit.errors.ParameterError`
naming their parameter, which the scene layer maps to the scene key. :func:`run_planar` runs
the simulation, the terminal ratio of an axisymmetric body against its closed form and the
published value, the equilibrium of a leg set, and the optional work-precision rows;
:meth:`PlanarStudyResult.to_dict` is the JSON under the key ``planar``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ParameterError, parameter_message
from ..shortfall import Shortfall
from .contacts import PlanarContactSet
from .equilibrium import PlanarEquilibrium
from .precision import PlanarPrecisionReport, precision_report
from .regions import DiscRegion, RingRegion, terminal_ratio
from ._warmup import warm_up
from .simulation import PlanarPlant, PlanarSimulationResult, check_method, check_start, simulate_planar

__all__ = ["PlanarSceneObjects", "PlanarStudyResult", "build_planar", "run_planar", "scene_precision", "PUBLISHED"]

#: Published terminal ratios ``v / (R omega)`` of passive bodies sliding and spinning to rest.
PUBLISHED = {
    "disc": (0.653, "Farkas, Bartels, Unger & Wolf, Phys. Rev. Lett. 90, 248302 (2003); "
                    "Weidman & Malhotra, Phys. Rev. Lett. 95, 264303 (2005)"),
    "ring": (1.0, "Weidman & Malhotra, Phys. Rev. Lett. 95, 264303 (2005)"),
}
#: Rounding of the published disc value (three digits): the tolerance of a check against it.
PUBLISHED_TOLERANCE = 5e-4


@dataclass(frozen=True, eq=False)
class PlanarSceneObjects:
    """The objects of a ``[planar]`` section.

    Attributes
    ----------
    spec : PlanarSpec
    plant : PlanarPlant
    v0 : ndarray of shape (2,), m/s
    omega0 : float, rad/s
    options : dict
        Method options for :func:`~toolkit.planar.simulation.simulate_planar`.
    """

    spec: Any
    plant: PlanarPlant
    v0: np.ndarray
    omega0: float
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def region(self) -> Any:
        """The disc or ring region (None for legs)."""
        c = self.plant.contacts
        return c if isinstance(c, (DiscRegion, RingRegion)) else None


def build_planar(spec: Any) -> PlanarSceneObjects:
    """Build the plant of a ``[planar]`` section (values checked by the constructors)."""
    body = spec.body
    if body in ("disc", "annulus", "ring"):
        if spec.mu is None or spec.radius is None:
            raise ParameterError(parameter_message("radius", "PlanarScene", "be given with 'mu' for a "
                                                   f"{body}", None))
        force = spec.mu * spec.mass * spec.gravity
        if body == "ring":
            region: Any = RingRegion(spec.radius, force)
            default_inertia = spec.mass * spec.radius ** 2
        else:
            inner = spec.inner_radius or 0.0
            region = DiscRegion(spec.radius, force, inner_radius=inner)
            default_inertia = 0.5 * spec.mass * (spec.radius ** 2 + inner ** 2)
        inertia = default_inertia if spec.inertia is None else spec.inertia
        plant = PlanarPlant(region, spec.mass, inertia, resolution=spec.resolution)
    else:
        contacts = PlanarContactSet(spec.positions, spec.velocities, spec.forces)
        plant = PlanarPlant(contacts, spec.mass, spec.inertia)
    options: dict[str, Any] = {}
    if spec.method == "moreau" and spec.step is not None:
        options["step"] = spec.step
    if spec.method == "smooth":
        options["epsilon"] = spec.epsilon
    v0, omega0 = check_start(plant, spec.v0, spec.omega0)
    check_method(plant, spec.method, v0, omega0)
    return PlanarSceneObjects(spec, plant, v0, omega0, options)


@dataclass(frozen=True, eq=False)
class PlanarStudyResult:
    """What a planar scene's run computed.

    Attributes
    ----------
    objects : PlanarSceneObjects
    simulation : PlanarSimulationResult
    terminal_ratio : float or None
        ``|V| / (R |omega|)`` as both vanish, from the run (``"exact"``: the reduced ODE's
        limit); None for legs or when the run does not give it.
    closed_form_ratio : float or None
        The stable root of ``F(eps) = eps T(eps) m R^2 / I`` (:func:`terminal_ratio`).
    published : tuple of (float, str) or None
        The published value and its source (uniform disc, thin ring).
    equilibrium : PlanarEquilibrium or None
        The equilibrium twist of a leg set (``body = "legs"``).
    precision : PlanarPrecisionReport or None
    shortfalls : tuple of Shortfall
        Requests missed (stage ``"planar"``: a run stopped by its budget, a ratio off the
        published value by more than its rounding).
    compile_time : float, s
        The planar kernels compiled (or loaded) before the timed run (``warm_up``).
    """

    objects: PlanarSceneObjects
    simulation: PlanarSimulationResult
    terminal_ratio: float | None
    closed_form_ratio: float | None
    published: tuple[float, str] | None
    equilibrium: PlanarEquilibrium | None
    precision: PlanarPrecisionReport | None
    shortfalls: tuple[Shortfall, ...] = ()
    compile_time: float = 0.0

    def to_dict(self, samples: int = 101) -> dict[str, Any]:
        """JSON form (the value of the key ``planar``): ``body``, ``method``, ``status``,
        ``terminal_ratio``, ``closed_form_ratio``, ``published_ratio``, ``published_source``,
        ``ratio_error`` (against the published value), ``stop_time`` (s), ``t_end`` (s),
        ``final`` (position m, heading rad, velocity m/s, omega rad/s), ``equilibrium`` (legs:
        ``velocity``, ``omega``, ``gap``, ``status``), ``trajectory`` (``samples`` times with
        speed, rim speed and ratio), ``precision`` (rows) and ``shortfalls``."""
        sim = self.simulation
        spec = self.objects.spec
        data: dict[str, Any] = {
            "body": spec.body, "method": sim.method, "setting": sim.setting, "status": sim.status.name,
            "message": sim.message, "terminal_ratio": self.terminal_ratio,
            "closed_form_ratio": self.closed_form_ratio,
            "published_ratio": None if self.published is None else self.published[0],
            "published_source": None if self.published is None else self.published[1],
            "ratio_error": (None if self.published is None or self.terminal_ratio is None
                            else abs(self.terminal_ratio - self.published[0])),
            "stop_time": sim.stop_time, "t_end": spec.t_end, "wall_time": sim.wall_time,
            "final": {"position": sim.position[-1].tolist(), "heading": float(sim.heading[-1]),
                      "velocity": sim.velocity[-1].tolist(), "omega": float(sim.omega[-1])},
        }
        if self.equilibrium is not None:
            eq = self.equilibrium
            data["equilibrium"] = {"velocity": eq.velocity.tolist(), "omega": eq.omega, "gap": eq.gap,
                                   "status": eq.status.name, "unique": eq.unique}
        region = self.objects.region
        if region is not None and sim.t.size:
            pick = np.unique(np.linspace(0, sim.t.size - 1, min(samples, sim.t.size)).round().astype(int))
            speed = sim.speed[pick]
            rim = np.abs(sim.omega[pick]) * region.radius
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = np.where(rim > 0, speed / rim, np.nan)
            data["trajectory"] = {"t": sim.t[pick].tolist(), "speed": speed.tolist(), "rim_speed": rim.tolist(),
                                  "ratio": [None if not math.isfinite(r) else float(r) for r in ratio]}
        data["precision"] = None if self.precision is None else self.precision.to_dict()
        data["shortfalls"] = [s.to_dict() for s in self.shortfalls]
        return data

    def lines(self) -> list[str]:
        """A text summary."""
        sim = self.simulation
        out = [f"planar {self.objects.spec.body}: {sim.method} ({sim.setting}) {sim.status.name}, "
               f"{sim.wall_time:.3g} s"]
        if sim.stop_time is not None:
            out.append(f"  comes to rest at t = {sim.stop_time:.9g} s")
        if self.terminal_ratio is not None:
            line = f"  terminal ratio |V| / (R |omega|) = {self.terminal_ratio:.9f}"
            if self.published is not None:
                line += f" (published {self.published[0]:g}: {self.published[1]})"
            out.append(line)
        if self.equilibrium is not None:
            eq = self.equilibrium
            out.append(f"  equilibrium V = {eq.velocity.tolist()} m/s, omega = {eq.omega:.6g} rad/s "
                       f"({eq.status.name}, gap {eq.gap:.2g} W)")
        if self.precision is not None:
            for row in self.precision.rows:
                out.append(f"  {row.method:7s} {row.setting:28s} error {row.max_error:.3g} m/s, "
                           f"{row.wall_time:.3g} s")
        out.extend(f"shortfall: {s}" for s in self.shortfalls)
        return out


def scene_precision(objects: PlanarSceneObjects) -> PlanarPrecisionReport:
    """The scene's work-precision report (:func:`~toolkit.planar.precision.precision_report`)
    with its ``[planar.precision]`` settings, or the defaults (Moreau-Jean steps 4, 2 and 1 ms at
    the plant's resolution, the regularized law at 1e-2 m/s) when it declares none."""
    spec, settings = objects.spec, objects.spec.precision or {}
    resolutions = settings.get("resolutions")
    return precision_report(objects.plant, spec.t_end, v0=objects.v0, omega0=objects.omega0,
                            steps=tuple(settings.get("steps", (4e-3, 2e-3, 1e-3))),
                            resolutions=None if resolutions is None else tuple(int(r) for r in resolutions),
                            epsilons=tuple(settings.get("epsilons", (1e-2,))))


def run_planar(objects: PlanarSceneObjects) -> PlanarStudyResult:
    """Run a planar scene: simulation, terminal ratio, equilibrium, work-precision rows."""
    spec = objects.spec
    plant = objects.plant
    compile_time = warm_up()           # every time reported below: compiled code
    sim = simulate_planar(plant, spec.t_end, v0=objects.v0, omega0=objects.omega0, method=spec.method,
                          **objects.options)
    shortfalls = []
    if not sim.success:
        shortfalls.append(Shortfall("planar", f"the simulation stopped before t_end: {sim.message}",
                                    spec.t_end - float(sim.t[-1]), "s"))
    ratio = closed = published = None
    region = objects.region
    if region is not None:
        kind = "ring" if isinstance(region, RingRegion) else "disc"
        eta = region.inner_radius / region.radius if kind == "disc" else 0.0
        k = plant.inertia / (plant.mass * region.radius ** 2)
        closed = terminal_ratio(kind, inertia_ratio=k, inner_ratio=eta)
        ratio = sim.terminal_ratio
        if spec.body in ("disc", "ring") and abs(k - region.inertia_ratio) <= 1e-12:
            published = PUBLISHED[kind]
        if ratio is not None and published is not None and abs(ratio - published[0]) > PUBLISHED_TOLERANCE:
            shortfalls.append(Shortfall("planar", f"terminal ratio {ratio:.6g} is off the published "
                                        f"{published[0]:g} by more than its rounding {PUBLISHED_TOLERANCE:g}",
                                        abs(ratio - published[0]), "1"))
    equilibrium = None
    if spec.body == "legs":
        equilibrium = plant.contacts.equilibrium()
    report = scene_precision(objects) if spec.precision is not None else None
    return PlanarStudyResult(objects, sim, ratio, closed, published, equilibrium, report, tuple(shortfalls),
                             compile_time)
