"""Scene files: the TOML documents that declare a study, read and written (the only module that reads them).

Each section is a frozen dataclass whose fields declare its keys once (:func:`~toolkit.scenes.keys.key`:
type, default, SI unit, bound, meaning); parsing, the messages, the command line's shared
bounds and the scene reference page (``toolkit.scenes.reference.render``) derive from
them. :func:`load_scene` checks the form only (known sections and keys, types, required and
exclusive keys) and builds nothing; bounds and rules between sections are checked by
:func:`~toolkit.scenes.build.build_scene`. :func:`dumps_scene` writes a scene back
(``loads_scene(dumps_scene(s)) == s``).
"""

from __future__ import annotations

import errno
import math
import stat
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar

import tomli_w

from ..errors import SceneError, SceneFileNotFoundError, suggestion
from ..model.truth import ModelPrior, WorldTruth
from ..simulation import Budget
from ..sweeps import MAX_RUNS
from .keys import (COMMANDS, FLAG, INDICES, INTEGER, INTEGERS, MATRIX, NAMES, NUMBER, NUMBER_OR_INF,
                   NUMBER_OR_NUMBERS, NUMBERS, PAIR, POINTS, SIGNAL, TABLE, TEXT, Key, Reader, Section,
                   check_keys, choice, key, known, plain)
from .limits import (INDEX, MAX_CURVE_POINTS, MAX_SAMPLES, NON_NEGATIVE, POSITIVE, SEED, Limit,
                     scene_value_error)

__all__ = [
    "Scene", "ContactsSpec", "BodySpec", "MotorsSpec", "SensorsSpec", "TargetSpec", "ScheduleSpec",
    "SimulationSpec", "EstimationSpec", "ControlSpec", "ReportSpec", "SweepSpec", "PlanarSpec", "SECTIONS",
    "SCENE_KEYS", "CONTROLLERS", "load_scene", "loads_scene", "dumps_scene", "flag_limit", "MAX_SCENE_BYTES",
    "MAX_SAMPLES",
]

#: Section names of earlier plans, refused with a pointer to the sections that replaced them.
PLANNED_SECTIONS = {"estimator": "estimation", "controller": "control"}
#: Largest scene file :func:`load_scene` reads, bytes (1 MiB): a scene is a short text.
MAX_SCENE_BYTES = 1 << 20
_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")
_fail = scene_value_error

#: The ``[scene]`` section's keys.
SCENE_KEYS = (
    Key(TEXT, "the scene's name: letters, digits, '_', '.' and '-' (it names the output folder; "
        "absent: the file's stem)", name="name"),
    Key(TEXT, "one line on what the scene studies", name="description", default=""),
)


# -- declarations several sections share ----------------------------------------------------------

#: Encoder noise keys of ``[estimation]`` and ``[control]``.
_NOISE = {
    "missed_count_prob": dict(read=NUMBER, unit="1", meaning="probability that an encoder misses a count"),
    "count_noise": dict(read=NUMBER, unit="counts", meaning="std of the noise on each encoder count"),
    "jitter": dict(read=NUMBER, unit="s", meaning="std of the jitter of the sample times"),
}
#: The keys of ``[estimation]`` and ``[control]`` that set the encoders' noise.
NOISE_KEYS = tuple(_NOISE)
_PAIRS = ("drag_range", "lag_range")
#: Keys of the ``truth`` and ``model`` sub-tables: the fields of WorldTruth and ModelPrior.
TRUTH_KEYS = tuple(item.name for item in fields(WorldTruth))
MODEL_KEYS = tuple(item.name for item in fields(ModelPrior))


def _knowledge_item(name: str) -> Reader:
    return NUMBERS if name in _PAIRS else NUMBER


_TRUTH = dict(read=known(lambda: TRUTH_KEYS, _knowledge_item),
              meaning="how the simulated world departs from the scene, drawn from ``seed`` and not told "
                      "to the estimators: the fields of :class:`~toolkit.model.truth.WorldTruth`")
_MODEL = dict(read=known(lambda: MODEL_KEYS, _knowledge_item),
              meaning="what the estimators are told beyond the scene: the fields of "
                      ":class:`~toolkit.estimation.ModelPrior`")
_ANY = Reader("value", lambda where, value: value)
_BUDGET = dict(read=known(lambda: tuple(item.name for item in fields(Budget)), _ANY),
               unit="s, count, 1/s, count",
               meaning="``{wall_time, max_steps, max_event_rate, max_samples}`` of each plant step "
                       "(a :class:`toolkit.simulation.Budget`)")


# -- sections ---------------------------------------------------------------------------------------

_RANDOM = (
    Key(INTEGER, "number of contacts", required=True, limit=Limit(low=1, high=MAX_SAMPLES, integer=True),
        name="n"),
    Key(NUMBER, "lowest speed", "m/s", required=True, name="low"),
    Key(NUMBER, "highest speed (>= low)", "m/s", required=True, name="high"),
    Key(INTEGER, "seed of the draw", limit=SEED, name="seed", default=0),
)


