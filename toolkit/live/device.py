"""Devices of the live loop: the interface the runner drives, and a real serial port.

:class:`Device` is what :func:`~toolkit.live.run_live` needs of a rig: ``open`` (the handshake,
checked against the scene, then ``START``), ``read_sample``, ``write_command`` and ``close``
(zero commands, ``STOP``). :class:`SerialDevice` speaks the line protocol
(``toolkit.live.protocol``) over a port that pyserial opens (``serial:///dev/ttyACM0?baud=115200``);
it skips and counts corrupt and out-of-order lines and counts the sequence numbers it never
saw. The simulated device (:mod:`toolkit.live.simulated`) is this class on a pseudo-terminal.
"""

from __future__ import annotations

import abc
import math
import os
import select
import time
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qs, urlsplit

import numpy as np

from ..errors import DeviceError, parameter_message
from . import protocol
from .protocol import Hello, ProtocolError, Sample

__all__ = ["Device", "SerialDevice", "LinkCounts", "HANDSHAKE_TIMEOUT", "check_hello", "expected_hello"]

#: How long :meth:`SerialDevice.open` waits for the device's ``HELLO``, s (the query repeated
#: every tenth of it).
HANDSHAKE_TIMEOUT = 3.0


@dataclass
class LinkCounts:
    """What a link skipped so far (a running tally; a result keeps a copy).

    Attributes
    ----------
    corrupt : int
        Lines that broke the grammar or their checksum (skipped).
    out_of_order : int
        Samples whose sequence number was not above the last one taken (skipped).
    lost : int
        Sequence numbers never received between two samples taken (a corrupt sample line
        is one of them too).
    unexpected : int
        Well-formed lines that are no sample (skipped).
    """

    corrupt: int = 0
    out_of_order: int = 0
    lost: int = 0
    unexpected: int = 0


class Device(abc.ABC):
    """A rig that samples its encoders and takes wheel commands, driven by the runner."""

    counts: LinkCounts

    @abc.abstractmethod
    def open(self, expected: Hello) -> Hello:
        """Open the link, ask who the device is, refuse (``DeviceError``,
        naming every field that differs) a device unlike ``expected``, then start it;
        returns its handshake."""

    @abc.abstractmethod
    def read_sample(self, deadline: float) -> Sample | None:
        """The next good sample, or None when none came by ``deadline``
        (``time.perf_counter()`` seconds)."""

    @abc.abstractmethod
    def write_command(self, seq: int, speeds: np.ndarray) -> None:
        """Send the commands (m/s, shape (n,)) answering sample ``seq``."""

    @abc.abstractmethod
    def close(self) -> None:
        """Stop the device (wheels to zero) and release the link; safe to call twice."""


def expected_hello(sensors: Any) -> Hello:
    """The handshake a device must state for ``sensors`` (a scene's
    :class:`~toolkit.model.sensors.Sensors`)."""
    return Hello(protocol.VERSION, sensors.n_wheels, sensors.rate, sensors.central.counts_per_rev,
                 sensors.wheel.counts_per_rev)


def check_hello(hello: Hello, expected: Hello, where: str) -> None:
    """Refuse a handshake that differs from ``expected`` in any field, naming each."""
    differ = []
    for name, unit in (("version", ""), ("wheels", ""), ("rate", " Hz"), ("central_cpr", " counts/rev"),
                       ("wheel_cpr", " counts/rev")):
        got, want = getattr(hello, name), getattr(expected, name)
        if not math.isclose(got, want, rel_tol=1e-9, abs_tol=0.0):
            differ.append(f"{name} {got:g}{unit} (the scene's: {want:g}{unit})")
    if differ:
        raise DeviceError(f"The device on {where} disagrees with the scene: " + ", ".join(differ)
                          + ". Run the scene written for this rig, or fix [sensors] and [contacts].")


def _port_path(url: str) -> tuple[str, int]:
    """``serial://PATH?baud=N`` as (PATH, N); the baud rate defaults to 115200."""
    parts = urlsplit(url)
    query = parse_qs(parts.query, keep_blank_values=True)
    unknown = sorted(set(query) - {"baud"})
    if parts.scheme != "serial" or not parts.path or unknown:
        raise DeviceError(parameter_message("device", "live", "be 'sim' or 'serial://PATH[?baud=N]' "
                                            "(e.g. serial:///dev/ttyACM0?baud=115200)", url))
    baud = query.get("baud", ["115200"])[-1]
    if not baud.isdigit() or int(baud) <= 0:
        raise DeviceError(parameter_message("device", "live", "give baud as a positive integer", url))
    return parts.path, int(baud)


