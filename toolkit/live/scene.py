"""A scene's live loop: its ``[control]`` controller and estimator on its ``[sensors]``, and the
device named on the command line (a serial port, or the scene's true world simulated).
"""

from __future__ import annotations

from typing import Any
from urllib.parse import parse_qsl, urlsplit

from ..errors import DeviceError, SceneError, as_float, parameter_message, suggestion
from .device import Device, SerialDevice
from .runner import LiveLoop

__all__ = ["scene_loop", "scene_device", "warm_loop"]


def scene_loop(objects: Any, duration: float | None = None) -> LiveLoop:
    """The :class:`LiveLoop` of a built scene's ``[control]`` (``duration`` s, default
    ``control.duration``).

    Raises
    ------
    SceneError
        The scene has no ``[control]``, an open loop, or a loop that reads no encoders.
    """
    scene = objects.scene
    spec, control = scene.control, objects.control
    if spec is None or control is None:
        raise SceneError(f"The scene {scene.name!r} has no [control] section (the controller and "
                         "estimator to run live).")
    if control.controller is None or control.sensors is None:
        raise SceneError(f"The scene {scene.name!r} has control.controller = {spec.controller!r} with "
                         f"sensors = {control.sensors is not None}: a live loop needs a feedback controller "
                         "reading the [sensors] encoders (control.sensors = true).")
    duration = spec.duration if duration is None else as_float(duration, "--duration", "live", low=0.0,
                                                                 low_open=True)
    return LiveLoop(objects.plant_on(None), control.controller, control.estimator, control.sensors,
                    duration, spec.v0)


def scene_device(objects: Any, url: str, duration: float) -> Device:
    """The device ``url`` names: ``serial://PATH[?baud=N]``, or ``sim`` (the scene's true world,
    ``[control.truth]``, as a :class:`~toolkit.live.SimulatedDevice`) with optional faults and
    timing: ``sim?corrupt=0.01&silent_after=100&apply=sample`` (:class:`~toolkit.live.DeviceFaults`,
    ``SimulatedDevice(apply=...)``)."""
    if url == "sim" or url.startswith("sim?"):
        return _simulated(objects, url, duration)
    if not url.startswith("serial://"):
        raise DeviceError(parameter_message("device", "live", "be 'sim[?options]' or 'serial://PATH[?baud=N]' "
                                            "(e.g. serial:///dev/ttyACM0?baud=115200)", url))
    return SerialDevice(url)


def _simulated(objects: Any, url: str, duration: float) -> Device:
    from ..scenes.study import control_world
    from .simulated import DeviceFaults, DeviceWorld, SimulatedDevice

    options = dict(parse_qsl(urlsplit(url).query, keep_blank_values=True, strict_parsing=False))
    known = ("corrupt", "silent_after", "apply")
    for key, value in options.items():
        if key not in known:
            raise DeviceError(parameter_message("device", "live", f"take options among {list(known)}", url)
                              + suggestion(key, known))
    try:
        faults = DeviceFaults(corrupt=float(options.get("corrupt", 0.0)),
                              silent_after=int(options["silent_after"]) if "silent_after" in options else None)
    except ValueError:
        raise DeviceError(parameter_message("device", "live", "give corrupt as a probability and silent_after "
                                            "as a sequence number", url)) from None
    apply = options.get("apply", "arrival")
    if apply not in ("arrival", "sample"):
        raise DeviceError(parameter_message("device", "live", "give apply as 'arrival' or 'sample'", url))
    spec = objects.scene.control
    plant, sensors, wander = control_world(objects, duration)
    world = DeviceWorld(plant, sensors, spec.v0, spec.seed, wander, objects.control.budget)
    return SimulatedDevice(world, faults, apply=apply, max_duration=duration + 60.0)


def warm_loop(loop: LiveLoop, horizon: float = 1.0) -> float:
    """Load the compiled kernels the loop and a simulated device run, run the estimator once
    over a short record of its own, and step the host's and the plant's sides over ``horizon``
    seconds of the scene's own loop (every first-use cost paid before the real-time work and
    before a simulated device's process forks); returns the seconds it took (the toolkit's
    timing policy, :mod:`toolkit._compiled`). The estimator is reset by the run that follows."""
    import numpy as np

    from .._compiled import warm
    from ..loop.closed_loop import HostStep, PlantSide
    from ..model import sample_times

    def dry_run() -> None:
        loop.estimator.warm_up()
        plant, rate = loop.plant, loop.sensors.rate
        side = PlantSide(plant, loop.sensors, loop.v0, np.random.default_rng(0))
        loop.estimator.reset(speed=loop.v0, contact_speeds=plant.initial_speeds())
        host = HostStep(loop.controller.bind(plant, 1.0 / rate), loop.estimator, plant.initial_speeds())
        times = sample_times(min(horizon, loop.duration), rate)
        for k, t in enumerate(times.tolist()):
            central, wheel = side.read()
            _, _, u, f = host(t, central, wheel)
            if not side.hold(k, u, f, t + 1.0 / rate):
                break

    return warm(dry_run, "core", "lines")
