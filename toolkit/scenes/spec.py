"""Scene files: TOML documents that declare what a study needs (the only module that reads them).

A scene declares only the stages it needs. ``[contacts]`` is required (except in a sweep
scene, below); every other section is optional and its absence leaves its stage out (and the packages only that stage needs
unimported). All values are SI: m/s, N, kg, s, N s/m.

::

    [scene]          name, description
    [contacts]       speeds | random, and forces | (mu, normal_loads)        (required)
    [body]           mass | (inertia, contact_radius); damping; external_force
    [motors]         speed_limit | speed_limits; lag; rate_limit; compliance; backlash; clip
    [sensors]        rate; wheel_counts_per_rev; wheel_radius; wheel_backlash;
                     central_counts_per_rev; contact_radius
    [target]         kind = force_curve | viscosity | friction_fraction | equilibrium_speed,
                     its parameters, method, strict, dt, fixed, failed, liftable, time_limit
    [schedule]       kind = braking | track, its parameters, v0, period, epsilon, horizon
    [simulation]     t_end; v0; method; options (budget); commands
    [estimation]     methods; scenario = brake | simulation; duration; brake_time; cruise;
                     brake; spread; friction_spread; seed; missed_count_prob; count_noise;
                     jitter; speed_std; initial_covariance
    [control]        controller = viscosity | speed_hold | friction_brake | open_loop, its
                     parameters; duration; v0; sensors; estimator; rate; seed; noise; budget;
                     cross_check
    [report]         plots; curve_points
    [sweep]          experiment = median_law | mean_median | outliers | residual_friction,
                     runs, seed, chunk_size, statistics, and the experiment's parameters
    [planar]         body = disc | annulus | ring | legs, its parameters; mass; inertia;
                     v0; omega0; t_end; method; step; resolution; epsilon; precision

A *planar scene* declares ``[planar]`` (with optional ``[scene]`` and ``[report]``) and
nothing else: a rigid body on planar contacts (:mod:`toolkit.planar`, imported only for such a
scene), see :class:`PlanarSpec`.

A *sweep scene* declares ``[sweep]`` (with optional ``[scene]`` and ``[report]``) and nothing
else: each run of the experiment draws its own contacts, so the model (contact count, speed
range, friction spread, motor compliance, drag, calibration errors) is given by the
experiment's parameters in ``[sweep]``, in SI units, documented on its class in
:mod:`toolkit.experiments`.

``[estimation]`` (needs ``[body]`` and both encoders in ``[sensors]``), units:
``methods`` names from :data:`toolkit.estimation.ESTIMATOR_NAMES` (default all but ``"ukf"``);
``duration``, ``brake_time`` (s); ``cruise``, ``brake``, ``spread`` (m/s: the contacts at
``cruise + linspace(-spread, spread, n)`` from rest, at ``brake + ...`` from
``brake_time``); ``friction_spread`` (relative std of the true ``f_i``); ``seed``
(integer); ``missed_count_prob`` (probability); ``count_noise`` (counts); ``jitter`` (s);
``speed_std`` (m/s, prior std of the start speed, default 1e-4); ``initial_covariance``
(2 x 2: m^2, m^2/s, (m/s)^2). ``[control]`` (needs ``[body]``):
``slope`` (N s/m), ``reference`` (m/s), ``band`` (m/s), ``kp`` (1), ``ki`` (1/s),
``fraction`` (mu/mu0), ``start`` (s), ``hold`` (m/s), ``duration`` (s), ``v0`` (m/s),
``sensors`` (true/false; default: whether ``[sensors]`` exists), ``estimator`` (one of
:data:`toolkit.estimation.ESTIMATOR_NAMES` but ``"rts"``), ``rate`` (Hz, ideal loop), ``seed``, the noise keys as above,
``budget = {wall_time (s), max_steps, max_event_rate (1/s), max_samples}`` per plant step,
``cross_check`` (true/false: also simulate the loop with python-control). See
:class:`EstimationSpec` and :class:`ControlSpec`. An estimator or a closed loop reading
encoders on a scene without them is refused, and so is a rate that would take more than
10^7 samples.

Signals given as tables (``body.external_force``, ``simulation.commands``) are piecewise
constant: ``{times = [t_1, ..., t_k], values = [x_0, x_1, ..., x_k]}`` holds ``x_0`` before
``t_1``, ``x_j`` on ``[t_j, t_{j+1})`` and ``x_k`` from ``t_k`` on, so ``values`` has one
entry more than ``times``.

Contact speeds (``contacts.speeds``, ``contacts.random``) and command tables
(``simulation.commands``) must lie within the motors' speed limits: a scene that asks for
more than its motors can do is refused, unless ``[motors] clip = true``, which clips them
to the limits (and the study reports each clip as a shortfall).

A scene file is read as UTF-8 and may be at most :data:`MAX_SCENE_BYTES` (1 MiB) long.

This module checks the *form* of the document only: known sections and keys (unknown ones
refused with a suggestion), types, finite numbers, required and exclusive keys. It builds no
object and imports no solver, filter or plotting library. The bounds of values
(:mod:`toolkit.scenes.limits`), the rules between sections and the rules of the constructors
are checked when :func:`toolkit.scenes.build.build_scene` builds the scene's objects, the one
place specs become objects. :func:`dumps_scene` writes a scene back (round trip:
``loads_scene(dumps_scene(s)) == s``).
"""

from __future__ import annotations

import errno
import math
import stat
import re
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from types import MappingProxyType
from typing import Any

import tomli_w

from ..errors import suggestion
from ..errors import SceneError, SceneFileNotFoundError
from ..model.truth import ModelPrior, WorldTruth
from ..simulation import Budget
from .limits import MAX_SAMPLES, scene_value_error

__all__ = [
    "Scene", "ContactsSpec", "BodySpec", "MotorsSpec", "SensorsSpec", "TargetSpec", "ScheduleSpec",
    "SimulationSpec", "EstimationSpec", "ControlSpec", "ReportSpec", "SweepSpec", "CONTROLLERS", "load_scene", "loads_scene", "dumps_scene", "MAX_SCENE_BYTES",
    "MAX_SAMPLES", "PlanarSpec",
]

#: Section names of earlier plans, refused with a pointer to the sections that replaced them.
PLANNED_SECTIONS = {"estimator": "estimation", "controller": "control"}
#: Largest scene file :func:`load_scene` reads, bytes (1 MiB): a scene is a short text.
MAX_SCENE_BYTES = 1 << 20
_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")