@dataclass(frozen=True)
class ContactsSpec(Section):
    """``[contacts]``: the contacts' speeds and friction magnitudes (required but in a sweep or
    planar scene)."""

    SECTION = "contacts"
    EXCLUSIVE = (("speeds", "random"), ("forces", "mu"))
    ONE_OF = (("speeds", "random"),)
    NEEDS = (("mu", "normal_loads"), ("normal_loads", "mu"))

    speeds: tuple[float, ...] | None = key(None, read=NUMBERS, unit="m/s", meaning="the contacts' speeds, one "
                                           "per contact, within the motors' speed limits")
    random: dict[str, Any] | None = key(None, keys=_RANDOM, meaning="``n`` speeds drawn "
                                        "uniformly on ``[low, high]`` by NumPy's default generator from ``seed``")
    forces: float | tuple[float, ...] | None = key(None, read=NUMBER_OR_NUMBERS, unit="N", meaning="friction "
                                                   "magnitudes, one for all or one per contact (neither "
                                                   "``forces`` nor ``mu``: 1 N each)")
    mu: float | tuple[float, ...] | None = key(None, read=NUMBER_OR_NUMBERS, unit="1", meaning="friction "
                                               "coefficients: ``f_i = mu_i N_i``")
    normal_loads: float | tuple[float, ...] | None = key(None, read=NUMBER_OR_NUMBERS, unit="N",
                                                         meaning="normal loads ``N_i`` (with ``mu``)")

    @property
    def n(self) -> int:
        """Number of contacts declared."""
        return self.random["n"] if self.random is not None else len(self.speeds)  # type: ignore[arg-type]


@dataclass(frozen=True)
class BodySpec(Section):
    """``[body]``: the moving body."""

    SECTION = "body"
    EXCLUSIVE = (("mass", "inertia"),)
    ONE_OF = (("mass", "inertia"),)
    NEEDS = (("inertia", "contact_radius"),)

    mass: float | None = key(None, read=NUMBER, unit="kg", meaning="moving inertia at the contacts")
    inertia: float | None = key(None, read=NUMBER, unit="kg m^2", limit=POSITIVE, meaning="rotational "
                                "inertia: ``mass = inertia / contact_radius**2``")
    contact_radius: float | None = key(None, read=NUMBER, unit="m", limit=POSITIVE, meaning="radius at which "
                                       "the contacts touch the body (with ``inertia``)")
    damping: float = key(0.0, read=NUMBER, unit="N s/m", meaning="viscous damping of the body")
    external_force: float | dict[str, Any] = key(0.0, read=SIGNAL, unit="N", meaning="force on the body: a "
                                                 "constant or a piecewise-constant table")

    @property
    def moving_mass(self) -> float:
        """Moving inertia at the contacts, kg (``inertia / contact_radius**2`` when given so)."""
        if self.mass is not None:
            return self.mass
        return self.inertia / self.contact_radius**2  # type: ignore[operator]


@dataclass(frozen=True)
class MotorsSpec(Section):
    """``[motors]``: the drives of the contacts."""

    SECTION = "motors"
    EXCLUSIVE = (("speed_limit", "speed_limits"),)

    speed_limits: tuple[float, float] = key((-math.inf, math.inf), read=PAIR, unit="m/s",
                                            meaning="speed limits ``[lo, hi]``")
    lag: float = key(0.0, read=NUMBER, unit="s", meaning="first-order time constant of the motors")
    rate_limit: float = key(math.inf, read=NUMBER_OR_INF, unit="m/s^2", meaning="largest acceleration of "
                            "a motor")
    compliance: float = key(0.0, read=NUMBER, unit="(m/s)/N", meaning="speed droop per newton of contact force")
    backlash: float = key(0.0, read=NUMBER, unit="m", meaning="gearbox play at the contact (simulated by "
                          "``method = \"moreau\"`` only, refused by the other methods)")
    clip: bool = key(False, read=FLAG, meaning="false: contact speeds and ``simulation.commands`` beyond the "
                     "speed limits are refused; true: clipped to them, and the study reports a shortfall")
    speed_limit: float | None = key(None, read=NUMBER, unit="m/s", limit=POSITIVE, meaning="symmetric "
                                    "limits: ``speed_limits = [-speed_limit, speed_limit]``")

    @classmethod
    def _finish(cls, values: dict[str, Any]) -> dict[str, Any]:
        if values.get("speed_limit") is not None:
            values["speed_limits"] = (-values["speed_limit"], values["speed_limit"])
        return values

    def to_table(self) -> dict[str, Any]:
        table = super().to_table()
        if self.speed_limit is not None or not all(map(math.isfinite, self.speed_limits)):
            table.pop("speed_limits", None)
        return table


