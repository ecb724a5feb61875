"""The loop on a rig: the scene's estimator and controller run live over a serial link
(``protocol``: the line protocol; :mod:`~toolkit.live.device`: the device
interface and a real port; :mod:`~toolkit.live.simulated`: the exact plant as a device on a
pseudo-terminal; :mod:`~toolkit.live.runner`: the per-sample loop, its deadlines and safety).
docs/live.md documents the protocol and the timing contract.
"""

from .device import Device, LinkCounts, SerialDevice, check_hello, expected_hello
from .protocol import Command, Hello, ProtocolError, Sample
from .runner import LiveLoop, LiveResult, LiveStatus, run_live
from .simulated import DeviceFaults, DeviceWorld, SimulatedDevice

__all__ = ["Device", "SerialDevice", "SimulatedDevice", "DeviceWorld", "DeviceFaults", "LinkCounts",
           "LiveLoop", "LiveResult", "LiveStatus", "run_live", "Hello", "Sample", "Command", "ProtocolError",
           "check_hello", "expected_hello"]
