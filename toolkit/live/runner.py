"""The live loop's runner: the scene's estimator and controller stepped per sample on a device,
with the deadlines kept and the safety rules applied.

Per sample, in order: read the sample line, estimate and act (:class:`~toolkit.loop.closed_loop.HostStep`,
the offline loop's own per-sample code), write the command, then tell the estimator the command
and move the law's state on (the same step's second half, outside the latency).
The latency is the host's time from the sample's line received to its command written; the
deadline is one period (the command for sample ``k`` must reach the device before sample
``k + 1``). The run stops, with zero commands sent and the device stopped, at its duration, on
Ctrl-C, on device silence for :data:`SILENCE_PERIODS` periods, or after :data:`MISSED_RUN`
missed deadlines in a row.
"""

from __future__ import annotations

import enum
import gc
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ParameterError, ParameterTypeError, as_float, parameter_message
from ..model import Plant, sample_count
from ..model.sensors import EncoderRecord, Sensors
from .device import Device, LinkCounts, expected_hello
from .protocol import DEVICE_CLOCK_WRAP

__all__ = ["LiveLoop", "LiveResult", "LiveStatus", "run_live", "SILENCE_PERIODS", "MISSED_RUN",
           "FIRST_SAMPLE_TIMEOUT", "STATUS_INTERVAL"]

#: Device silence (no good sample) for this many periods stops the run.
SILENCE_PERIODS = 3
#: This many missed deadlines in a row stop the run.
MISSED_RUN = 3
#: How long the host waits for the first sample after ``START``, s.
FIRST_SAMPLE_TIMEOUT = 2.0
#: Seconds between two status reports (the ``status`` callback).
STATUS_INTERVAL = 0.25


class LiveStatus(enum.Enum):
    """How a live run ended; the value is its message."""

    COMPLETED = "ran its duration"
    INTERRUPTED = "interrupted (Ctrl-C)"
    SILENCE = f"the device fell silent for {SILENCE_PERIODS} periods"
    MISSED = f"{MISSED_RUN} deadlines missed in a row"


@dataclass(frozen=True, eq=False)
class LiveLoop:
    """What a live run steps: the scene's plant (the model the controller is bound to), its
    controller, its estimator and encoders.

    Parameters
    ----------
    plant : Plant
        The nominal plant: its contact speeds at ``t = 0`` are the motors' settled speeds.
    controller : Controller
    estimator : Estimator
        Reset at the start exactly as the offline loop resets it.
    sensors : Sensors
        The scene's encoders: the handshake must state their wheels, rate and counts per rev.
    duration : float, s
    v0 : float, m/s
        The speed the estimator starts from.
    """

    plant: Plant
    controller: Any
    estimator: Any
    sensors: Sensors
    duration: float
    v0: float = 0.0

    def __post_init__(self) -> None:
        owner = "LiveLoop"
        if not isinstance(self.plant, Plant):
            raise ParameterTypeError(parameter_message("plant", owner, "be a Plant", self.plant))
        if not isinstance(self.sensors, Sensors):
            raise ParameterTypeError(parameter_message("sensors", owner, "be a Sensors", self.sensors))
        object.__setattr__(self, "duration", as_float(self.duration, "duration", owner, low=0.0, low_open=True))
        object.__setattr__(self, "v0", as_float(self.v0, "v0", owner))


@dataclass(frozen=True, eq=False)
class LiveResult:
    """One live run, per sample taken.

    Attributes
    ----------
    record : EncoderRecord or None
        The counts at the device's sample times and the commands sent (no truth); None when
        no sample came.
    sequence : ndarray of shape (k,), int
        The device's sequence number of each sample.
    received, answered : ndarray of shape (k,), s
        Host time (from ``START``) each sample's line was received and its command written.
    estimate, variance : ndarray of shape (k,), m/s and (m/s)^2
    status : LiveStatus
    message : str
        One line: how the run ended.
    counts : LinkCounts
        Lines skipped and sequence numbers lost.
    late : int
        Samples received more than 1.5 periods after the previous one.
    hello : Hello
        The device's handshake.
    """

    record: EncoderRecord | None
    sequence: np.ndarray
    received: np.ndarray
    answered: np.ndarray
    estimate: np.ndarray
    variance: np.ndarray
    status: LiveStatus
    message: str
    counts: LinkCounts
    late: int
    hello: Any
    period: float = field(default=math.nan)

    @property
    def latency(self) -> np.ndarray:
        """Host latency of each sample (received to answered), s."""
        return self.answered - self.received

    @property
    def missed(self) -> int:
        """Deadlines missed: commands written more than one period after their sample came."""
        return int(np.count_nonzero(self.latency > self.period))

    def timing(self) -> dict[str, Any]:
        """Latency p50, p99 and max (ms), missed deadlines, late, lost, corrupt, out-of-order
        and unexpected lines."""
        latency = self.latency * 1e3
        quantiles = (np.percentile(latency, [50, 99]).tolist() if latency.size else [math.nan, math.nan])
        return {"samples": int(self.sequence.size), "latency_p50_ms": quantiles[0],
                "latency_p99_ms": quantiles[1], "latency_max_ms": float(latency.max()) if latency.size else math.nan,
                "missed_deadlines": self.missed, "late": self.late, "lost": self.counts.lost,
                "corrupt": self.counts.corrupt, "out_of_order": self.counts.out_of_order,
                "unexpected": self.counts.unexpected}

    def summary(self) -> str:
        """One line: samples, latency quantiles, missed deadlines and skipped lines."""
        t = self.timing()
        return (f"{t['samples']} samples; latency p50 {t['latency_p50_ms']:.3f} ms, p99 "
                f"{t['latency_p99_ms']:.3f} ms, max {t['latency_max_ms']:.3f} ms; {t['missed_deadlines']} "
                f"missed deadlines; {t['late']} late, {t['lost']} lost, {t['corrupt']} corrupt, "
                f"{t['out_of_order']} out-of-order lines")