@dataclass(frozen=True)
class SensorsSpec(Section):
    """``[sensors]``: the encoders, sampled together."""

    SECTION = "sensors"
    NEEDS = (("wheel_counts_per_rev", "wheel_radius"), ("wheel_radius", "wheel_counts_per_rev"),
             ("central_counts_per_rev", "contact_radius"), ("contact_radius", "central_counts_per_rev"))

    rate: float = key(50.0, read=NUMBER, unit="Hz", meaning="sample rate of the encoders")
    wheel_counts_per_rev: float | None = key(None, read=NUMBER, meaning="counts per revolution of each "
                                             "wheel encoder")
    wheel_radius: float | None = key(None, read=NUMBER, unit="m", meaning="radius of the wheels the wheel "
                                     "encoders turn with")
    wheel_backlash: float = key(0.0, read=NUMBER, unit="m", meaning="gearbox play between a wheel and its "
                                "encoder, at the contact")
    central_counts_per_rev: float | None = key(None, read=NUMBER, meaning="counts per revolution of the "
                                               "central encoder")
    contact_radius: float | None = key(None, read=NUMBER, unit="m", meaning="radius at which the central "
                                       "encoder reads the body")


@dataclass(frozen=True)
class TargetSpec(Section):
    """``[target]``: what the allocation stage realizes (:func:`toolkit.allocate`)."""

    SECTION = "target"
    SELECTOR = "kind"
    KINDS = {"force_curve": "a force-speed curve through given points",
             "viscosity": "a viscous law ``F = -slope (v - center)`` over a band",
             "friction_fraction": "a fraction ``mu/mu0`` of the full friction over a band",
             "equilibrium_speed": "an equilibrium at ``speed`` that ``margin`` failed contacts keep"}
    PARAMS = (
        Key(NUMBERS, "speeds of the curve's points", "m/s", kinds=("force_curve",), required=True, name="speeds"),
        Key(NUMBERS, "forces of the curve's points", "N", kinds=("force_curve",), required=True, name="forces"),
        Key(NUMBERS, "weights of the points (absent: equal)", "1", kinds=("force_curve",), name="weights"),
        Key(NUMBER, "viscous slope", "N s/m", kinds=("viscosity",), required=True, name="slope"),
        Key(NUMBER, "speed of zero force", "m/s", kinds=("viscosity",), required=True, name="center"),
        Key(NUMBER_OR_NUMBERS, "half-width of the speed band over which the law holds", "m/s",
            kinds=("viscosity", "friction_fraction"), required=True, name="band"),
        Key(NUMBER, "``mu/mu0`` in [0, 1]", "1", kinds=("friction_fraction",), required=True, name="fraction"),
        Key(NUMBER, "the equilibrium speed", "m/s", kinds=("equilibrium_speed",), required=True, name="speed"),
        Key(INTEGER, "a count of contacts, not a speed: the equilibrium stays at ``speed`` when that many "
            "contacts fail (``W >= |U - L| + 2 *`` the sum of the ``margin`` largest magnitudes)",
            kinds=("equilibrium_speed",), name="margin", default=0),
    )

    kind: str = key(read=choice(lambda: TargetSpec.KINDS), required=True, meaning="what to realize")
    params: dict[str, Any] = field(default_factory=dict)
    method: str | None = key(None, read=TEXT, meaning="allocation solver (absent: chosen)")
    strict: bool = key(False, read=FLAG, meaning="refuse a target out of reach instead of projecting it")
    dt: float | None = key(None, read=NUMBER, unit="s", limit=POSITIVE, meaning="with ``[motors] "
                           "rate_limit``: each contact moves at most ``rate_limit * dt`` from its current speed")
    fixed: tuple[int, ...] = key((), read=INDICES, limit=INDEX, each=True, meaning="contacts that keep their "
                                 "current speed (and still push)")
    failed: tuple[int, ...] = key((), read=INDICES, limit=INDEX, each=True, meaning="contacts that have "
                                  "failed: they keep their current speed (and still push)")
    liftable: tuple[int, ...] = key((), read=INDICES, limit=INDEX, each=True, meaning="contacts that may be "
                                    "lifted (magnitude 0)")
    time_limit: float = key(30.0, read=NUMBER, unit="s", limit=POSITIVE, meaning="time budget of the MILP "
                            "solver")


@dataclass(frozen=True)
class ScheduleSpec(Section):
    """``[schedule]``: a time-varying contact-speed design (:func:`toolkit.design_schedule`)."""

    SECTION = "schedule"
    SELECTOR = "kind"
    KINDS = {"braking": "brake the body to ``speed``", "track": "track a body-speed trajectory"}
    PARAMS = (
        Key(NUMBER, "the speed to brake to", "m/s", kinds=("braking",), required=True, name="speed"),
        Key(NUMBER, "time to brake in (absent: as fast as possible)", "s", kinds=("braking",), name="duration"),
        Key(NUMBERS, "times of the trajectory", "s", kinds=("track",), required=True, name="times"),
        Key(NUMBERS, "body speeds at those times", "m/s", kinds=("track",), required=True, name="speeds"),
    )

    kind: str = key(read=choice(lambda: ScheduleSpec.KINDS), required=True, meaning="what to design")
    params: dict[str, Any] = field(default_factory=dict)
    v0: float = key(0.0, read=NUMBER, unit="m/s", meaning="body speed at the start")
    period: float = key(0.02, read=NUMBER, unit="s", limit=POSITIVE, meaning="controller period")
    epsilon: float = key(1e-3, read=NUMBER, unit="m/s", limit=POSITIVE, meaning="smoothing width of the "
                         "optimizer")
    horizon: float | None = key(None, read=NUMBER, unit="s", limit=POSITIVE, meaning="length of the schedule "
                                "(absent: the trajectory's end, or the braking time with a margin)")
    time_limit: float = key(30.0, read=NUMBER, unit="s", limit=POSITIVE, meaning="time budget of the design")


