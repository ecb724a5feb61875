"""The simulated device: the exact plant, its true encoders and the motors' wander, stepped in
real time in a process of its own and spoken to over a pseudo-terminal.

The device is the plant half of the offline closed loop (:class:`~toolkit.loop.closed_loop.PlantSide`:
:func:`~toolkit.simulation.advance` between samples, the sensor law at them) behind the line
protocol. Each command takes effect when it arrives (``apply = "arrival"``, what a rig does) or,
for a cross check with the offline loop, from its sample's instant (``apply = "sample"``). The
host sees only the serial lines; the device writes the truth (its own record with the true
speed, position and contact speeds) and its tallies to files read after the run.
"""

from __future__ import annotations

import gc
import json
import multiprocessing
import os
import select
import shutil
import signal
import tempfile
import time
import tty
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ParameterError, parameter_message
from ..model import Plant
from ..model.record_io import read_record_csv, write_record_csv
from ..model.sensors import EncoderRecord, Sensors
from ..simulation import Budget
from . import protocol
from .device import Device, LinkCounts, SerialDevice
from .protocol import Command, Hello, ProtocolError, Query, Start, Stop

__all__ = ["SimulatedDevice", "DeviceWorld", "DeviceFaults", "WATCHDOG_PERIODS"]

#: The device's watchdog: no command for this many periods sets the wheels to zero.
WATCHDOG_PERIODS = 3
_APPLY = ("arrival", "sample")


@dataclass(frozen=True, eq=False)
class DeviceWorld:
    """The true world a simulated device runs.

    Parameters
    ----------
    plant : Plant
        The true plant (its contact speeds at ``t = 0``: the motors' settled speeds).
    sensors : Sensors
        The true encoders (their noise, missed counts and jitter drawn from ``seed``).
    v0 : float, m/s
    seed : int
        Seeds the encoders' draws as the offline loop does (``default_rng(seed)``).
    wander : ndarray of shape (k, n), m/s, or None
        The motors' wander about the commands, one row per period (past the end: the last).
    budget : Budget or None
        Guards of each plant step.
    """

    plant: Plant
    sensors: Sensors
    v0: float = 0.0
    seed: int = 0
    wander: np.ndarray | None = None
    budget: Budget | None = None


@dataclass(frozen=True)
class DeviceFaults:
    """Faults a simulated device can show, for tests of the host's safety.

    Parameters
    ----------
    corrupt : float
        Probability in ``[0, 1]`` that a sample line is sent with one byte changed.
    silent_after : int or None
        Send no sample line from this sequence number on (the device keeps running).
    hello : Hello or None
        A handshake to state instead of the world's (a device built for another rig).
    seed : int
        Seeds the corruption draws.
    """

    corrupt: float = 0.0
    silent_after: int | None = None
    hello: Hello | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0.0 <= self.corrupt <= 1.0:
            raise ParameterError(parameter_message("corrupt", "DeviceFaults", "lie in [0, 1]", self.corrupt))


