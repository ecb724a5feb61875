"""The closed-loop stage of a study: the controller of ``[control]`` on the scene's world,
sensed through its encoders, and its shortfalls.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._compiled import warm
from ..errors import SceneError
from ..model import sample_count
from .build import SceneObjects
from .spec import Scene
from ..schedule import ScheduleResult
from ..shortfall import Shortfall
from ..simulation import SimulationStatus
from .stages import _built, _spec, design_scene_schedule


@dataclass(frozen=True, eq=False)
class ControlStudy:
    """The closed loop of ``[control]``.

    Attributes
    ----------
    loop : ClosedLoopResult
    controller : str
        The scene's ``control.controller``.
    estimator : str or None
        The estimator's name (None: the ideal loop on the true speed).
    cross_check : CrossCheck or None
        The loop's plant against its smoothed model in python-control, width by width
        (:func:`toolkit.loop.cross_check.cross_check`; None when not asked for, or the loop
        stopped early).
    compile_time : float, s
        The one-time cost paid before the loop was timed (the kernels compiled and the loop
        run once, untimed: the policy of :mod:`toolkit._compiled`); not in the loop's
        ``wall_time``.
    """

    loop: Any
    controller: str
    estimator: str | None
    cross_check: Any = None
    compile_time: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: settings, status, final speed, estimation error, wall time, the series."""
        loop = self.loop
        error = loop.estimate - loop.speed
        return {"controller": self.controller, "estimator": self.estimator,
                "status": loop.status, "message": loop.message, "samples": int(loop.times.size),
                "final_speed": float(loop.speed[-1]), "wall_time": loop.wall_time,
                "compile_time": self.compile_time, "estimate_rms_error": float(np.sqrt(np.mean(error ** 2))),
                "estimate_max_error": float(np.max(np.abs(error))),
                "cross_check": None if self.cross_check is None else self.cross_check.to_dict(),
                "times": loop.times, "speed": loop.speed, "estimate": loop.estimate,
                "force": loop.force, "commands": loop.commands}


def control_scene(scene: Scene | SceneObjects, schedule: ScheduleResult | None = None) -> ControlStudy:
    """Run the scene's ``[control]`` closed loop (and its python-control cross check).

    Parameters
    ----------
    scene : Scene or SceneObjects
        Needs ``[control]``.
    schedule : ScheduleResult, optional
        For ``controller = "open_loop"``: the designed ``[schedule]`` (designed here when
        not given).
    """
    from ..loop.closed_loop import simulate_closed_loop

    built = _built(scene)
    spec, objects = built.scene.control, built.control
    if spec is None or objects is None:
        raise SceneError(f"The scene {built.scene.name!r} has no [control] section.")
    controller = objects.controller
    if controller is None:                                     # open loop: the designed schedule
        from ..controllers import OpenLoop

        if schedule is None:
            schedule, _ = design_scene_schedule(built)
        controller = OpenLoop(schedule)
    rate = None if objects.sensors is not None else objects.rate
    plant, sensors, wander = control_world(built, spec.duration)
    arguments = dict(sensors=sensors, estimator=objects.estimator, v0=spec.v0, seed=spec.seed,
                     budget=objects.budget)
    if wander is not None:
        arguments["wander"] = wander
    # The loop's wall time is of compiled code: the kernels loaded and the loop run once first,
    # untimed (toolkit._compiled.warm: a kernel compiles at its first call, wherever it comes).
    compile_time = warm(lambda: simulate_closed_loop(plant, controller, spec.duration, rate=rate,
                                                     **arguments), "core", "lines")
    loop = simulate_closed_loop(plant, controller, spec.duration, rate=rate, **arguments)
    check = None
    if spec.cross_check and loop.status is SimulationStatus.SUCCESS:
        from ..loop.cross_check import cross_check     # python-control: only for a cross check

        check = cross_check(plant, controller, spec.duration, rate=objects.rate, v0=spec.v0,
                            budget=objects.budget)
    name = getattr(objects.estimator, "name", None) if objects.sensors is not None else None
    return ControlStudy(loop, spec.controller, name, check, compile_time)


def control_world(scene: Scene | SceneObjects, duration: float | None = None) -> tuple[Any, Any, Any]:
    """The true world ``[control]``'s loop runs on (``[control.truth]``; the scene itself when it
    says nothing): its plant, its encoders (None for an ideal loop) and the motors' wander
    (ndarray of shape (k, n), m/s, one row per period of ``duration`` s, default
    ``control.duration``; None without wander), every draw from ``control.seed``. The loop's
    estimator knows the scene only."""
    built = _built(scene)
    spec, objects = built.scene.control, built.control
    if spec is None or objects is None:
        raise SceneError(f"The scene {built.scene.name!r} has no [control] section.")
    duration = spec.duration if duration is None else duration
    plant, truth, sensors = built.plant_on(None), objects.truth, objects.sensors
    if truth.is_nominal:
        return plant, sensors, None
    plant = truth.plant(plant, spec.seed)
    sensors = None if sensors is None else truth.sensors(sensors)
    return plant, sensors, truth.wander(sample_count(duration, objects.rate), plant.n, 1.0 / objects.rate, spec.seed)


def control_shortfalls(scene: Scene | SceneObjects, study: ControlStudy) -> list[Shortfall]:
    """A loop stopped before ``duration`` (time left, s); a cross check that does not converge
    (:attr:`toolkit.loop.cross_check.CrossCheck.converges`; its fitted order)."""
    found: list[Shortfall] = []
    loop, duration = study.loop, _spec(scene).control.duration
    if loop.status is not SimulationStatus.SUCCESS:
        reached = float(loop.times[-1]) if loop.times.size else 0.0
        found.append(Shortfall("control", f"the closed loop {loop.status.value} at t = {reached:.6g} s of "
                               f"duration = {duration:g} s ({duration - reached:.6g} s not run): "
                               f"{loop.message}", duration - reached, "s"))
    check = study.cross_check
    if check is not None and not check.converges:
        from ..loop.cross_check import ORDER_BAND

        found.append(Shortfall("control", f"the smoothed model's loop does not converge to the exact "
                               f"one: differences {', '.join(f'{d:.3g}' for d in check.differences)} m/s "
                               f"at widths {', '.join(f'{w:g}' for w in check.widths)} m/s, fitted "
                               f"order {check.order:.3g} (band {ORDER_BAND[0]:g} to {ORDER_BAND[1]:g}; "
                               f"{check.message})", check.order, "order"))
    return found