@dataclass(frozen=True)
class SimulationSpec(Section):
    """``[simulation]``: simulate the plant (:func:`toolkit.simulate`)."""

    SECTION = "simulation"

    t_end: float = key(read=NUMBER, unit="s", limit=POSITIVE, required=True, meaning="end time")
    v0: float = key(0.0, read=NUMBER, unit="m/s", meaning="body speed at the start")
    method: str = key("exact", read=TEXT, meaning="simulation method (:func:`toolkit.simulate`'s)")
    options: dict[str, Any] = key(factory=dict, read=TABLE, meaning="options of :func:`toolkit.simulate`; "
                                  "its ``budget`` table (" + _BUDGET["meaning"] + ") is checked when built")
    commands: dict[str, Any] | None = key(None, read=COMMANDS, unit="m/s", meaning="piecewise-constant "
                                          "contact-speed commands: each value a list of n speeds within the "
                                          "motors' speed limits")


#: Length of the brake scenario's record when ``[estimation] duration`` is absent, s.
BRAKE_RECORD = 10.0


@dataclass(frozen=True)
class EstimationSpec(Section):
    """``[estimation]``: estimate the body speed from simulated encoder counts (needs ``[body]`` and
    both encoders in ``[sensors]``). Its keys are *declared*: the estimators are told them;
    ``truth`` and ``model`` keep truth and belief apart."""

    SECTION = "estimation"
    SELECTOR = "scenario"
    KINDS = {"brake": "the contacts at ``cruise + linspace(-spread, spread, n)`` from rest, at ``brake + "
                      "...`` from ``brake_time``; a switch between samples is honoured at its instant",
             "simulation": "the scene's own ``[simulation]``, exact, recorded over its ``t_end``"}

    methods: tuple[str, ...] = key(("central_difference", "wheel_difference", "foaw_end", "foaw_best",
                                    "alpha_beta", "kalman", "rts"), read=NAMES,
                                   meaning="estimators to score, names of :data:`toolkit.estimation.ESTIMATOR_NAMES`")
    scenario: str = key("brake", read=choice(lambda: EstimationSpec.KINDS), meaning="the record")
    duration: float | None = key(None, read=NUMBER, unit="s", limit=POSITIVE, kinds=("brake",),
                                 meaning=f"length of the record (absent: {BRAKE_RECORD:g} s)")
    brake_time: float = key(5.0, read=NUMBER, unit="s", limit=NON_NEGATIVE, kinds=("brake",),
                            meaning="when the contacts switch from cruise to brake")
    cruise: float = key(0.2, read=NUMBER, unit="m/s", kinds=("brake",), meaning="centre of the contacts' "
                        "speeds from rest")
    brake: float = key(-0.1, read=NUMBER, unit="m/s", kinds=("brake",), meaning="centre of the contacts' "
                       "speeds from ``brake_time``")
    spread: float = key(0.05, read=NUMBER, unit="m/s", limit=NON_NEGATIVE, kinds=("brake",),
                        meaning="half-width of the contacts' speeds around ``cruise`` and ``brake``")
    seed: int = key(0, read=INTEGER, limit=SEED, meaning="the sensors', friction and wander draws and where "
                    "the encoders' count grids start (each seed another phase of the quantization)")
    friction_spread: float = key(0.0, read=NUMBER, unit="1", limit=NON_NEGATIVE, kinds=("brake",),
                                 meaning="relative std of each true ``f_i`` around the declared one, drawn "
                                         "once (the estimators are told the spread, not the draw)")
    missed_count_prob: float = key(0.0, **_NOISE["missed_count_prob"])
    count_noise: float = key(0.0, **_NOISE["count_noise"])
    jitter: float = key(0.0, **_NOISE["jitter"])
    speed_std: float = key(1e-4, read=NUMBER, unit="m/s", limit=POSITIVE, meaning="std of the filters' prior "
                           "on the start speed, which the scenario knows (rest or ``simulation.v0``)")
    initial_covariance: tuple[tuple[float, ...], ...] | None = key(
        None, read=MATRIX, unit="m^2, m^2/s, (m/s)^2", meaning="the filters' whole prior on (position, "
        "speed), 2 x 2 symmetric positive definite, replacing ``speed_std``")
    truth: dict[str, Any] | None = key(None, **_TRUTH)
    model: dict[str, Any] | None = key(None, **_MODEL)

    @property
    def record_duration(self) -> float:
        """Length of the brake scenario's record, s."""
        return BRAKE_RECORD if self.duration is None else self.duration