def run_live(loop: LiveLoop, device: Device, *, status: Callable[[dict[str, float]], None] | None = None,
             started: Callable[[Any], None] | None = None) -> LiveResult:
    """Run ``loop`` on ``device`` in real time for ``loop.duration`` seconds of device time.

    Parameters
    ----------
    loop : LiveLoop
    device : Device
        Opened here (the handshake checked against ``loop.sensors``) and closed at the end,
        whatever ends the run (zero commands and ``STOP`` sent).
    status : callable, optional
        Called about every ``STATUS_INTERVAL`` seconds with ``t`` (s), ``estimate``,
        ``sigma`` and ``command`` (m/s, the commands' mean), ``p99_ms`` and ``missed``.
    started : callable, optional
        Called with the device's handshake once it is accepted, before the first sample.

    Returns
    -------
    LiveResult

    Raises
    ------
    DeviceError
        The device could not be opened, or its handshake disagrees with the scene.
    """
    from ..loop.closed_loop import HostStep

    if not isinstance(loop, LiveLoop):
        raise ParameterTypeError(parameter_message("loop", "run_live", "be a LiveLoop", loop))
    sensors, plant = loop.sensors, loop.plant
    rate = sensors.rate
    period = 1.0 / rate
    samples = sample_count(loop.duration, rate)
    n = plant.n
    if sensors.n_wheels != n:
        raise ParameterError(parameter_message("sensors", "run_live", f"read the plant's {n} wheels",
                                               sensors.n_wheels))
    law = loop.controller.bind(plant, period)
    estimator = loop.estimator
    initial = plant.initial_speeds()
    estimator.reset(speed=loop.v0, contact_speeds=initial)
    host = HostStep(law, estimator, initial)
    sequence = np.zeros(samples, dtype=np.int64)
    times, received, answered = np.zeros(samples), np.zeros(samples), np.zeros(samples)
    central, wheel = np.zeros(samples, dtype=np.int64), np.zeros((samples, n), dtype=np.int64)
    commands, estimate, variance = np.zeros((samples, n)), np.zeros(samples), np.zeros(samples)
    end, late, run = LiveStatus.COMPLETED, 0, 0
    k, wraps, last_us, hello = 0, 0, -1, None
    collecting = gc.isenabled()
    try:
        hello = device.open(expected_hello(sensors))
        if started is not None:
            started(hello)
        origin = time.perf_counter()
        next_status = origin + STATUS_INTERVAL
        gc.disable()                 # no collector pause inside a period
        deadline = origin + FIRST_SAMPLE_TIMEOUT
        while k < samples:
            sample = device.read_sample(deadline)
            got = time.perf_counter()
            if sample is None:
                end = LiveStatus.SILENCE
                break
            if sample.seq >= samples:                # the duration's last sample was lost
                break
            if sample.wheels.shape != (n,):
                device.counts.unexpected += 1
                continue
            if sample.device_us < last_us:           # the device's 32-bit microsecond clock wrapped
                wraps += 1
            last_us = sample.device_us
            t = (sample.device_us + wraps * DEVICE_CLOCK_WRAP) / 1e6
            if k and not t > times[k - 1]:
                device.counts.out_of_order += 1
                continue
            est, var, u, f = host.act(t, sample.central, sample.wheels)
            if f != 0.0:
                raise ParameterError(parameter_message(
                    "controller", "run_live", "send wheel speeds only (the protocol carries no outside "
                    "force: a rig's force cannot be applied live)", f"a force of {f:g} N"))
            device.write_command(sample.seq, u)
            done = time.perf_counter()
            host.settle()                            # after the command: not in the latency
            if k and got - origin - received[k - 1] > 1.5 * period:
                late += 1
            sequence[k], times[k], received[k], answered[k] = sample.seq, t, got - origin, done - origin
            central[k], wheel[k], commands[k], estimate[k], variance[k] = sample.central, sample.wheels, u, est, var
            k += 1
            if sample.seq == samples - 1:            # the duration's last sample (device time)
                break
            # A step of m periods misses m deadlines in a row (the samples that came meanwhile
            # are answered after their successors): a host stalled 3 periods stops the run.
            run = run + max(int((done - got) / period), 1) if done - got > period else 0
            if run >= MISSED_RUN:
                end = LiveStatus.MISSED
                break
            deadline = got + SILENCE_PERIODS * period
            if status is not None and done >= next_status:
                next_status = done + STATUS_INTERVAL
                status({"t": t, "estimate": est, "sigma": math.sqrt(max(var, 0.0)), "command": float(np.mean(u)),
                        "p99_ms": float(np.percentile(answered[:k] - received[:k], 99)) * 1e3,
                        "missed": int(np.count_nonzero(answered[:k] - received[:k] > period))})
    except KeyboardInterrupt:
        end = LiveStatus.INTERRUPTED
    finally:
        device.close()               # zero commands and STOP, whatever ended the run
        if collecting:
            gc.enable()
    keep = slice(0, k)
    record = None
    if k:
        record = EncoderRecord(times[keep], central[keep], wheel[keep], commands[keep],
                               sensors.central.distance_per_count, sensors.wheel.distance_per_count,
                               sensors.backlash, initial_commands=initial)
    at = f" at t = {times[k - 1]:.3f} s" if k else " before the first sample"
    message = (end.value if end is LiveStatus.COMPLETED else f"{end.value}{at}; zero commands sent")
    return LiveResult(record, sequence[keep], received[keep], answered[keep], estimate[keep], variance[keep],
                      end, message, LinkCounts(**vars(device.counts)), late, hello, period)