class SimulatedDevice(Device):
    """A :class:`DeviceWorld` in its own process, on a pseudo-terminal that the host opens with
    pyserial exactly as a real port (:class:`~toolkit.live.device.SerialDevice`).

    Parameters
    ----------
    world : DeviceWorld
    faults : DeviceFaults, optional
    apply : {"arrival", "sample"}
        When a command takes effect: when it arrives (default), or from its sample's instant
        (the offline loop's idealization; the device then steps the plant over a period only
        once its command came or the period ended).
    max_duration : float, s
        The device stops by itself after this much device time (a host that never stops it).

    Attributes
    ----------
    truth : EncoderRecord or None
        After :meth:`close`: the device's own record, with the commands in effect at the end
        of each period and the true speed, position and contact speeds.
    report : dict or None
        After :meth:`close`: the device's tallies (``samples``, ``commands``, ``late``,
        ``missing``, ``corrupted``, ``watchdog``, ``stop``: the sequence numbers of the last
        sample sent and the last command taken when ``STOP`` came (-1: before any), or None).
    """

    def __init__(self, world: DeviceWorld, faults: DeviceFaults | None = None, *, apply: str = "arrival",
                 max_duration: float = 3600.0) -> None:
        if apply not in _APPLY:
            raise ParameterError(parameter_message("apply", "SimulatedDevice", f"be one of {list(_APPLY)}", apply))
        self.world, self.faults, self.apply = world, faults or DeviceFaults(), apply
        self.max_duration = max_duration
        self.truth: EncoderRecord | None = None
        self.report: dict[str, Any] | None = None
        self._process: Any = None
        self._folder: Path | None = None
        self._link: SerialDevice | None = None

    @property
    def counts(self) -> Any:                   # type: ignore[override]
        return self._link.counts if self._link is not None else LinkCounts()

    def open(self, expected: Hello) -> Hello:
        master, slave = os.openpty()
        tty.setraw(slave)                      # no echo, no line editing, before either side talks
        tty.setraw(master)
        self._folder = Path(tempfile.mkdtemp(prefix="active-contacts-device-"))
        context = multiprocessing.get_context("fork")
        self._process = context.Process(target=_serve, args=(master, slave, self.world, self.faults, self.apply,
                                                             self.max_duration, self._folder), daemon=True)
        gc.freeze()                            # the collector of the child writes no inherited page
        try:
            self._process.start()
        finally:
            gc.unfreeze()
        os.close(master)
        try:
            self._link = SerialDevice(f"serial://{os.ttyname(slave)}")
            return self._link.open(expected)
        finally:
            os.close(slave)                    # the host's own port keeps the terminal open

    def read_sample(self, deadline: float) -> Any:
        return self._link.read_sample(deadline)

    def write_command(self, seq: int, speeds: np.ndarray) -> None:
        self._link.write_command(seq, speeds)

    def close(self) -> None:
        if self._link is not None:
            self._link.close()
        process, self._process = self._process, None
        if process is not None:
            process.join(10.0)
            if process.is_alive():
                process.terminate()
                process.join(1.0)
        folder, self._folder = self._folder, None
        if folder is not None:
            if (folder / "truth.csv").is_file():
                self.truth = read_record_csv(folder / "truth.csv")
            if (folder / "device.json").is_file():
                self.report = json.loads((folder / "device.json").read_text())
            shutil.rmtree(folder, ignore_errors=True)


# -- the device process --------------------------------------------------------------------------

class _Port:
    """The device's end of the pseudo-terminal: whole lines in, lines out."""

    def __init__(self, fd: int) -> None:
        self.fd, self.buffer, self.closed = fd, bytearray(), False

    def lines(self, timeout: float) -> list[bytes]:
        if self.closed or not select.select([self.fd], [], [], max(timeout, 0.0))[0]:
            return []
        try:
            chunk = os.read(self.fd, 4096)
        except OSError:                        # the host closed its end
            chunk = b""
        if not chunk:
            self.closed = True
            return []
        self.buffer += chunk
        *lines, rest = self.buffer.split(b"\n")
        self.buffer = bytearray(rest)
        return lines

    def write(self, data: bytes) -> None:
        if not self.closed:
            try:
                os.write(self.fd, data)
            except OSError:
                self.closed = True


def _messages(port: _Port, timeout: float, tally: dict[str, Any]) -> list[Any]:
    out = []
    for line in port.lines(timeout):
        try:
            out.append(protocol.parse(line))
        except ProtocolError:
            tally["bad_lines"] += 1
    return out