#: What an absent ``[control] estimator`` and ``rate`` (of the ideal loop) mean.
LOOP_ESTIMATOR, IDEAL_LOOP_RATE = "kalman", 50.0


@dataclass(frozen=True)
class ControlSpec(Section):
    """``[control]``: a closed loop at the sample rate (needs ``[body]``)."""

    SECTION = "control"
    SELECTOR = "controller"
    KINDS = {"viscosity": "a virtual viscosity of ``slope`` around ``reference``",
             "speed_hold": "hold ``reference`` by shifting the viscous law's centre (PI on the speed error)",
             "friction_brake": "brake with friction ``fraction`` of the full friction from ``start``",
             "open_loop": "replay the scene's designed ``[schedule]``"}
    PARAMS = (
        Key(NUMBER, "commanded ``dF/dV``", "N s/m", kinds=("viscosity", "speed_hold"), required=True,
            name="slope"),
        Key(NUMBER, "speed of zero force (speed_hold: the speed held)", "m/s",
            kinds=("viscosity", "speed_hold"), required=("speed_hold",), name="reference", default=0.0),
        Key(NUMBER, "half-width over which the law should hold (absent: the contacts' whole spread)", "m/s",
            kinds=("viscosity",), name="band"),
        Key(NUMBER, "proportional gain: centre shift per m/s of error", "1", kinds=("speed_hold",), name="kp",
            default=0.5),
        Key(NUMBER, "integral gain", "1/s", kinds=("speed_hold",), name="ki", default=5.0),
        Key(NUMBER, "``mu/mu0`` in [0, 1]", "1", kinds=("friction_brake",), required=True, name="fraction"),
        Key(NUMBER, "before it every contact runs at the upper speed limit", "s", kinds=("friction_brake",),
            name="start", default=0.0),
        Key(NUMBER, "hold the speed this close to the lower limit (absent: no hold)", "m/s",
            kinds=("friction_brake",), name="hold"),
    )

    controller: str = key(read=choice(lambda: ControlSpec.KINDS), required=True, meaning="the controller")
    params: dict[str, Any] = field(default_factory=dict)
    duration: float = key(10.0, read=NUMBER, unit="s", limit=POSITIVE, meaning="length of the run")
    v0: float = key(0.0, read=NUMBER, unit="m/s", meaning="body speed at the start")
    sensors: bool | None = key(None, read=FLAG, meaning="true: read the ``[sensors]`` encoders through "
                               "``estimator``; false: the ideal loop on the true speed (absent: whether the "
                               "scene has ``[sensors]``)")
    estimator: str | None = key(None, read=TEXT, meaning="the loop's estimator, a name of "
                                ":data:`toolkit.estimation.ESTIMATOR_NAMES` but ``rts`` "
                                f"(absent: ``{LOOP_ESTIMATOR}``)")
    rate: float | None = key(None, read=NUMBER, unit="Hz", meaning="rate of the ideal loop (with sensors: "
                             f"theirs; absent: {IDEAL_LOOP_RATE:g} Hz)")
    seed: int = key(0, read=INTEGER, limit=SEED, meaning="seed of the sensors' and the world's draws")
    missed_count_prob: float = key(0.0, **_NOISE["missed_count_prob"])
    count_noise: float = key(0.0, **_NOISE["count_noise"])
    jitter: float = key(0.0, **_NOISE["jitter"])
    budget: dict[str, Any] | None = key(None, **_BUDGET)
    cross_check: bool = key(False, read=FLAG, meaning="also simulate the loop as a python-control "
                            "interconnection (:mod:`toolkit.loop.interop`) and report the largest difference")
    truth: dict[str, Any] | None = key(None, **_TRUTH)
    model: dict[str, Any] | None = key(None, **_MODEL)


#: Controllers a ``[control]`` section may name, with the parameters each takes.
CONTROLLERS = {name: tuple(k.name for k in ControlSpec.PARAMS if k.takes(name)) for name in ControlSpec.KINDS}


@dataclass(frozen=True)
class ReportSpec(Section):
    """``[report]``: what a run writes."""

    SECTION = "report"

    plots: bool = key(True, read=FLAG, meaning="write PNG figures (needs matplotlib)")
    curve_points: int = key(801, read=INTEGER, limit=Limit(low=2, high=MAX_CURVE_POINTS, integer=True),
                            flag="curve --points", meaning="samples of the force-speed curve in the JSON output")


def _statistics(where: str, value: Any) -> tuple[str, ...]:
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise _fail(where, "be a non-empty list of summary names", value)
    return tuple(value)