class SerialDevice(Device):
    """A device on a serial port, speaking ``toolkit.live.protocol``.

    Parameters
    ----------
    url : str
        ``serial://PATH[?baud=N]`` (``serial:///dev/ttyACM0?baud=115200``); the port is opened
        here, exclusively (a missing port, or one another program holds, is refused at once),
        and :meth:`open` makes the handshake.
    """

    def __init__(self, url: str) -> None:
        self.url = url
        self.path, self.baud = _port_path(url)
        self.counts = LinkCounts()
        self._port: Any = None
        self._buffer = bytearray()
        self._last_seq = -1
        self._started = False
        self._wheels = 1
        self._connect()

    # -- the link -------------------------------------------------------------------------
    def _connect(self) -> None:
        import serial                 # pyserial: only for a live run

        try:
            self._port = serial.Serial(self.path, self.baud, timeout=0, write_timeout=1.0, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as error:
            text = str(error)
            why = ("it is busy (another program holds it)" if "lock" in text.lower()
                   else f"it cannot be opened ({text})")
            raise DeviceError(parameter_message("device", "live", "name a serial port this process can "
                                                "open", self.url) + f" {self.path!r}: {why}.") from None
        self._fd = self._port.fileno()

    def _line(self, deadline: float) -> bytes | None:
        """The next whole line (without its newline), or None at ``deadline``."""
        buffer = self._buffer
        polled = False
        while True:
            end = buffer.find(b"\n")
            if end >= 0:
                line = bytes(buffer[:end])
                del buffer[:end + 1]
                return line
            if len(buffer) > protocol.MAX_LINE:       # garbage without a newline: drop it
                self.counts.corrupt += 1
                buffer.clear()
            # Past the deadline what has arrived is still read, by one poll: a host that was
            # slow is not a device that fell silent (and a flood cannot hold the verdict off).
            remaining = deadline - time.perf_counter()
            if remaining <= 0.0:
                if polled:
                    return None
                polled = True
            if not select.select([self._fd], [], [], max(remaining, 0.0))[0]:
                return None
            try:
                chunk = os.read(self._fd, 4096)
            except OSError:
                chunk = b""
            if not chunk:                              # the other end closed the port
                raise EOFError(f"the device closed {self.path}")
            buffer += chunk

    def _write(self, data: bytes) -> None:
        """Write all of ``data`` on the (non-blocking) port: one system call unless the output
        buffer is full (pyserial's ``write`` waits on a select after every write)."""
        view = memoryview(data)
        while view:
            try:
                view = view[os.write(self._fd, view):]
            except BlockingIOError:
                if not select.select([], [self._fd], [], 1.0)[1]:
                    raise DeviceError(f"The device on {self.url} took no output for 1 s.") from None

    # -- Device ---------------------------------------------------------------------------
    def open(self, expected: Hello) -> Hello:
        self._wheels = expected.wheels
        if self._port is None:            # closed: open again
            self._connect()
        self._write(protocol.STOP_LINE)               # a device left streaming by an earlier host
        self._port.reset_input_buffer()
        hello = None
        give_up = time.perf_counter() + HANDSHAKE_TIMEOUT
        while hello is None and time.perf_counter() < give_up:
            self._write(protocol.QUERY_LINE)
            ask_again = min(give_up, time.perf_counter() + HANDSHAKE_TIMEOUT / 10)
            try:
                while (line := self._line(ask_again)) is not None:
                    try:
                        message = protocol.parse(line)
                    except ProtocolError:
                        continue
                    if isinstance(message, Hello):
                        hello = message
                        break
            except EOFError:
                break
        if hello is None:
            self.close()
            raise DeviceError(parameter_message("device", "live", "answer HELLO? with HELLO within "
                                                f"{HANDSHAKE_TIMEOUT:g} s (docs/live.md)", self.url))
        try:
            check_hello(hello, expected, self.url)
        except DeviceError:
            self.close()
            raise
        self._buffer.clear()
        self._write(protocol.START_LINE)
        self._started = True
        return hello

    def read_sample(self, deadline: float) -> Sample | None:
        counts = self.counts
        while True:
            line = self._line(deadline)
            if line is None:
                return None
            try:
                message = protocol.parse(line)
            except ProtocolError:
                counts.corrupt += 1
                continue
            if not isinstance(message, Sample):
                counts.unexpected += 1
                continue
            if message.seq <= self._last_seq:
                counts.out_of_order += 1
                continue
            counts.lost += message.seq - self._last_seq - 1
            self._last_seq = message.seq
            return message

    def write_command(self, seq: int, speeds: np.ndarray) -> None:
        self._write(protocol.command_line(seq, speeds))

    def close(self) -> None:
        port, self._port = self._port, None
        if port is None:
            return
        try:
            if self._started:
                port.write(protocol.command_line(max(self._last_seq, 0), np.zeros(self._wheels)))
            port.write(protocol.STOP_LINE)
            port.flush()
        except Exception:                              # the device is gone: nothing to stop
            pass
        finally:
            port.close()

