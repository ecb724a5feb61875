"""What a scene builds into (:func:`~toolkit.scenes.build.build_scene`): the objects of each
section (:class:`SceneObjects`), those of ``[estimation]`` and ``[control]``, and the speeds
clipped to the motors' limits (:class:`Clip`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from ..errors import SceneError
from ..model import ContactSet, Encoder, Motors, Plant
from ..model.sensors import Sensors
from ..schedule import Braking, SpeedTrajectory
from ..simulation import Budget
from ._key_errors import _scene_keys
from .spec import Scene

__all__ = ["Clip", "SceneObjects", "EstimationObjects", "ControlObjects"]


@dataclass(frozen=True)
class Clip:
    """Speeds a scene asked for beyond its motors' limits, clipped (``[motors] clip = true``).

    Attributes
    ----------
    key : str
        The scene key that set them (``"contacts.speeds"``, ``"simulation.commands"``, ...).
    value : float, m/s
        The requested speed farthest beyond the limits.
    limit : float, m/s
        The limit it was clipped to.
    count : int
        How many speeds were clipped.
    """

    key: str
    value: float
    limit: float
    count: int

    @property
    def excess(self) -> float:
        """``|value - limit|``, m/s."""
        return abs(self.value - self.limit)

@dataclass(frozen=True, eq=False)
class EstimationObjects:
    """What ``[estimation]`` declares.

    Attributes
    ----------
    sensors : Sensors
        The scene's encoders with the section's noise (missed counts, read noise, jitter).
    model : EstimatorModel
        What the model-based estimators know: the declared forces (N), the mass (kg), the
        sensors, the motor lag (s), the drag (N s/m) and ``friction_spread``.
    estimators : dict of str to Estimator
        One per ``methods`` entry, in order.
    truth : WorldTruth
        How the simulated world departs from the scene (``[estimation.truth]``; the
        estimators are not told).
    prior : ModelPrior
        What the estimators are told beyond the scene (``[estimation.model]``).
    plant : Plant
        The plant the record is simulated on: the brake scenario's (true friction: the
        declared forces with the drawn spread, and its commands), or the scene's own for
        ``scenario = "simulation"``.
    duration : float, s
        Length of the record.
    v0 : float, m/s
        The speed the record starts from (rest, or ``simulation.v0``).
    """

    sensors: Sensors
    model: Any
    estimators: dict[str, Any]
    plant: Plant
    duration: float
    v0: float
    truth: Any = None
    prior: Any = None


@dataclass(frozen=True, eq=False)
class ControlObjects:
    """What ``[control]`` declares.

    Attributes
    ----------
    controller : Controller or None
        None for ``"open_loop"`` (the study builds it from the designed schedule).
    sensors : Sensors or None
        The encoders read in the loop (None: the ideal loop on the true speed).
    estimator : Estimator or None
        What turns the counts into the estimate (with sensors).
    rate : float, Hz
    budget : Budget or None
        Guards of each plant step.
    truth : WorldTruth
        How the loop's world departs from the scene (``[control.truth]``).
    """

    controller: Any
    sensors: Sensors | None
    estimator: Any
    rate: float
    budget: Budget | None
    truth: Any = None

@dataclass(frozen=True, eq=False)
class SceneObjects:
    """The toolkit objects a scene declares, built by :func:`build_scene`.

    Attributes
    ----------
    scene : Scene
        The parsed scene they were built from.
    contacts : ContactSet or None
        Declared contact speeds (m/s) and friction magnitudes (N), shape (n,); None in a
        sweep scene.
    motors : Motors or None
        ``[motors]``; None for ideal motors.
    plant : Plant or None
        ``[body]`` on the declared contacts with the motors, the external force (N) and the
        ``[simulation]`` commands (m/s); None without ``[body]``.
    encoders : dict of str to Encoder
        ``"wheel"`` and ``"central"``, those ``[sensors]`` declares (empty without it).
    sensors : Sensors or None
        Both encoders, noise-free (None unless ``[sensors]`` declares both).
    target : ForceCurve, Viscosity, FrictionFraction, EquilibriumSpeed or None
        The allocation target of ``[target]``.
    schedule_target : Braking, SpeedTrajectory or None
        The schedule target of ``[schedule]``.
    simulation_options : dict
        ``[simulation] options`` as :func:`toolkit.simulate` takes them (``budget`` a
        :class:`~toolkit.simulation.Budget`); empty without ``[simulation]``.
    clipped : tuple of Clip
        Speeds clipped to the motor limits (``[motors] clip = true``); empty otherwise.
    estimation : EstimationObjects or None
    control : ControlObjects or None
    sweep : experiment or None
        ``[sweep]`` (:mod:`toolkit.experiments`).
    planar : toolkit.planar.scene.PlanarSceneObjects or None
        ``[planar]`` (:mod:`toolkit.planar`, imported only for a planar scene).
    """

    scene: Scene
    contacts: ContactSet | None
    motors: Motors | None = None
    plant: Plant | None = None
    encoders: dict[str, Encoder] = field(default_factory=dict)
    sensors: Sensors | None = None
    target: Any = None
    schedule_target: Braking | SpeedTrajectory | None = None
    simulation_options: dict[str, Any] = field(default_factory=dict)
    clipped: tuple[Clip, ...] = ()
    estimation: EstimationObjects | None = None
    control: ControlObjects | None = None
    sweep: Any = None
    planar: Any = None

    def plant_on(self, contacts: ContactSet | None = None) -> Plant:
        """The scene's plant, on other contacts (e.g. allocated ones) when given.

        Raises
        ------
        SceneError
            The scene has no ``[body]`` (the moving inertia).
        """
        if self.plant is None:
            raise SceneError(f"The scene {self.scene.name!r} has no [body] section (the moving "
                             "inertia) that this stage needs.")
        if contacts is None or contacts is self.contacts:
            return self.plant
        return replace(self.plant, contacts=contacts)

    def apparatus(self) -> Any:
        """The scene's plant and encoders as the paper's predictions' apparatus
        (:class:`toolkit.predictions.Apparatus`).

        Raises
        ------
        SceneError
            The scene has no ``[body]``, or breaks the apparatus's rules, named by the scene key
            that sets what it breaks (``contacts.forces``: one equal magnitude;
            ``motors.speed_limit``: finite symmetric limits).
        """
        from ..predictions import Apparatus

        keys = {"plant.contacts.forces": "contacts.forces", "plant.motors.speed_limits": "motors.speed_limit"}
        with _scene_keys("contacts", keys):
            return Apparatus(self.plant_on(None), self.sensors)
