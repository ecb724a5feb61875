"""The live loop's line protocol: the messages a device and the host exchange over serial.

Every line is ``$BODY*CCCC\\n``: ASCII fields separated by commas, then the CRC-16/CCITT-FALSE
of ``BODY`` (polynomial 0x1021, initial value 0xFFFF; Python's ``binascii.crc_hqx(body,
0xFFFF)``) in four upper-case hex digits. Host to device: ``HELLO?,1`` (who are you),
``START``, ``C,seq,u_1,...,u_n`` (the commands answering sample ``seq``, m/s), ``STOP``
(wheels to zero, stop sampling). Device to host: ``HELLO,1,n,rate_hz,central_cpr,wheel_cpr``
and ``S,seq,device_us,central,w_1,...,w_n``. The grammar, the timing contract and the
watchdog are in docs/live.md.
"""

from __future__ import annotations

import binascii
from dataclasses import dataclass

import numpy as np

__all__ = ["VERSION", "ProtocolError", "Hello", "Sample", "Command", "Query", "Start", "Stop", "encode",
           "parse", "crc", "hello_line", "sample_line", "command_line", "QUERY_LINE", "START_LINE",
           "STOP_LINE", "MAX_LINE", "DEVICE_CLOCK_WRAP"]

#: The protocol's version, stated in ``HELLO?`` and ``HELLO``.
VERSION = 1
#: Longest line either side accepts, bytes (a longer one is corrupt).
MAX_LINE = 1024
#: The device clock counts microseconds in 32 bits: it wraps after 2^32 us (71.6 min).
DEVICE_CLOCK_WRAP = 1 << 32


class ProtocolError(ValueError):
    """A line that breaks the grammar (its reason in words); the receiver skips it."""


@dataclass(frozen=True)
class Hello:
    """The device's handshake: protocol version, wheel channels, sample rate (Hz) and the
    encoders' counts per revolution (central, wheel)."""

    version: int
    wheels: int
    rate: float
    central_cpr: float
    wheel_cpr: float


@dataclass(frozen=True)
class Sample:
    """One sample: sequence number, device time (us, 32-bit, wrapping), counts."""

    seq: int
    device_us: int
    central: int
    wheels: np.ndarray


@dataclass(frozen=True)
class Command:
    """The commands (m/s, one per wheel) answering sample ``seq``."""

    seq: int
    speeds: np.ndarray


@dataclass(frozen=True)
class Query:
    """The host's ``HELLO?`` with its protocol version."""

    version: int


@dataclass(frozen=True)
class Start:
    """The host's ``START``: sample from now on, sequence 0 at device time 0."""


@dataclass(frozen=True)
class Stop:
    """The host's ``STOP``: wheels to zero at once, stop sampling."""


def crc(body: bytes) -> int:
    """CRC-16/CCITT-FALSE of ``body`` (the line's checksum)."""
    return binascii.crc_hqx(body, 0xFFFF)


def encode(body: str) -> bytes:
    """The line ``$body*CCCC\\n`` (ASCII)."""
    data = body.encode("ascii")
    return b"$" + data + b"*%04X\n" % crc(data)


QUERY_LINE = encode(f"HELLO?,{VERSION}")
START_LINE = encode("START")
STOP_LINE = encode("STOP")


def hello_line(wheels: int, rate: float, central_cpr: float, wheel_cpr: float) -> bytes:
    """The device's ``HELLO`` line."""
    return encode(f"HELLO,{VERSION},{wheels},{rate!r},{central_cpr!r},{wheel_cpr!r}")


def sample_line(seq: int, device_us: int, central: int, wheels: np.ndarray) -> bytes:
    """The device's ``S`` line (``device_us`` taken modulo 2^32)."""
    counts = ",".join(map(str, wheels.tolist()))
    return encode(f"S,{seq},{device_us % DEVICE_CLOCK_WRAP},{central},{counts}")


def command_line(seq: int, speeds: np.ndarray) -> bytes:
    """The host's ``C`` line: every speed with 17 significant digits, so the device reads
    back exactly what the host computed and logged."""
    return encode(f"C,{seq}," + ",".join(map(repr, speeds.tolist())))


def _integers(fields: list[str], what: str) -> list[int]:
    try:
        return [int(field) for field in fields]
    except ValueError:
        raise ProtocolError(f"{what} must be integers: {fields!r}") from None


def parse(line: bytes) -> Hello | Sample | Command | Query | Start | Stop:
    """Check a line's frame and checksum and read its message.

    Raises
    ------
    ProtocolError
        A line without its ``$``/``*`` frame, a checksum that does not match, an unknown
        tag or fields of the wrong number or kind.
    """
    line = line.rstrip(b"\r\n")
    if len(line) > MAX_LINE:
        raise ProtocolError(f"a line of {len(line)} bytes (at most {MAX_LINE})")
    star = line.rfind(b"*")
    if not line.startswith(b"$") or star < 0 or len(line) - star != 5:
        raise ProtocolError(f"no $...*CCCC frame: {line[:40]!r}")
    body = line[1:star]
    try:
        stated = int(line[star + 1:], 16)
    except ValueError:
        raise ProtocolError(f"a checksum that is not 4 hex digits: {line[star + 1:]!r}") from None
    if crc(body) != stated:
        raise ProtocolError(f"checksum {stated:04X} where the line's is {crc(body):04X}")
    try:
        fields = body.decode("ascii").split(",")
    except UnicodeDecodeError:
        raise ProtocolError(f"bytes that are not ASCII: {body[:40]!r}") from None
    tag, rest = fields[0], fields[1:]
    if tag == "S":
        if len(rest) < 4:
            raise ProtocolError(f"a sample needs seq, time, central and >= 1 wheel count: {len(rest)} fields")
        numbers = _integers(rest, "a sample's fields")
        return Sample(numbers[0], numbers[1], numbers[2], np.array(numbers[3:], dtype=np.int64))
    if tag == "C":
        if len(rest) < 2:
            raise ProtocolError(f"a command needs seq and >= 1 speed: {len(rest)} fields")
        seq = _integers(rest[:1], "a command's sequence number")[0]
        try:
            speeds = np.array([float(field) for field in rest[1:]])
        except ValueError:
            raise ProtocolError(f"a command's speeds must be numbers: {rest[1:]!r}") from None
        if not np.isfinite(speeds).all():
            raise ProtocolError(f"a command's speeds must be finite: {rest[1:]!r}")
        return Command(seq, speeds)
    if tag == "HELLO":
        if len(rest) != 5:
            raise ProtocolError(f"HELLO needs version, wheels, rate, central_cpr, wheel_cpr: {len(rest)} fields")
        version, wheels = _integers(rest[:2], "HELLO's version and wheels")
        try:
            rate, central_cpr, wheel_cpr = (float(field) for field in rest[2:])
        except ValueError:
            raise ProtocolError(f"HELLO's rate and counts per revolution must be numbers: {rest[2:]!r}") from None
        return Hello(version, wheels, rate, central_cpr, wheel_cpr)
    if tag == "HELLO?" and len(rest) == 1:
        return Query(_integers(rest, "HELLO?'s version")[0])
    if tag == "START" and not rest:
        return Start()
    if tag == "STOP" and not rest:
        return Stop()
    raise ProtocolError(f"an unknown message {tag!r} with {len(rest)} fields")
