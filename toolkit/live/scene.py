"""A scene's live loop: its ``[control]`` controller and estimator on its ``[sensors]``, and the
device named on the command line (a serial port, or the scene's true world simulated).
"""

from __future__ import annotations

from typing import Any

from ..errors import DeviceError, SceneError, as_float, parameter_message
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
    """The device ``url`` names: ``"sim"`` (the scene's true world, ``[control.truth]``, as a
    :class:`~toolkit.live.SimulatedDevice`) or ``serial://PATH[?baud=N]``."""
    if url == "sim":
        from ..scenes.study import control_world
        from .simulated import DeviceWorld, SimulatedDevice

        spec = objects.scene.control
        plant, sensors, wander = control_world(objects, duration)
        world = DeviceWorld(plant, sensors, spec.v0, spec.seed, wander, objects.control.budget)
        return SimulatedDevice(world, max_duration=duration + 60.0)
    if not url.startswith("serial://"):
        raise DeviceError(parameter_message("device", "live", "be 'sim' or 'serial://PATH[?baud=N]' "
                                            "(e.g. serial:///dev/ttyACM0?baud=115200)", url))
    return SerialDevice(url)


def warm_loop(loop: LiveLoop) -> float:
    """Load the compiled kernels the loop and a simulated device run, and run the estimator
    once over a short record of its own (then reset), before any real-time work; returns the
    seconds it took (the toolkit's timing policy, :mod:`toolkit._compiled`)."""
    from .._compiled import warm

    return warm(loop.estimator.warm_up, "core", "lines")