# -- form checks: each returns the cleaned value or raises SceneError --------------------------
# (types, finite numbers, known, required and exclusive keys; the bounds of values and the
# rules between sections are toolkit.scenes.build's)

_fail = scene_value_error


def _number(where: str, value: Any, *, allow_inf: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _fail(where, "be a number", value)
    value = float(value)
    if math.isnan(value) or (not allow_inf and math.isinf(value)):
        raise _fail(where, "be finite", value)
    return value


def _integer(where: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise _fail(where, "be an integer", value)
    return value


def _numbers(where: str, value: Any) -> tuple[float, ...]:
    if not isinstance(value, list) or not value:
        raise _fail(where, "be a non-empty array of numbers", value)
    return tuple(_number(f"{where}[{i}]", item) for i, item in enumerate(value))


def _scalar_or_numbers(where: str, value: Any) -> float | tuple[float, ...]:
    return _numbers(where, value) if isinstance(value, list) else _number(where, value)


def _text(where: str, value: Any) -> str:
    if not isinstance(value, str):
        raise _fail(where, "be a string", value)
    return value


def _flag(where: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise _fail(where, "be true or false", value)
    return value


def _table(where: str, value: Any) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise _fail(where, "be a table", value)
    return value


def _check_keys(where: str, table: Mapping[str, Any], allowed: tuple[str, ...]) -> None:
    for key in table:
        if key not in allowed:
            hint = suggestion(key, allowed) or f" Valid keys: {', '.join(allowed)}."
            raise SceneError(f"Unknown key {key!r} in [{where}].{hint}")


def _require(where: str, table: Mapping[str, Any], key: str) -> Any:
    if key not in table:
        raise SceneError(f"The [{where}] section needs the key {key!r}.")
    return table[key]


def _exclusive(where: str, table: Mapping[str, Any], *keys: str) -> None:
    given = [k for k in keys if k in table]
    if len(given) > 1:
        raise SceneError(f"In [{where}] give only one of {', '.join(map(repr, keys))}; got {given}.")


def _kind(section: str, table: Mapping[str, Any], kind_keys: Mapping[str, tuple[str, ...]],
          required: Mapping[str, tuple[str, ...]], common: tuple[str, ...]) -> str:
    """Read ``kind``, then refuse keys that kind does not take and require the ones it needs."""
    kind = _choice(f"{section}.kind", _require(section, table, "kind"), kind_keys)
    _check_keys(section, table, (*common, *kind_keys[kind]))
    for key in required[kind]:
        _require(section, table, key)
    return kind


def _signal_table(where: str, value: Any, *, vector: bool = False) -> float | dict[str, Any]:
    """A constant, or a piecewise-constant table ``{times = [...], values = [...]}`` of numbers.

    Only the form is checked here; the order of the times and the number of values are the
    rules of :class:`~toolkit.model.PiecewiseConstant`, checked when it is built.
    """
    if not isinstance(value, dict):
        return _number(where, value)
    _check_keys(where, value, ("times", "values"))
    times = _numbers(f"{where}.times", _require(where, value, "times"))
    raw = _require(where, value, "values")
    if not isinstance(raw, list) or not raw:
        raise _fail(f"{where}.values", "be a non-empty array", raw)
    values: list[Any] = []
    for i, item in enumerate(raw):
        values.append(_numbers(f"{where}.values[{i}]", item) if vector else _number(f"{where}.values[{i}]", item))
    return {"times": times, "values": tuple(values)}


# -- sections --------------------------------------------------------------------------------

@dataclass(frozen=True)
class ContactsSpec:
    """``[contacts]``: speeds (m/s) and friction magnitudes (N).

    ``speeds`` or ``random = {n, low, high, seed}`` (uniform speeds drawn with NumPy's
    default generator from ``seed``); ``forces`` (N, scalar or per contact) or ``mu`` and
    ``normal_loads`` (N) with ``f_i = mu_i N_i``; neither means 1 N each.
    """

    speeds: tuple[float, ...] | None = None
    random: dict[str, Any] | None = None
    forces: float | tuple[float, ...] | None = None
    mu: float | tuple[float, ...] | None = None
    normal_loads: float | tuple[float, ...] | None = None

    KEYS = ("speeds", "random", "forces", "mu", "normal_loads")

    @classmethod
    def parse(cls, table: dict[str, Any]) -> ContactsSpec:
        _check_keys("contacts", table, cls.KEYS)
        _exclusive("contacts", table, "speeds", "random")
        _exclusive("contacts", table, "forces", "mu")
        if "speeds" not in table and "random" not in table:
            raise SceneError("The [contacts] section needs 'speeds' (m/s) or 'random' = {n, low, high, seed}.")
        if ("mu" in table) != ("normal_loads" in table):
            raise SceneError("In [contacts] 'mu' and 'normal_loads' go together (f_i = mu_i * N_i).")
        random = None
        if "random" in table:
            raw = _table("contacts.random", table["random"])
            _check_keys("contacts.random", raw, ("n", "low", "high", "seed"))
            random = {"n": _integer("contacts.random.n", _require("contacts.random", raw, "n")),
                      "low": _number("contacts.random.low", _require("contacts.random", raw, "low")),
                      "high": _number("contacts.random.high", _require("contacts.random", raw, "high")),
                      "seed": _integer("contacts.random.seed", raw.get("seed", 0))}
        return cls(
            speeds=_numbers("contacts.speeds", table["speeds"]) if "speeds" in table else None,
            random=random,
            forces=_scalar_or_numbers("contacts.forces", table["forces"]) if "forces" in table else None,
            mu=_scalar_or_numbers("contacts.mu", table["mu"]) if "mu" in table else None,
            normal_loads=(_scalar_or_numbers("contacts.normal_loads", table["normal_loads"])
                          if "normal_loads" in table else None),
        )

    @property
    def n(self) -> int:
        """Number of contacts declared."""
        return self.random["n"] if self.random is not None else len(self.speeds)  # type: ignore[arg-type]


@dataclass(frozen=True)
class BodySpec:
    """``[body]``: moving inertia ``mass`` (kg) or ``inertia`` (kg m^2) with ``contact_radius``
    (m, ``mass = inertia / contact_radius**2``); ``damping`` (N s/m); ``external_force`` (N,
    a constant or a piecewise-constant table ``{times = [t_1..t_k], values = [f_0..f_k]}``:
    ``f_0`` before ``t_1``, ``f_j`` from ``t_j`` on, so one value more than times)."""

    mass: float | None = None
    inertia: float | None = None
    contact_radius: float | None = None
    damping: float = 0.0
    external_force: float | dict[str, Any] = 0.0

    KEYS = ("mass", "inertia", "contact_radius", "damping", "external_force")

    @classmethod
    def parse(cls, table: dict[str, Any]) -> BodySpec:
        _check_keys("body", table, cls.KEYS)
        _exclusive("body", table, "mass", "inertia")
        if "mass" not in table and "inertia" not in table:
            raise SceneError("The [body] section needs 'mass' (kg) or 'inertia' (kg m^2) with 'contact_radius' (m).")
        if "inertia" in table and "contact_radius" not in table:
            raise SceneError("In [body] 'inertia' needs 'contact_radius' (m): mass = inertia / contact_radius**2.")
        get = table.get
        return cls(
            mass=_number("body.mass", table["mass"]) if "mass" in table else None,
            inertia=_number("body.inertia", table["inertia"]) if "inertia" in table else None,
            contact_radius=(_number("body.contact_radius", table["contact_radius"])
                            if "contact_radius" in table else None),
            damping=_number("body.damping", get("damping", 0.0)),
            external_force=_signal_table("body.external_force", get("external_force", 0.0)),
        )

    @property
    def moving_mass(self) -> float:
        """Moving inertia at the contacts, kg (``inertia / contact_radius**2`` when given so)."""
        if self.mass is not None:
            return self.mass
        return self.inertia / self.contact_radius**2  # type: ignore[operator]


@dataclass(frozen=True)
class MotorsSpec:
    """``[motors]``: ``speed_limit`` (m/s, symmetric) or ``speed_limits = [lo, hi]``; ``lag``
    (s, first-order time constant); ``rate_limit`` (m/s^2); ``compliance`` ((m/s)/N, speed
    droop per newton of contact force); ``backlash`` (m at the contact, the drive's gearbox
    play; simulated by ``method = "moreau"`` only, refused by the other methods); ``clip``
    (default false: contact speeds and
    ``simulation.commands`` beyond the speed limits are refused; true: they are clipped to
    the limits and the study reports a shortfall)."""

    speed_limits: tuple[float, float] = (-math.inf, math.inf)
    lag: float = 0.0
    rate_limit: float = math.inf
    compliance: float = 0.0
    backlash: float = 0.0
    clip: bool = False
    speed_limit: float | None = None

    KEYS = ("speed_limit", "speed_limits", "lag", "rate_limit", "compliance", "backlash", "clip")

    @classmethod
    def parse(cls, table: dict[str, Any]) -> MotorsSpec:
        _check_keys("motors", table, cls.KEYS)
        _exclusive("motors", table, "speed_limit", "speed_limits")
        limits: tuple[float, float] = (-math.inf, math.inf)
        v_max = None
        if "speed_limit" in table:
            v_max = _number("motors.speed_limit", table["speed_limit"])
            limits = (-v_max, v_max)
        elif "speed_limits" in table:
            pair = _numbers("motors.speed_limits", table["speed_limits"])
            if len(pair) != 2:
                raise _fail("motors.speed_limits", "be a pair [lo, hi]", list(pair))
            limits = (pair[0], pair[1])
        return cls(
            speed_limit=v_max,
            speed_limits=limits,
            lag=_number("motors.lag", table.get("lag", 0.0)),
            rate_limit=_number("motors.rate_limit", table.get("rate_limit", math.inf), allow_inf=True),
            compliance=_number("motors.compliance", table.get("compliance", 0.0)),
            backlash=_number("motors.backlash", table.get("backlash", 0.0)),
            clip=_flag("motors.clip", table.get("clip", False)),
        )


@dataclass(frozen=True)
class SensorsSpec:
    """``[sensors]``: encoders sampled at ``rate`` (Hz). Wheel encoders: ``wheel_counts_per_rev``
    at ``wheel_radius`` (m) with gearbox ``wheel_backlash`` (m at the contact); the central
    encoder: ``central_counts_per_rev`` at ``contact_radius`` (m)."""

    rate: float = 50.0
    wheel_counts_per_rev: float | None = None
    wheel_radius: float | None = None
    wheel_backlash: float = 0.0
    central_counts_per_rev: float | None = None
    contact_radius: float | None = None

    KEYS = ("rate", "wheel_counts_per_rev", "wheel_radius", "wheel_backlash",
            "central_counts_per_rev", "contact_radius")

    @classmethod
    def parse(cls, table: dict[str, Any]) -> SensorsSpec:
        _check_keys("sensors", table, cls.KEYS)
        for a, b in (("wheel_counts_per_rev", "wheel_radius"), ("central_counts_per_rev", "contact_radius")):
            if (a in table) != (b in table):
                raise SceneError(f"In [sensors] {a!r} and {b!r} go together.")
        def optional(key: str) -> float | None:
            return _number(f"sensors.{key}", table[key]) if key in table else None
        return cls(
            rate=_number("sensors.rate", table.get("rate", 50.0)),
            wheel_counts_per_rev=optional("wheel_counts_per_rev"),
            wheel_radius=optional("wheel_radius"),
            wheel_backlash=_number("sensors.wheel_backlash", table.get("wheel_backlash", 0.0)),
            central_counts_per_rev=optional("central_counts_per_rev"),
            contact_radius=optional("contact_radius"),
        )


@dataclass(frozen=True)
class TargetSpec:
    """``[target]``: what the allocation stage should realize.

    ``kind = "force_curve"``: ``speeds`` (m/s), ``forces`` (N), optional ``weights``;
    ``kind = "viscosity"``: ``slope`` (N s/m), ``center`` (m/s), ``band`` (m/s, half-width);
    ``kind = "friction_fraction"``: ``fraction`` (mu/mu0 in [0, 1]), ``band`` (m/s);
    ``kind = "equilibrium_speed"``: ``speed`` (m/s), ``margin`` (an integer >= 0, default 0:
    a count of contacts, not a speed: the equilibrium must stay at ``speed`` even when that
    many contacts fail, i.e. the magnitude ``W`` at ``speed`` and those ``L`` below and ``U``
    above satisfy ``W >= |U - L| + 2 * (sum of the margin largest magnitudes)``).
    Common keys: ``method`` (solver name; default: chosen), ``strict`` (refuse instead of
    project), ``dt`` (s: with ``[motors] rate_limit``, each contact may move at most
    ``rate_limit * dt`` from its current speed), ``fixed``, ``failed``, ``liftable`` (lists
    of contact indices), ``time_limit`` (s, MILP budget).
    """

    kind: str
    params: dict[str, Any] = field(default_factory=dict)
    method: str | None = None
    strict: bool = False
    dt: float | None = None
    fixed: tuple[int, ...] = ()
    failed: tuple[int, ...] = ()
    liftable: tuple[int, ...] = ()
    time_limit: float = 30.0

    COMMON = ("kind", "method", "strict", "dt", "fixed", "failed", "liftable", "time_limit")

    _KIND_KEYS = {
        "force_curve": ("speeds", "forces", "weights"),
        "viscosity": ("slope", "center", "band"),
        "friction_fraction": ("fraction", "band"),
        "equilibrium_speed": ("speed", "margin"),
    }
    _REQUIRED = {
        "force_curve": ("speeds", "forces"),
        "viscosity": ("slope", "center", "band"),
        "friction_fraction": ("fraction", "band"),
        "equilibrium_speed": ("speed",),
    }

    @classmethod
    def parse(cls, table: dict[str, Any]) -> TargetSpec:
        kind = _kind("target", table, cls._KIND_KEYS, cls._REQUIRED, cls.COMMON)
        params: dict[str, Any] = {}
        for key in cls._KIND_KEYS[kind]:
            if key not in table:
                continue
            where = f"target.{key}"
            if key in ("speeds", "forces", "weights"):
                params[key] = _numbers(where, table[key])
            elif key == "margin":
                params[key] = _integer(where, table[key])
            elif key == "band":
                params[key] = _scalar_or_numbers(where, table[key])
            else:
                params[key] = _number(where, table[key])
        def indices(key: str) -> tuple[int, ...]:
            raw = table.get(key, [])
            if not isinstance(raw, list):
                raise _fail(f"target.{key}", "be a list of contact indices", raw)
            return tuple(_integer(f"target.{key}[{i}]", item) for i, item in enumerate(raw))

        method = _text("target.method", table["method"]) if "method" in table else None
        return cls(kind=kind, params=params, method=method,
                   strict=_flag("target.strict", table.get("strict", False)),
                   dt=_number("target.dt", table["dt"]) if "dt" in table else None,
                   fixed=indices("fixed"), failed=indices("failed"), liftable=indices("liftable"),
                   time_limit=_number("target.time_limit", table.get("time_limit", 30.0)))


@dataclass(frozen=True)
class ScheduleSpec:
    """``[schedule]``: a time-varying contact-speed design (:func:`toolkit.design_schedule`).

    ``kind = "braking"``: ``speed`` (m/s, the speed to brake to), optional ``duration`` (s;
    default: as fast as possible); ``kind = "track"``: ``times`` (s) and ``speeds`` (m/s) of
    the body-speed trajectory. Common: ``v0`` (m/s), ``period`` (s, controller period,
    default 0.02), ``epsilon`` (m/s, smoothing width of the optimizer, default 1e-3),
    ``horizon`` (s), ``time_limit`` (s, default 30).
    """

    kind: str
    params: dict[str, Any] = field(default_factory=dict)
    v0: float = 0.0
    period: float = 0.02
    epsilon: float = 1e-3
    horizon: float | None = None
    time_limit: float = 30.0

    _KIND_KEYS = {"braking": ("speed", "duration"), "track": ("times", "speeds")}
    _REQUIRED = {"braking": ("speed",), "track": ("times", "speeds")}

    @classmethod
    def parse(cls, table: dict[str, Any]) -> ScheduleSpec:
        kind = _kind("schedule", table, cls._KIND_KEYS, cls._REQUIRED,
                     ("kind", "v0", "period", "epsilon", "horizon", "time_limit"))
        params: dict[str, Any] = {}
        for key in cls._KIND_KEYS[kind]:
            if key in table:
                where = f"schedule.{key}"
                params[key] = (_numbers(where, table[key]) if key in ("times", "speeds")
                               else _number(where, table[key]))

        def positive(key: str, default: float | None) -> float | None:
            return _number(f"schedule.{key}", table[key]) if key in table else default

        return cls(kind=kind, params=params, v0=_number("schedule.v0", table.get("v0", 0.0)),
                   period=positive("period", 0.02), epsilon=positive("epsilon", 1e-3),
                   horizon=positive("horizon", None), time_limit=positive("time_limit", 30.0))


@dataclass(frozen=True)
class SimulationSpec:
    """``[simulation]``: ``t_end`` (s), ``v0`` (m/s), ``method`` (default ``"exact"``),
    ``options`` (a table passed to :func:`toolkit.simulate`; its ``budget`` table, with keys
    ``wall_time`` (s), ``max_steps``, ``max_event_rate`` (1/s) and ``max_samples``, becomes a
    :class:`toolkit.simulation.Budget`), ``commands`` (piecewise-constant contact-speed
    commands ``{times, values}``: ``values`` has one entry more than ``times``, each a list of
    n speeds in m/s within the motors' speed limits)."""

    t_end: float
    v0: float = 0.0
    method: str = "exact"
    options: dict[str, Any] = field(default_factory=dict)
    commands: dict[str, Any] | None = None

    KEYS = ("t_end", "v0", "method", "options", "commands")

    @classmethod
    def parse(cls, table: dict[str, Any]) -> SimulationSpec:
        _check_keys("simulation", table, cls.KEYS)
        commands = None
        if "commands" in table:
            commands = _signal_table("simulation.commands", _table("simulation.commands", table["commands"]),
                                     vector=True)
        return cls(
            t_end=_number("simulation.t_end", _require("simulation", table, "t_end")),
            v0=_number("simulation.v0", table.get("v0", 0.0)),
            method=_text("simulation.method", table.get("method", "exact")),
            options=dict(_table("simulation.options", table.get("options", {}))),
            commands=commands,  # type: ignore[arg-type]
        )



#: Controllers a ``[control]`` section may name, with the keys each takes.
CONTROLLERS = {"viscosity": ("slope", "reference", "band"),
               "speed_hold": ("reference", "slope", "kp", "ki"),
               "friction_brake": ("fraction", "start", "hold"),
               "open_loop": ()}
_CONTROLLER_REQUIRED = {"viscosity": ("slope",), "speed_hold": ("reference", "slope"),
                        "friction_brake": ("fraction",), "open_loop": ()}
#: ``[estimation] scenario`` values and the keys only each takes.
SCENARIOS = {"brake": ("duration", "brake_time", "cruise", "brake", "spread", "friction_spread"),
             "simulation": ()}
_NOISE_KEYS = ("missed_count_prob", "count_noise", "jitter")
#: Sub-tables of ``[estimation]`` and ``[control]``: ``truth`` (how the simulated world departs
#: from the scene, :class:`~toolkit.model.truth.WorldTruth`) and ``model`` (what the estimators
#: are told beyond the scene, :class:`~toolkit.estimation.ModelPrior`), key for key.
TRUTH_KEYS = tuple(item.name for item in fields(WorldTruth))
MODEL_KEYS = tuple(item.name for item in fields(ModelPrior))
_PAIRS = ("drag_range", "lag_range")


def _knowledge(where: str, value: Any, keys: tuple[str, ...]) -> dict[str, Any]:
    """A ``truth`` or ``model`` sub-table: known keys, numbers (pairs for the ranges)."""
    table = _table(where, value)
    _check_keys(where, table, keys)
    return {key: (_numbers(f"{where}.{key}", item) if key in _PAIRS else _number(f"{where}.{key}", item))
            for key, item in table.items()}


def _names(where: str, value: Any) -> tuple[str, ...]:
    """A non-empty list of distinct names (which names exist is the build's rule)."""
    if not isinstance(value, list) or not value:
        raise _fail(where, "be a non-empty list of names", value)
    names = tuple(_text(f"{where}[{i}]", item) for i, item in enumerate(value))
    if len(set(names)) != len(names):
        raise _fail(where, "name each method once", list(names))
    return names


def _choice(where: str, value: Any, choices: Any) -> str:
    text = _text(where, value)
    if text not in choices:
        raise SceneError(f"The {where!r} value in the scene must be one of {list(choices)}. "
                         f"Got {text!r} instead.{suggestion(text, choices)}")
    return text


def _matrix(where: str, value: Any) -> tuple[tuple[float, ...], ...]:
    """A non-empty list of equally long rows of finite numbers (its rules: the constructor's)."""
    if not isinstance(value, list) or not value or not all(isinstance(row, list) for row in value):
        raise _fail(where, "be a matrix (a list of rows of numbers)", value)
    rows = tuple(_numbers(f"{where}[{i}]", row) for i, row in enumerate(value))
    if len({len(row) for row in rows}) != 1:
        raise _fail(where, "have rows of one length", [list(r) for r in rows])
    return rows


@dataclass(frozen=True)
class EstimationSpec:
    """``[estimation]``: estimate the body speed from simulated encoder counts (needs
    ``[sensors]`` with both encoders and ``[body]``).

    ``methods`` (names from :data:`toolkit.estimation.ESTIMATOR_NAMES`; default all but ``"kalman_nominal"`` and
    ``"ukf"``: the practitioner's baselines, the default Kalman filter and the smoother);
    ``scenario``: ``"brake"`` (default: the contacts at ``cruise + linspace(-spread,
    spread, n)`` m/s from rest, then at ``brake + ...`` from ``brake_time`` s, over
    ``duration`` s; defaults 0.2, 0.05, -0.1, 5, 10) or ``"simulation"`` (the scene's own
    ``[simulation]``, exact, recorded over its ``t_end``). A ``brake_time`` (or a command
    switch) between two samples is honoured: the motors get the new command at that instant,
    and the record, which carries only what the device logs (the commands sent at each
    sample), shows it from the first sample at or after it. ``seed`` (integer, the sensors',
    friction and wander draws and where the encoders' count grids start, so that each seed is
    another phase of the quantization); ``friction_spread`` (relative std of each true ``f_i`` around the
    declared one, drawn once; the model-based estimators are told the spread, not the
    draw); ``missed_count_prob``, ``count_noise`` (counts), ``jitter`` (s) of the encoders;
    ``speed_std`` (m/s, > 0, default 1e-4: the std of the filters' prior on the start speed,
    which the scenario knows, rest or ``simulation.v0``); ``initial_covariance`` (2 x 2,
    symmetric positive definite: m^2, m^2/s, (m/s)^2; the filters' whole prior on (position,
    speed), replacing ``speed_std``). The keys above are *declared*: the estimators are told
    them. Two sub-tables keep truth and belief apart: ``truth`` (:data:`TRUTH_KEYS`, how the
    simulated world departs from the scene without the estimators being told, drawn from
    ``seed``: :class:`~toolkit.model.truth.WorldTruth`) and ``model`` (:data:`MODEL_KEYS`, the
    estimators' prior knowledge beyond the scene: :class:`~toolkit.estimation.ModelPrior`).
    """

    methods: tuple[str, ...] = ("central_difference", "wheel_difference", "foaw_end", "foaw_best", "alpha_beta",
                                "kalman", "rts")
    scenario: str = "brake"
    duration: float | None = None
    brake_time: float = 5.0
    cruise: float = 0.2
    brake: float = -0.1
    spread: float = 0.05
    seed: int = 0
    friction_spread: float = 0.0
    missed_count_prob: float = 0.0
    count_noise: float = 0.0
    jitter: float = 0.0
    speed_std: float = 1e-4
    initial_covariance: tuple[tuple[float, ...], ...] | None = None
    truth: dict[str, Any] | None = None
    model: dict[str, Any] | None = None

    KEYS = ("methods", "scenario", "duration", "brake_time", "cruise", "brake", "spread", "seed",
            "friction_spread", *_NOISE_KEYS, "speed_std", "initial_covariance", "truth", "model")

    @classmethod
    def parse(cls, table: dict[str, Any]) -> EstimationSpec:
        _check_keys("estimation", table, cls.KEYS)
        scenario = _choice("estimation.scenario", table.get("scenario", "brake"), SCENARIOS)
        for other, keys in SCENARIOS.items():
            for key in keys:
                if key in table and key not in SCENARIOS[scenario]:
                    raise SceneError(f"The [estimation] key {key!r} belongs to scenario = {other!r}; "
                                     f"scenario = {scenario!r} does not take it.")
        get = table.get
        return cls(
            methods=(_names("estimation.methods", table["methods"])
                     if "methods" in table else cls.methods),
            scenario=scenario,
            duration=_number("estimation.duration", table["duration"]) if "duration" in table else None,
            brake_time=_number("estimation.brake_time", get("brake_time", 5.0)),
            cruise=_number("estimation.cruise", get("cruise", 0.2)),
            brake=_number("estimation.brake", get("brake", -0.1)),
            spread=_number("estimation.spread", get("spread", 0.05)),
            seed=_integer("estimation.seed", get("seed", 0)),
            friction_spread=_number("estimation.friction_spread", get("friction_spread", 0.0)),
            **{key: _number(f"estimation.{key}", get(key, 0.0)) for key in _NOISE_KEYS},
            speed_std=_number("estimation.speed_std", get("speed_std", 1e-4)),
            initial_covariance=(_matrix("estimation.initial_covariance", table["initial_covariance"])
                                if "initial_covariance" in table else None),
            truth=_knowledge("estimation.truth", table["truth"], TRUTH_KEYS) if "truth" in table else None,
            model=_knowledge("estimation.model", table["model"], MODEL_KEYS) if "model" in table else None,
        )

    @property
    def record_duration(self) -> float:
        """Length of the brake scenario's record, s (default 10)."""
        return 10.0 if self.duration is None else self.duration


@dataclass(frozen=True)
class ControlSpec:
    """``[control]``: a closed loop at the sample rate (needs ``[body]``).

    ``controller`` (one of :data:`CONTROLLERS`) and its parameters: ``"viscosity"``:
    ``slope`` (N s/m), ``reference`` (m/s, default 0), ``band`` (m/s, optional);
    ``"speed_hold"``: ``reference`` (m/s), ``slope`` (N s/m), ``kp`` (default 0.5), ``ki``
    (1/s, default 5); ``"friction_brake"``: ``fraction`` (mu/mu0 in [0, 1]), ``start`` (s,
    default 0), ``hold`` (m/s, optional); ``"open_loop"``: replays the scene's designed
    ``[schedule]``. Common: ``duration`` (s, default 10), ``v0`` (m/s, default 0),
    ``sensors`` (true: read the ``[sensors]`` encoders through ``estimator``; false: the
    ideal loop on the true speed; default: true when the scene has ``[sensors]``),
    ``estimator`` (any name of :data:`toolkit.estimation.ESTIMATOR_NAMES` but ``"rts"``, default ``"kalman"``), ``rate`` (Hz, the
    ideal loop's; with sensors theirs), ``seed`` (integer), ``missed_count_prob``,
    ``count_noise`` (counts), ``jitter`` (s), ``budget`` (``{wall_time, max_steps,
    max_event_rate, max_samples}`` of each plant step: s, count, 1/s, count), ``truth`` and
    ``model`` (sub-tables as in :class:`EstimationSpec`: the loop runs on the true world, its
    estimator is told the scene and the model only), ``cross_check`` (true: also
    simulate the loop as a python-control interconnection, :mod:`toolkit.loop.interop`, and
    report the largest difference).
    """

    controller: str
    params: dict[str, Any] = field(default_factory=dict)
    duration: float = 10.0
    v0: float = 0.0
    sensors: bool | None = None
    estimator: str | None = None
    rate: float | None = None
    seed: int = 0
    missed_count_prob: float = 0.0
    count_noise: float = 0.0
    jitter: float = 0.0
    budget: dict[str, Any] | None = None
    cross_check: bool = False
    truth: dict[str, Any] | None = None
    model: dict[str, Any] | None = None

    COMMON = ("controller", "duration", "v0", "sensors", "estimator", "rate", "seed", *_NOISE_KEYS,
              "budget", "cross_check", "truth", "model")

    @classmethod
    def parse(cls, table: dict[str, Any]) -> ControlSpec:
        kind = _choice("control.controller", _require("control", table, "controller"), CONTROLLERS)
        _check_keys("control", table, (*cls.COMMON, *CONTROLLERS[kind]))
        for key in _CONTROLLER_REQUIRED[kind]:
            _require("control", table, key)
        params = {key: _number(f"control.{key}", table[key]) for key in CONTROLLERS[kind] if key in table}
        get = table.get
        budget = None
        if "budget" in table:
            budget = dict(_table("control.budget", table["budget"]))
            _check_keys("control.budget", budget, tuple(item.name for item in fields(Budget)))
        return cls(
            controller=kind, params=params,
            duration=_number("control.duration", get("duration", 10.0)),
            v0=_number("control.v0", get("v0", 0.0)),
            sensors=_flag("control.sensors", table["sensors"]) if "sensors" in table else None,
            estimator=_text("control.estimator", table["estimator"]) if "estimator" in table else None,
            rate=_number("control.rate", table["rate"]) if "rate" in table else None,
            seed=_integer("control.seed", get("seed", 0)),
            **{key: _number(f"control.{key}", get(key, 0.0)) for key in _NOISE_KEYS},
            budget=budget,
            cross_check=_flag("control.cross_check", get("cross_check", False)),
            truth=_knowledge("control.truth", table["truth"], TRUTH_KEYS) if "truth" in table else None,
            model=_knowledge("control.model", table["model"], MODEL_KEYS) if "model" in table else None,
        )


@dataclass(frozen=True)
class ReportSpec:
    """``[report]``: ``plots`` (write PNG figures; needs matplotlib), ``curve_points`` (samples of
    the force-speed curve in the JSON output)."""

    plots: bool = True
    curve_points: int = 801

    KEYS = ("plots", "curve_points")

    @classmethod
    def parse(cls, table: dict[str, Any]) -> ReportSpec:
        _check_keys("report", table, cls.KEYS)
        return cls(plots=_flag("report.plots", table.get("plots", True)),
                   curve_points=_integer("report.curve_points", table.get("curve_points", 801)))


@dataclass(frozen=True)
class SweepSpec:
    """``[sweep]``: many seeded runs of one of the paper's experiments (:func:`toolkit.sweep`).

    ``experiment`` (one of :data:`toolkit.experiments.EXPERIMENTS`), ``runs`` (count, default
    1000, at most :data:`toolkit.sweeps.MAX_RUNS`), ``seed`` (root seed, default 0),
    ``chunk_size`` (runs per chunk, optional; results do not depend on it), ``statistics``
    (the summary statistics ``--json`` prints, default all), and any parameter of the
    experiment's class, each checked by its constructor:

    - ``median_law`` (:class:`~toolkit.experiments.MedianLaw`): ``n``, ``speed_limit`` (m/s),
      ``acceleration`` (m/s^2), ``mass`` (kg), ``friction_spread`` (relative), ``damping`` (N
      s/m), ``wheel_radius_bias``, ``wheel_radius_std``, ``contact_radius_error`` (relative),
      ``compliance`` ((m/s)/N), ``settle_time`` (s), ``wheel_seed``;
    - ``mean_median`` (:class:`~toolkit.experiments.MeanMedian`): ``held``, ``level``, ``gap``,
      ``median_range`` (m/s), ``n``, ``speed_limit`` (m/s), ``acceleration`` (m/s^2),
      ``settle_time`` (s), ``friction_spread``, ``wheel_seed``;
    - ``outliers`` (:class:`~toolkit.experiments.Outliers`): ``n``, ``outliers``, ``amplitude``
      (m/s), ``frequency`` (Hz), ``speed_limit`` (m/s), ``acceleration`` (m/s^2), ``lag`` (s),
      ``rate`` (Hz), ``settle_time``, ``window`` (s), ``random_amplitude``,
      ``friction_spread``, ``wheel_seed``, ``compliance`` ((m/s)/N);
    - ``residual_friction`` (:class:`~toolkit.experiments.ResidualFriction`): ``n``,
      ``friction_spread``, ``bearing_friction`` (N), ``bearing_drag`` (N s/m), ``speed_limit``
      (m/s), ``acceleration`` (m/s^2), ``mass`` (kg), ``probes``, ``wheel_seed``.

    ``params`` is a read-only mapping (the spec is frozen).
    """

    experiment: str
    params: Mapping[str, Any] = field(default_factory=dict)
    runs: int = 1000
    seed: int = 0
    chunk_size: int | None = None
    statistics: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))

    COMMON = ("experiment", "runs", "seed", "chunk_size", "statistics")

    @classmethod
    def parse(cls, table: dict[str, Any]) -> SweepSpec:
        from ..experiments import EXPERIMENTS

        kind = _choice("sweep.experiment", _require("sweep", table, "experiment"), EXPERIMENTS)
        names = tuple(f.name for f in fields(EXPERIMENTS[kind]))
        _check_keys("sweep", table, (*cls.COMMON, *names))
        params: dict[str, Any] = {}
        for key in names:
            if key in table:
                value = table[key]
                if not isinstance(value, (bool, int, float, str)):
                    raise _fail(f"sweep.{key}", "be a number, a string or true/false", value)
                if isinstance(value, float):
                    _number(f"sweep.{key}", value)
                params[key] = value
        statistics = ()
        if "statistics" in table:
            value = table["statistics"]
            if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
                raise _fail("sweep.statistics", "be a non-empty list of summary names", value)
            statistics = tuple(value)
        return cls(experiment=kind, params=params,
                   runs=_integer("sweep.runs", table.get("runs", 1000)),
                   seed=_integer("sweep.seed", table.get("seed", 0)),
                   chunk_size=_integer("sweep.chunk_size", table["chunk_size"]) if "chunk_size" in table else None,
                   statistics=statistics)


@dataclass(frozen=True)
class PlanarSpec:
    """``[planar]``: a rigid body on planar contacts (:mod:`toolkit.planar`).

    ``body`` = ``disc`` (``radius`` m, ``mu``), ``annulus`` (``radius``, ``inner_radius`` m,
    ``mu``), ``ring`` (a thin ring: ``radius``, ``mu``), each with uniform pressure, friction
    ``mu mass gravity`` (``gravity`` m/s^2, default 9.81) and, unless ``inertia`` (kg m^2) is
    given, the inertia of its uniform shape; or ``legs`` (``positions`` [[x, y], ...] m,
    ``velocities`` [[vx, vy], ...] m/s, ``forces`` N, ``inertia``). ``mass`` (kg); ``v0`` =
    [vx, vy] (m/s) and ``omega0`` (rad/s) at the start; ``t_end`` (s); ``method`` = ``exact``
    (default; a disc, annulus or ring, or legs on one line) / ``moreau`` (``step`` s) /
    ``smooth`` (``epsilon`` m/s); ``resolution`` (rings of a disc's quadrature, arcs of a
    ring's); ``precision = {steps = [s, ...], resolutions = [...], epsilons = [m/s, ...]}``:
    also the work-precision rows against the exact method (Moreau-Jean at each step with the
    matching quadrature resolution, the regularized law at each width).
    """

    body: str
    mass: float
    radius: float | None = None
    inner_radius: float | None = None
    mu: float | None = None
    gravity: float = 9.81
    inertia: float | None = None
    positions: tuple[tuple[float, ...], ...] | None = None
    velocities: tuple[tuple[float, ...], ...] | None = None
    forces: tuple[float, ...] | None = None
    v0: tuple[float, ...] = (0.0, 0.0)
    omega0: float = 0.0
    t_end: float = 1.0
    method: str = "exact"
    step: float | None = None
    resolution: int | None = None
    epsilon: float | None = None
    precision: dict[str, Any] | None = None

    COMMON = ("body", "mass", "inertia", "v0", "omega0", "t_end", "method", "step", "resolution",
              "epsilon", "precision")
    _BODY_KEYS = {"disc": ("radius", "mu", "gravity"), "annulus": ("radius", "inner_radius", "mu", "gravity"),
                  "ring": ("radius", "mu", "gravity"), "legs": ("positions", "velocities", "forces")}
    _REQUIRED = {"disc": ("radius", "mu"), "annulus": ("radius", "inner_radius", "mu"),
                 "ring": ("radius", "mu"), "legs": ("positions", "velocities", "forces", "inertia")}
    METHODS = ("exact", "moreau", "smooth")

    @classmethod
    def parse(cls, table: dict[str, Any]) -> PlanarSpec:
        body = _choice("planar.body", _require("planar", table, "body"), cls._BODY_KEYS)
        _check_keys("planar", table, (*cls.COMMON, *cls._BODY_KEYS[body]))
        for key in ("mass", *cls._REQUIRED[body]):
            _require("planar", table, key)
        method = _choice("planar.method", table.get("method", "exact"), cls.METHODS)
        if method == "smooth" and "epsilon" not in table:
            raise SceneError("The [planar] section needs the key 'epsilon' (m/s) with method = 'smooth'.")

        def optional(key: str, read: Callable[[str, Any], Any]) -> Any:
            return read(f"planar.{key}", table[key]) if key in table else None

        def points(key: str) -> tuple[tuple[float, ...], ...] | None:
            if key not in table:
                return None
            raw = table[key]
            if not isinstance(raw, list) or not raw:
                raise _fail(f"planar.{key}", "be a non-empty array of [x, y] pairs", raw)
            return tuple(_numbers(f"planar.{key}[{i}]", item) for i, item in enumerate(raw))

        precision = None
        if "precision" in table:
            raw = _table("planar.precision", table["precision"])
            _check_keys("planar.precision", raw, ("steps", "resolutions", "epsilons"))
            precision = {k: _numbers(f"planar.precision.{k}", raw[k]) for k in ("steps", "epsilons") if k in raw}
            if "resolutions" in raw:
                values = raw["resolutions"]
                if not isinstance(values, list) or not values:
                    raise _fail("planar.precision.resolutions", "be a non-empty array of integers", values)
                precision["resolutions"] = tuple(_integer(f"planar.precision.resolutions[{i}]", v)
                                                 for i, v in enumerate(values))
                if len(precision["resolutions"]) != len(precision.get("steps", (4e-3, 2e-3, 1e-3))):
                    raise SceneError("In [planar.precision] give one resolution per step.")
        return cls(
            body=body, mass=_number("planar.mass", table["mass"]),
            radius=optional("radius", _number), inner_radius=optional("inner_radius", _number),
            mu=optional("mu", _number), gravity=_number("planar.gravity", table.get("gravity", 9.81)),
            inertia=optional("inertia", _number), positions=points("positions"),
            velocities=points("velocities"), forces=optional("forces", _numbers),
            v0=_numbers("planar.v0", table.get("v0", [0.0, 0.0])),
            omega0=_number("planar.omega0", table.get("omega0", 0.0)),
            t_end=_number("planar.t_end", table.get("t_end", 1.0)), method=method,
            step=optional("step", _number), resolution=optional("resolution", _integer),
            epsilon=optional("epsilon", _number), precision=precision)


_SECTIONS: dict[str, Callable[[dict[str, Any]], Any]] = {
    "contacts": ContactsSpec.parse, "body": BodySpec.parse, "motors": MotorsSpec.parse,
    "sensors": SensorsSpec.parse, "target": TargetSpec.parse, "schedule": ScheduleSpec.parse,
    "simulation": SimulationSpec.parse, "estimation": EstimationSpec.parse,
    "control": ControlSpec.parse, "report": ReportSpec.parse, "sweep": SweepSpec.parse,
    "planar": PlanarSpec.parse,
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
    allowed = ("scene", *_SECTIONS)
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
    _check_keys("scene", meta, ("name", "description"))
    if "sweep" in data:
        _alone(data, "sweep", _SWEEP_SECTIONS, "its model in [sweep] (each run draws its own contacts)")
    elif "planar" in data:
        _alone(data, "planar", _PLANAR_SECTIONS, "its body and contacts in [planar]")
    elif "contacts" not in data:
        raise SceneError(f"The {where} needs a [contacts] section.")
    sections = {key: _SECTIONS[key](value) for key, value in data.items() if key in _SECTIONS}
    scene_name = _text("scene.name", meta.get("name", name))
    if not _NAME.fullmatch(scene_name):
        raise _fail("scene.name", "be a plain name of letters, digits, '_', '.' and '-' (it names the "
                    "output folder)", scene_name)
    return Scene(name=scene_name, description=_text("scene.description", meta.get("description", "")),
                 **{"contacts": None, **sections})


def load_scene(path: str | Path) -> Scene:
    """Read a scene file and check its form (no objects are built: :func:`~toolkit.scenes.build.build_scene`).

    Parameters
    ----------
    path : str or Path
        A TOML scene file (see the module docstring for the sections; SI units).

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


def _plain(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def _section_table(spec: Any) -> dict[str, Any]:
    table: dict[str, Any] = {}
    defaults = (type(spec)() if type(spec) in (MotorsSpec, SensorsSpec, ReportSpec, EstimationSpec)
                else ControlSpec(spec.controller) if type(spec) is ControlSpec else None)
    for item in fields(spec):
        if not item.init:
            continue
        value = getattr(spec, item.name)
        if value is None or (defaults is not None and value == getattr(defaults, item.name)):
            continue
        if isinstance(value, float) and math.isinf(value):
            continue
        table[item.name] = _plain(value)
    return table


def dumps_scene(scene: Scene) -> str:
    """Write a scene as TOML text that :func:`loads_scene` reads back to an equal scene."""
    data: dict[str, Any] = {"scene": {"name": scene.name}}
    if scene.description:
        data["scene"]["description"] = scene.description
    for key in _SECTIONS:
        spec = getattr(scene, key)
        if spec is None:
            continue
        if key == "schedule":
            table = {"kind": spec.kind, **_plain(spec.params), **{
                k: getattr(spec, k) for k in ("v0", "period", "epsilon", "horizon", "time_limit")
                if getattr(spec, k) is not None}}
        elif key == "target":
            table = {"kind": spec.kind, **_plain(spec.params), "strict": spec.strict,
                     "time_limit": spec.time_limit}
            for name in ("method", "dt"):
                if getattr(spec, name) is not None:
                    table[name] = getattr(spec, name)
            for name in ("fixed", "failed", "liftable"):
                if getattr(spec, name):
                    table[name] = list(getattr(spec, name))
        elif key == "sweep":
            table = {"experiment": spec.experiment, **dict(spec.params), "runs": spec.runs, "seed": spec.seed}
            if spec.chunk_size is not None:
                table["chunk_size"] = spec.chunk_size
            if spec.statistics:
                table["statistics"] = list(spec.statistics)
        elif key == "control":
            table = _section_table(spec)
            table = {"controller": spec.controller, **_plain(spec.params),
                     **{k: v for k, v in table.items() if k not in ("controller", "params")}}
        elif key == "planar":
            table = {k: v for k, v in _section_table(spec).items()
                     if not (k == "gravity" and v == 9.81) and not (k == "method" and v == "exact")}
        elif key == "motors":
            table = _section_table(spec)
            limits = table.pop("speed_limits", None)
            if "speed_limit" not in table and limits is not None and all(math.isfinite(x) for x in limits):
                table["speed_limits"] = limits
        else:
            table = _section_table(spec)
        data[key] = table
    return tomli_w.dumps(data)