def _serve(master: int, slave: int, world: DeviceWorld, faults: DeviceFaults, apply: str,
           max_duration: float, folder: Path) -> None:
    """The device process: handshake, then sample in real time until ``STOP``, the host's
    end closing, or ``max_duration``; then the truth and the tallies written to ``folder``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)      # a terminal's Ctrl-C is the host's to handle
    gc.disable()                                       # no collector pause inside a period
    os.close(slave)
    port = _Port(master)
    sensors = world.sensors
    _rehearse(world)
    tally: dict[str, Any] = {"samples": 0, "commands": 0, "late": 0, "missing": 0, "corrupted": 0,
                             "watchdog": 0, "bad_lines": 0, "stop": None}
    hello = faults.hello or Hello(protocol.VERSION, sensors.n_wheels, sensors.rate,
                                  sensors.central.counts_per_rev, sensors.wheel.counts_per_rev)
    started = stopped = False
    while not started and not stopped and not port.closed:
        for message in _messages(port, 0.5, tally):
            if isinstance(message, Query):
                port.write(protocol.hello_line(hello.wheels, hello.rate, hello.central_cpr, hello.wheel_cpr))
            elif isinstance(message, Start):
                started = True
            elif isinstance(message, Stop) and started:     # stopped before the first sample
                started, stopped = False, True
                tally["stop"] = {"sample": -1, "last_command": -1}
    if started:
        _run(port, world, faults, apply, max_duration, folder, tally)
    (folder / "device.json").write_text(json.dumps(tally))
    os.close(master)


def _rehearse(world: DeviceWorld, periods: int = 25) -> None:
    """Step a copy of the world over a few periods before the handshake: the pages the
    process shares with its parent are copied now, not inside the first periods."""
    from ..loop.closed_loop import PlantSide

    plant, rate = world.plant, world.sensors.rate
    side = PlantSide(plant, world.sensors, world.v0, np.random.default_rng(0), world.wander, world.budget)
    command = plant.initial_speeds()
    for k in range(periods):
        side.read()
        if not side.hold(k, command, 0.0, (k + 1) / rate):
            break


def _run(port: _Port, world: DeviceWorld, faults: DeviceFaults, apply: str, max_duration: float,
         folder: Path, tally: dict[str, Any]) -> None:
    from ..loop.closed_loop import PlantSide

    plant, sensors = world.plant, world.sensors
    rate, n = sensors.rate, plant.n
    period = 1.0 / rate
    side = PlantSide(plant, sensors, world.v0, np.random.default_rng(world.seed), world.wander, world.budget)
    noise = np.random.default_rng([faults.seed, 3])
    limit = int(max_duration * rate) + 1
    rows: list[tuple[Any, ...]] = []
    u, last_command = plant.initial_speeds(), 0
    zeros = np.zeros(n)
    instant = 0.0                                      # the read instant of sample k, s of device time
    origin = time.perf_counter()
    for k in range(limit):
        central, wheel = side.read()
        state = side.state
        truth = (k / rate, central, wheel.copy(), state.V, side.X, state.contact_speeds.copy())
        if faults.silent_after is None or k < faults.silent_after:
            line = protocol.sample_line(k, round(k * 1e6 / rate), central, wheel)
            if faults.corrupt > 0 and noise.random() < faults.corrupt:
                spot = 1 + int(noise.integers(len(line) - 7))          # inside the body
                line = line[:spot] + bytes([line[spot] ^ 0x01]) + line[spot + 1:]
                tally["corrupted"] += 1
            port.write(line)
        tally["samples"] = k + 1
        following = side.next_instant((k + 1) / rate, period)   # the offline grid, k / rate
        answered, stopped = False, False
        while not stopped and (left := origin + following - time.perf_counter()) > 0 and not port.closed:
            for message in _messages(port, left, tally):
                now = min(max(time.perf_counter() - origin, instant), following)
                if isinstance(message, Stop):
                    tally["stop"] = {"sample": k, "last_command": last_command}
                    new, stopped = zeros, True
                elif isinstance(message, Command) and message.seq == k and message.speeds.shape == (n,):
                    tally["commands"] += not answered                  # a repeat replaces it
                    new, answered, last_command = message.speeds, True, k
                else:
                    if isinstance(message, Command):
                        tally["late"] += 1
                    continue
                if apply == "arrival" and now > side.state.t:
                    side.hold(k, u, 0.0, now)                          # the old command until now
                u = new
                if stopped:
                    break
        if not answered and not stopped:
            tally["missing"] += 1
            if k - last_command >= WATCHDOG_PERIODS and np.any(u != 0.0):
                u = zeros                                              # the watchdog
                tally["watchdog"] += 1
        rows.append((*truth, u.copy()))
        if stopped or port.closed:
            if following > side.state.t:
                side.hold(k, u, 0.0, following)
            break
        if following > side.state.t and not side.hold(k, u, 0.0, following):
            break
        instant = following
    _write_truth(rows, sensors, plant, folder)


def _write_truth(rows: list[tuple[Any, ...]], sensors: Sensors, plant: Plant, folder: Path) -> None:
    if not rows:
        return
    times, central, wheel, speed, position, contact, commands = (list(column) for column in zip(*rows))
    record = EncoderRecord(np.array(times), np.array(central, dtype=np.int64), np.array(wheel, dtype=np.int64),
                           np.array(commands), sensors.central.distance_per_count,
                           sensors.wheel.distance_per_count, sensors.backlash, truth_speed=np.array(speed),
                           truth_position=np.array(position), truth_contact_speeds=np.array(contact),
                           initial_commands=plant.initial_speeds())
    write_record_csv(record, folder / "truth.csv")