@dataclass(frozen=True)
class SweepSpec(Section):
    """``[sweep]``: many seeded runs of one of the paper's experiments (:func:`toolkit.sweep`); every
    other key is a parameter of the experiment's class (:mod:`toolkit.experiments`), checked by its
    constructor. A sweep scene holds only ``[sweep]``, ``[scene]`` and ``[report]``."""

    SECTION = "sweep"
    SELECTOR = "experiment"

    experiment: str = key(read=choice(lambda: SweepSpec.kinds()), required=True, meaning="the experiment")
    params: Mapping[str, Any] = field(default_factory=dict)
    runs: int = key(1000, read=INTEGER, limit=Limit(low=1, high=MAX_RUNS, integer=True), flag="sweep --runs",
                    meaning="number of runs")
    seed: int = key(0, read=INTEGER, limit=Limit(low=0, integer=True), flag="sweep --seed",
                    meaning="root seed")
    chunk_size: int | None = key(None, read=INTEGER, limit=Limit(low=1, integer=True), meaning="runs per "
                                 "chunk (results do not depend on it)")
    statistics: tuple[str, ...] = key((), read=Reader("array of names", _statistics), meaning="the summary "
                                      "statistics ``--json`` prints (absent: all)")

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))

    @classmethod
    def kinds(cls) -> Mapping[str, str]:
        from ..experiments import EXPERIMENTS

        return {name: (kind.__doc__ or "").strip().split("\n")[0].split(" (see")[0].rstrip(".")
                for name, kind in EXPERIMENTS.items()}

    @classmethod
    def parse(cls, table: dict[str, Any]) -> SweepSpec:
        from ..experiments import EXPERIMENTS

        kind = cls._kind(table, cls.declared())
        names = tuple(f.name for f in fields(EXPERIMENTS[kind]))
        check_keys("sweep", table, (*(k.name for k in cls.declared()), *names))
        params: dict[str, Any] = {}
        for name in names:
            if name in table:
                value = table[name]
                if not isinstance(value, (bool, int, float, str)):
                    raise _fail(f"sweep.{name}", "be a number, a string or true/false", value)
                params[name] = NUMBER.read(f"sweep.{name}", value) if isinstance(value, float) else value
        spec = super().parse({k: v for k, v in table.items() if k not in names})
        return cls(**{**{f.name: getattr(spec, f.name) for f in fields(spec)}, "params": params})

    def to_table(self) -> dict[str, Any]:
        return {**super().to_table(), **plain(dict(self.params))}


_PRECISION = (
    Key(NUMBERS, "Moreau-Jean steps", "s", limit=POSITIVE, each=True, name="steps"),
    Key(INTEGERS, "quadrature resolution at each step", limit=Limit(low=1, high=1000, integer=True), each=True,
        name="resolutions"),
    Key(NUMBERS, "widths of the regularized law", "m/s", limit=POSITIVE, each=True, name="epsilons"),
)
_SHAPES = ("disc", "annulus", "ring")


@dataclass(frozen=True)
class PlanarSpec(Section):
    """``[planar]``: a rigid body on planar contacts (:mod:`toolkit.planar`, imported only for such a
    scene); a planar scene holds only ``[planar]``, ``[scene]`` and ``[report]``. A shape has
    uniform pressure and friction ``mu mass gravity``."""

    SECTION = "planar"
    SELECTOR = "body"
    KINDS = {"disc": "a uniform disc", "annulus": "a uniform annulus", "ring": "a thin ring",
             "legs": "point contacts at ``positions``"}
    METHODS: ClassVar[tuple[str, ...]] = ("exact", "moreau", "smooth")

    body: str = key(read=choice(lambda: PlanarSpec.KINDS), required=True, meaning="the body's contacts")
    mass: float = key(read=NUMBER, unit="kg", limit=POSITIVE, required=True, meaning="mass of the body")
    radius: float | None = key(None, read=NUMBER, unit="m", limit=POSITIVE, kinds=_SHAPES, required=True,
                               meaning="outer radius")
    inner_radius: float | None = key(None, read=NUMBER, unit="m", limit=NON_NEGATIVE, kinds=("annulus",),
                                     required=True, meaning="inner radius")
    mu: float | None = key(None, read=NUMBER, unit="1", limit=POSITIVE, kinds=_SHAPES, required=True,
                           meaning="friction coefficient")
    gravity: float = key(9.81, read=NUMBER, unit="m/s^2", limit=POSITIVE, kinds=_SHAPES,
                         meaning="gravitational acceleration")
    inertia: float | None = key(None, read=NUMBER, unit="kg m^2", limit=POSITIVE, required=("legs",),
                                meaning="inertia about the centre (absent for a shape: its uniform shape's)")
    positions: tuple[tuple[float, ...], ...] | None = key(None, read=POINTS, unit="m", kinds=("legs",),
                                                          required=True, meaning="contact points ``[[x, y], ...]``")
    velocities: tuple[tuple[float, ...], ...] | None = key(None, read=POINTS, unit="m/s", kinds=("legs",),
                                                           required=True, meaning="contact velocities "
                                                           "``[[vx, vy], ...]``")
    forces: tuple[float, ...] | None = key(None, read=NUMBERS, unit="N", limit=NON_NEGATIVE, each=True,
                                           kinds=("legs",), required=True, meaning="friction magnitudes")
    v0: tuple[float, ...] = key((0.0, 0.0), read=NUMBERS, unit="m/s", meaning="``[vx, vy]`` at the start")
    omega0: float = key(0.0, read=NUMBER, unit="rad/s", meaning="spin at the start")
    t_end: float = key(1.0, read=NUMBER, unit="s", limit=POSITIVE, meaning="end time")
    method: str = key("exact", read=choice(lambda: dict.fromkeys(PlanarSpec.METHODS)), meaning="``exact`` (a "
                      "shape, or legs on one line), ``moreau`` (``step``) or ``smooth`` (``epsilon``)")
    step: float | None = key(None, read=NUMBER, unit="s", limit=POSITIVE, meaning="step of ``moreau``")
    resolution: int | None = key(None, read=INTEGER, limit=Limit(low=1, high=1000, integer=True),
                                 meaning="rings of a disc's quadrature, arcs of a ring's (about pi "
                                         "resolution^2 nodes)")
    epsilon: float | None = key(None, read=NUMBER, unit="m/s", limit=POSITIVE, meaning="regularization "
                                "width of ``smooth``")
    precision: dict[str, Any] | None = key(None, keys=_PRECISION,
                                           meaning="also the work-precision rows against the exact method "
                                                   "(absent keys: the planar work-precision report's defaults)")

    @classmethod
    def _finish(cls, values: dict[str, Any]) -> dict[str, Any]:
        if values.get("method") == "smooth" and "epsilon" not in values:
            raise SceneError("The [planar] section needs the key 'epsilon' (m/s) with method = 'smooth'.")
        precision = values.get("precision") or {}
        steps = precision.get("steps", (4e-3, 2e-3, 1e-3))        # scene_precision's default steps
        if "resolutions" in precision and len(precision["resolutions"]) != len(steps):
            raise SceneError("In [planar.precision] give one resolution per step.")
        return values


#: Every section a scene may declare besides ``[scene]``, in the order of :class:`Scene`.
SECTIONS: dict[str, type[Section]] = {
    "contacts": ContactsSpec, "body": BodySpec, "motors": MotorsSpec, "sensors": SensorsSpec,
    "target": TargetSpec, "schedule": ScheduleSpec, "simulation": SimulationSpec,
    "estimation": EstimationSpec, "control": ControlSpec, "report": ReportSpec, "sweep": SweepSpec,
    "planar": PlanarSpec,
}
#: The sections a sweep scene may hold besides [sweep].
_SWEEP_SECTIONS = ("scene", "sweep", "report")
#: The sections a planar scene may hold besides [planar].
_PLANAR_SECTIONS = ("scene", "planar", "report")


@dataclass(frozen=True)
class Scene:
    """A validated, frozen scene. Absent sections are ``None`` and their stages are left out.

    Attributes
    ----------
    name, description : str
    contacts : ContactsSpec or None
        ``None`` only in a sweep scene (its runs draw their own contacts).
    body, motors, sensors, target, schedule, simulation, estimation, control, report, sweep,
    planar : section spec or None
    """

    name: str
    contacts: ContactsSpec | None
    description: str = ""
    body: BodySpec | None = None
    motors: MotorsSpec | None = None
    sensors: SensorsSpec | None = None
    target: TargetSpec | None = None
    schedule: ScheduleSpec | None = None
    simulation: SimulationSpec | None = None
    estimation: EstimationSpec | None = None
    control: ControlSpec | None = None
    report: ReportSpec | None = None
    sweep: SweepSpec | None = None
    planar: PlanarSpec | None = None

    @property
    def stages(self) -> tuple[str, ...]:
        """The stages this scene declares, in the order ``run`` executes them."""
        if self.planar is not None:
            return ("planar",) + (("report",) if self.report is not None else ())
        if self.sweep is not None:
            return ("sweep",) + (("report",) if self.report is not None else ())
        order = ("sensors", "target", "schedule", "simulation", "estimation", "control", "report")
        return ("curve",) + tuple(s for s in order if getattr(self, s) is not None)



def flag_limit(flag: str) -> Limit | None:
    """The bound of the scene key a command-line flag (``"sweep --runs"``) also sets, if any."""
    return next((k.limit for section in SECTIONS.values() for k in section.declared() if k.flag == flag), None)


def _alone(data: Mapping[str, Any], kind: str, allowed: tuple[str, ...], declares: str) -> None:
    """Refuse a section that a sweep or planar scene (which declares its own model) does not hold."""
    others = [key for key in data if key not in allowed]
    if others:
        raise SceneError(f"A {kind} scene declares {declares}; remove [{others[0]}]. A {kind} scene "
                         f"may hold {', '.join(f'[{k}]' for k in allowed)}.")


def loads_scene(text: str, *, name: str = "scene", source: str | None = None) -> Scene:
    """Parse a scene from TOML text and check its form; see :func:`load_scene`.

    ``source``, the file the text was read from, is what messages about the file's form
    (invalid TOML, unknown or missing sections) name; without one they name the scene.
    """
    where = f"scene {name!r}" if source is None else f"scene file {source!r}"
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise SceneError(f"The {where} is not valid TOML: {error}.") from None
    allowed = ("scene", *SECTIONS)
    for key, value in data.items():
        if key in PLANNED_SECTIONS:
            raise SceneError(f"Unknown section [{key}] in {where}. Did you mean "
                             f"[{PLANNED_SECTIONS[key]}]?")
        if key not in allowed:
            hint = suggestion(key, allowed) or f" Valid sections: {', '.join(allowed)}."
            raise SceneError(f"Unknown section [{key}] in {where}.{hint}")
        if not isinstance(value, dict):
            raise SceneError(f"[{key}] in {where} must be a table (a [section]), got {value!r}.")
    meta = data.get("scene", {})
    check_keys("scene", meta, tuple(k.name for k in SCENE_KEYS))
    if "sweep" in data:
        _alone(data, "sweep", _SWEEP_SECTIONS, "its model in [sweep] (each run draws its own contacts)")
    elif "planar" in data:
        _alone(data, "planar", _PLANAR_SECTIONS, "its body and contacts in [planar]")
    elif "contacts" not in data:
        raise SceneError(f"The {where} needs a [contacts] section.")
    sections = {key: SECTIONS[key].parse(value) for key, value in data.items() if key in SECTIONS}
    scene_name = TEXT.read("scene.name", meta.get("name", name))
    if not _NAME.fullmatch(scene_name):
        raise _fail("scene.name", "be a plain name of letters, digits, '_', '.' and '-' (it names the "
                    "output folder)", scene_name)
    return Scene(name=scene_name, description=TEXT.read("scene.description", meta.get("description", "")),
                 **{"contacts": None, **sections})


def load_scene(path: str | Path) -> Scene:
    """Read a scene file and check its form (no objects are built: :func:`~toolkit.scenes.build.build_scene`).

    Parameters
    ----------
    path : str or Path
        A TOML scene file (its sections and keys: the scene reference page,
        ``toolkit.scenes.reference.render``; SI units).

    Returns
    -------
    Scene

    Raises
    ------
    SceneFileNotFoundError
        The file does not exist.
    SceneError
        The path is a directory, a symbolic link loop or not a regular file; the file cannot
        be read, is empty, larger than :data:`MAX_SCENE_BYTES` or not UTF-8; invalid TOML, an
        unknown section or key (with a suggestion), a missing or conflicting key, a value of
        the wrong type or not finite.
    """
    file = Path(path)
    stem = file.stem if _NAME.fullmatch(file.stem) else "scene"
    return loads_scene(_read_scene_text(file), name=stem, source=str(file))


def _read_scene_text(file: Path) -> str:
    """The text of a scene file, or a one-line error naming the file and what is wrong."""
    shown = repr(str(file))
    try:
        info = file.stat()
    except FileNotFoundError:
        if file.is_symlink():
            raise SceneFileNotFoundError(f"The scene file {shown} is a symbolic link to a file "
                                         "that does not exist.") from None
        raise SceneFileNotFoundError(f"The scene file {shown} does not exist.") from None
    except OSError as error:
        if error.errno == errno.ELOOP:
            raise SceneError(f"The scene file {shown} is a symbolic link loop.") from None
        raise SceneError(f"The scene file {shown} cannot be read: {error.strerror}.") from None
    if stat.S_ISDIR(info.st_mode):
        raise SceneError(f"The scene path {shown} is a directory, not a scene file.")
    if not stat.S_ISREG(info.st_mode):
        raise SceneError(f"The scene path {shown} is not a regular file.")
    if info.st_size > MAX_SCENE_BYTES:
        raise SceneError(f"The scene file {shown} is {info.st_size} bytes; scene files are limited "
                         f"to {MAX_SCENE_BYTES} bytes (1 MiB).")
    try:
        with open(file, "rb") as stream:
            data = stream.read(MAX_SCENE_BYTES + 1)
    except OSError as error:
        raise SceneError(f"The scene file {shown} cannot be read: {error.strerror}.") from None
    if len(data) > MAX_SCENE_BYTES:          # grew since stat
        raise SceneError(f"The scene file {shown} is more than {MAX_SCENE_BYTES} bytes; scene files "
                         "are limited to 1 MiB.")
    if not data.strip():
        raise SceneError(f"The scene file {shown} is empty; a scene needs at least a [contacts] "
                         "section.")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise SceneError(f"The scene file {shown} is not UTF-8 text: byte "
                         f"0x{data[error.start]:02x} at offset {error.start}.") from None


def dumps_scene(scene: Scene) -> str:
    """Write a scene as TOML text that ``loads_scene`` reads back to an equal scene."""
    data: dict[str, Any] = {"scene": {"name": scene.name}}
    if scene.description:
        data["scene"]["description"] = scene.description
    for name in SECTIONS:
        spec = getattr(scene, name)
        if spec is not None:
            data[name] = spec.to_table()
    return tomli_w.dumps(data)
