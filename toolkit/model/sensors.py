"""Encoders as the hardware has them: integer counts of position sampled at a fixed rate.

The sensor law is written once, in :func:`measure`: positions in, integer counts out
(``floor(x / q)``), with gearbox backlash as the play operator :func:`play`, missed counts,
read noise and sample-time jitter drawn from a generator passed in. :class:`Sensors`
describes a suite, :class:`EncoderRecord` holds what it reports, and
:func:`record_simulation` turns an exact simulation into a record. At constant speed the
quantization error is a deterministic sawtooth (docs/physics.md section 5; docs/methods.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import as_float, as_float_array, as_int
from ..errors import ParameterError, ParameterTypeError, parameter_message
from .signals import sample_times

#: Largest jitter standard deviation, in periods: a quarter period (where the read offsets
#: are truncated) is then at least 4 standard deviations out.
MAX_JITTER_PERIODS = 1.0 / 16.0

__all__ = ["Encoder", "Sensors", "SensorState", "SensorReader", "play", "measure", "EncoderRecord", "EncoderSample",
           "record_simulation", "contact_speeds_at", "GAUSS_NODES"]


@dataclass(frozen=True)
class Encoder:
    """A position encoder read at a fixed rate.

    Parameters
    ----------
    counts_per_rev : float
        Counts per revolution of the measured shaft (gear ratio included), > 0.
    radius : float, m
        Radius at which the measured motion happens (wheel radius, or contact radius L
        for the central encoder), > 0.
    rate : float, Hz
        Sampling rate, > 0.
    backlash : float, m
        Dead band of the gearbox at the contact, >= 0 (0: none).
    """

    counts_per_rev: float
    radius: float
    rate: float = 50.0
    backlash: float = 0.0

    def __post_init__(self) -> None:
        for name in ("counts_per_rev", "radius", "rate"):
            object.__setattr__(self, name, as_float(getattr(self, name), name, "Encoder", low=0.0, low_open=True))
        object.__setattr__(self, "backlash", as_float(self.backlash, "backlash", "Encoder", low=0.0))

    @property
    def distance_per_count(self) -> float:
        """Linear distance of one count at ``radius``, m."""
        return 2.0 * math.pi * self.radius / self.counts_per_rev

    @property
    def speed_step(self) -> float:
        """Speed resolution of differencing consecutive samples, m/s."""
        return self.distance_per_count * self.rate

    @property
    def backlash_speed_step(self) -> float:
        """Speed error one backlash width causes over one sample period, m/s."""
        return self.backlash * self.rate

    def counts(self, position: Any) -> np.ndarray:
        """Integer counts for positions (m at ``radius``): ``floor(position / distance_per_count)``."""
        return np.floor(np.asarray(position, dtype=float) / self.distance_per_count).astype(np.int64)

    def summary(self) -> dict[str, float]:
        """The resolutions as a JSON-able dict (SI units)."""
        return {"distance_per_count": self.distance_per_count, "speed_step": self.speed_step,
                "backlash_speed_step": self.backlash_speed_step, "rate": self.rate}


# -- the carousel's sensor suite -------------------------------------------------------------
@dataclass(frozen=True)
class Sensors:
    """The sensor suite of a body on ``n_wheels`` motor-driven contacts, all read at one rate.

    Parameters
    ----------
    central : Encoder
        The body's encoder (for the carousel the central AMT103-V, 8192 counts/rev at the
        contact radius ``L``).
    wheel : Encoder
        The encoder of each contact's motor (identical for every wheel); ``wheel.backlash``
        is the gearbox play between motor and contact (m at the contact).
    n_wheels : int
        Number of wheel encoders (= contacts), ``>= 1``.
    missed_count_prob : float
        Probability, in ``[0, 1]``, that the counter misses one count transition; a missed
        transition shifts that channel's count for good (the counter never sees it again).
    count_noise : float, counts
        Standard deviation (``>= 0``) of an additive read noise, rounded to whole counts and
        not accumulated (e.g. a glitching line read once).
    jitter : float, s
        Standard deviation (``>= 0``, at most ``MAX_JITTER_PERIODS`` of a period) of the
        sample-time jitter: the positions are read at ``t_k + d_k`` while the record stamps
        ``t_k``; ``d_k`` is a normal law truncated at a quarter period (so that samples keep
        their order), at least 4 standard deviations out: the truncation changes fewer than
        1e-4 of the draws.

    Notes
    -----
    The rates of the two encoders must agree: one rate for all encoders and the motor
    commands (docs/physics.md section 5: 50 Hz).
    """

    central: Encoder
    wheel: Encoder
    n_wheels: int
    missed_count_prob: float = 0.0
    count_noise: float = 0.0
    jitter: float = 0.0

    def __post_init__(self) -> None:
        owner = "Sensors"
        for name in ("central", "wheel"):
            if not isinstance(getattr(self, name), Encoder):
                raise ParameterTypeError(parameter_message(name, owner, "be an Encoder", getattr(self, name)))
        if self.central.rate != self.wheel.rate:
            raise ParameterError(parameter_message(
                "wheel", owner, f"have the central encoder's rate ({self.central.rate:g} Hz)",
                f"rate {self.wheel.rate:g} Hz"))
        object.__setattr__(self, "n_wheels", as_int(self.n_wheels, "n_wheels", owner, low=1))
        object.__setattr__(self, "missed_count_prob", as_float(
            self.missed_count_prob, "missed_count_prob", owner, low=0.0, high=1.0))
        object.__setattr__(self, "count_noise", as_float(self.count_noise, "count_noise", owner, low=0.0))
        object.__setattr__(self, "jitter", as_float(self.jitter, "jitter", owner, low=0.0))
        if self.jitter > MAX_JITTER_PERIODS / self.rate:
            raise ParameterError(parameter_message(
                "jitter", owner, f"be <= {MAX_JITTER_PERIODS:g} period ({MAX_JITTER_PERIODS / self.rate:.4g} s at "
                f"{self.rate:g} Hz: the read offsets are a normal law truncated at a quarter period, which "
                "must lie at least 4 standard deviations out)", self.jitter))

    # -- constructors ---------------------------------------------------------------------
    @staticmethod
    def checked(sensors: Any, n_contacts: int, owner: str) -> Sensors:
        """``sensors`` checked for a plant of ``n_contacts`` contacts: a :class:`Sensors`
        with one wheel encoder per contact (the check every closed-loop entry point makes).

        Raises
        ------
        ParameterTypeError, ParameterError
            Naming ``owner``'s ``sensors`` parameter, the rule and the value.
        """
        if not isinstance(sensors, Sensors):
            raise ParameterTypeError(parameter_message("sensors", owner, "be a Sensors or None", sensors))
        if sensors.n_wheels != n_contacts:
            raise ParameterError(parameter_message(
                "sensors", owner, f"have one wheel encoder per contact ({n_contacts})", sensors.n_wheels))
        return sensors

    # -- properties -----------------------------------------------------------------------
    @property
    def rate(self) -> float:
        """Sampling rate of every encoder, Hz."""
        return self.central.rate

    @property
    def period(self) -> float:
        """Sampling period ``1 / rate``, s."""
        return 1.0 / self.central.rate

    @property
    def backlash(self) -> float:
        """Gearbox play of each wheel at the contact, m."""
        return self.wheel.backlash

    @property
    def read_noise_variance(self) -> float:
        """Variance of the read noise the sensor law adds, counts^2: a normal draw of std
        ``count_noise`` rounded to whole counts (``SensorReader.read``), so ``sum_k k^2
        P(k)`` with ``P(k)`` the normal's mass on ``[k - 1/2, k + 1/2)``: not ``count_noise^2``
        (0.325 against 0.25 at half a count)."""
        sigma = self.count_noise
        if sigma == 0.0:
            return 0.0
        from scipy.special import ndtr

        k = np.arange(1, int(math.ceil(12.0 * sigma)) + 2)
        # The upper tails' difference: no cancellation where the mass is far below 1.
        mass = ndtr((0.5 - k) / sigma) - ndtr((-0.5 - k) / sigma)
        return float(2.0 * np.sum(k * k * mass))

    def initial_state(self, contact_speeds: Any = None, *, central_position: float = 0.0,
                      contact_positions: Any = None) -> SensorState:
        """The sensors' state before the first sample.

        Parameters
        ----------
        contact_speeds : array_like of shape (n,), m/s, optional
            Contact speeds at the start. A contact already moving has its gearbox loaded:
            the motor side trails the contact by half the play, ``-sign(v_i) b / 2``
            (the play operator's steady state); at rest (or ``None``) the play is centred.
        central_position, contact_positions : float and array_like of shape (n,), m
            Positions at the start (default 0): they set the reference of the missed-count
            bookkeeping.
        """
        n = self.n_wheels
        x0 = np.zeros(n) if contact_positions is None else np.asarray(contact_positions, dtype=float).reshape(n)
        v0 = np.zeros(n) if contact_speeds is None else np.asarray(contact_speeds, dtype=float).reshape(n)
        motor = x0 - np.sign(v0) * 0.5 * self.backlash
        return SensorState(motor=motor,
                           central_count=int(self.central.counts(central_position)),
                           wheel_count=self.wheel.counts(motor),
                           central_offset=0, wheel_offset=np.zeros(n, dtype=np.int64))


@dataclass(frozen=True, eq=False)
class SensorState:
    """What the sensors remember between samples (a value: :func:`measure` returns a new one).

    Attributes
    ----------
    motor : ndarray of shape (n,), m
        Motor-side position of each wheel's gearbox (the play operator's output).
    central_count, wheel_count : int and ndarray of shape (n,)
        The true (un-missed) counts at the previous sample.
    central_offset, wheel_offset : int and ndarray of shape (n,)
        Counts lost so far to missed transitions (added to the true counts).
    """

    motor: np.ndarray
    central_count: int
    wheel_count: np.ndarray
    central_offset: int
    wheel_offset: np.ndarray


def play(positions: Any, width: float, start: Any) -> np.ndarray:
    """The play (backlash) operator: the motor-side position seen through a dead band.

    ``y_k = clip(y_{k-1}, x_k - width / 2, x_k + width / 2)``: the motor side stays put while
    the contact moves inside the gearbox play and is dragged along at its edge. After a
    reversal the output stands still until the input has travelled ``width``.

    Parameters
    ----------
    positions : array_like of shape (k, n), m
        Contact positions ``x`` at successive samples.
    width : float, m
        Play ``b >= 0``.
    start : array_like of shape (n,), m
        Output ``y`` before the first sample.

    Returns
    -------
    ndarray of shape (k, n), m
        ``y`` at each sample (row by row: the same code serves one sample or a whole record).
    """
    x = np.asarray(positions, dtype=float)
    out = np.empty_like(x)
    y = np.asarray(start, dtype=float)
    half = 0.5 * width
    for j in range(x.shape[0]):
        y = out[j] = _play_step(y, x[j], half)
    return out


def _play_step(y: np.ndarray, x: np.ndarray, half: float) -> np.ndarray:
    """One sample of the play operator: ``clip(y, x - half, x + half)``."""
    return np.minimum(np.maximum(y, x - half), x + half)


def measure(sensors: Sensors, central_positions: Any, contact_positions: Any, state: SensorState,
            rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray, SensorState]:
    """The sensor law: body and contact positions to the integer counts the encoders report.

    One sample (``k = 1``) in a closed loop or a whole record: the same code, row by row.

    Parameters
    ----------
    sensors : Sensors
    central_positions : array_like of shape (k,), m
        Body position (at the central encoder's radius) at each read instant.
    contact_positions : array_like of shape (k, n), m
        Contact positions (at the wheels' contact point) at each read instant.
    state : SensorState
        From :meth:`Sensors.initial_state` or a previous call.
    rng : numpy.random.Generator, optional
        Draws the missed counts and the read noise; needed when either is non-zero.

    Returns
    -------
    central_counts : ndarray of shape (k,), int64
        ``floor(X / q_c)`` plus missed-count offsets and read noise.
    wheel_counts : ndarray of shape (k, n), int64
        ``floor(play(x) / q_w)`` (the motor-side encoder sees the contact through the
        gearbox play), plus offsets and noise.
    state : SensorState
        The state after the last sample.

    Notes
    -----
    Per sample and in this order: the play operator; the true counts (position quantized by
    ``floor``, never speed); for each channel the transitions since the last sample,
    ``|c_k - c_{k-1}|``, each missed with probability ``p`` (one binomial draw per channel,
    central first), the missed ones shifting the count against the motion for good; then
    the read noise (one normal draw per channel, rounded). Draws happen only for non-zero
    ``p`` or noise, so a noiseless suite consumes no random numbers.
    """
    owner = "measure"
    X = as_float_array(central_positions, "central_positions", owner)
    x = as_float_array(contact_positions, "contact_positions", owner, ndim=2)
    if x.shape != (X.size, sensors.n_wheels):
        raise ParameterError(parameter_message(
            "contact_positions", owner, f"have shape ({X.size}, {sensors.n_wheels})",
            f"an array of shape {x.shape}"))
    reader = SensorReader(sensors, state, rng)
    read = reader.read
    central = np.empty(X.size, dtype=np.int64)
    wheel = np.empty((X.size, sensors.n_wheels), dtype=np.int64)
    for j in range(X.size):
        central[j], wheel[j] = read(float(X[j]), x[j])
    return central, wheel, reader.state


class SensorReader:
    """The sensor law one sample at a time (what :func:`measure` runs on each row).

    A closed loop keeps one reader and calls :meth:`read` at each sample: no validation or
    state object per sample. :func:`measure` builds one from its ``state`` and reads its
    rows through the same :meth:`read`, so the two agree sample for sample (the same
    random draws in the same order).

    Parameters
    ----------
    sensors : Sensors
    state : SensorState
        From :meth:`Sensors.initial_state` or :attr:`state`.
    rng : numpy.random.Generator, optional
        Needed when counts can be missed or noisy.
    """

    def __init__(self, sensors: Sensors, state: SensorState, rng: np.random.Generator | None = None) -> None:
        p, noise = sensors.missed_count_prob, sensors.count_noise
        if (p > 0 or noise > 0) and not isinstance(rng, np.random.Generator):
            raise ParameterTypeError(parameter_message(
                "rng", "measure", "be a numpy.random.Generator when counts can be missed or noisy", rng))
        self.sensors, self.rng = sensors, rng
        self._p, self._noise, self._n = p, noise, sensors.n_wheels
        self._qc = sensors.central.distance_per_count
        self._qw = sensors.wheel.distance_per_count
        self._half = 0.5 * sensors.backlash
        self._motor = np.array(state.motor, dtype=float)
        self._last_c, self._last_w = int(state.central_count), np.array(state.wheel_count, dtype=np.int64)
        self._off_c, self._off_w = int(state.central_offset), np.array(state.wheel_offset, dtype=np.int64)

    def read(self, central_position: float, contact_positions: np.ndarray) -> tuple[int, np.ndarray]:
        """Counts at one read instant.

        Parameters
        ----------
        central_position : float, m
        contact_positions : ndarray of shape (n,), m

        Returns
        -------
        central : int
        wheels : ndarray of shape (n,), int64
        """
        # Play operator, then position quantized by floor (never speed).
        motor = self._motor = _play_step(self._motor, contact_positions, self._half)
        c = math.floor(central_position / self._qc)
        w = np.floor(motor / self._qw).astype(np.int64)
        rng = self.rng
        if self._p > 0:
            p = self._p
            dc, dw = c - self._last_c, w - self._last_w
            self._off_c -= int(np.sign(dc)) * int(rng.binomial(abs(dc), p))
            self._off_w = self._off_w - np.sign(dw) * rng.binomial(np.abs(dw), p)
        central, wheels = c + self._off_c, w + self._off_w
        if self._noise > 0:
            central += int(np.rint(rng.normal(0.0, self._noise)))
            wheels = wheels + np.rint(rng.normal(0.0, self._noise, self._n)).astype(np.int64)
        self._last_c, self._last_w = c, w
        return central, wheels

    @property
    def state(self) -> SensorState:
        """The state after the last read (a new value)."""
        return SensorState(motor=self._motor.copy(), central_count=self._last_c,
                           wheel_count=np.array(self._last_w, dtype=np.int64),
                           central_offset=self._off_c, wheel_offset=self._off_w.copy())


# -- records ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class EncoderSample:
    """One sample of an :class:`EncoderRecord`: what a controller receives at ``time``.

    Attributes
    ----------
    time : float, s
    central_count : int
    wheel_counts : ndarray of shape (n,), int64
    command : ndarray of shape (n,), m/s
        The contact speeds commanded at this sample.
    force : float, N
        The outside force applied to the body from this sample to the next (a rig's; 0
        when nothing but the contacts acts).
    """

    time: float
    central_count: int
    wheel_counts: np.ndarray
    command: np.ndarray
    force: float = 0.0


def _int_array(value: Any, name: str, ndim: int) -> np.ndarray:
    array = np.asarray(value)
    if array.dtype.kind not in "iu" or array.ndim != ndim:
        raise ParameterError(parameter_message(
            name, "EncoderRecord", f"be a {ndim}-dimensional array of integer counts",
            f"an array of dtype {array.dtype} and shape {array.shape}"))
    array = array.astype(np.int64, copy=True)
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class EncoderRecord:
    """Encoder counts and commands sampled at one rate, with the truth when simulated.

    Parameters
    ----------
    times : array_like of shape (k,), s
        Sample stamps, strictly increasing (the nominal instants; with jitter the encoders
        were read slightly off them).
    central_counts : array_like of shape (k,), int
    wheel_counts : array_like of shape (k, n), int
    commands : array_like of shape (k, n), m/s
        Contact speeds commanded at each sample.
    central_resolution, wheel_resolution : float, m per count
        Distance of one count at the body's contact radius and at the wheels' contacts.
    wheel_backlash : float, m
        Gearbox play of the wheels, ``>= 0``.
    truth_speed, truth_position : array_like of shape (k,), optional
        True body speed (m/s) and position (m) at ``times``: for scoring only, never read
        by an estimator.
    truth_contact_speeds : array_like of shape (k, n), m/s, optional
        True contact speeds at ``times`` (scoring only).
    initial_commands : array_like of shape (n,), m/s, optional
        The command the motors had settled at before the first sample (the last command
        sent before ``times[0]``); ``None``: unknown, taken as ``commands[0]`` (the motors
        already run at the first command). Estimators use it to know whether the first
        command starts a motor transient.
    force : array_like of shape (k,), N, optional
        Outside force applied to the body from each sample to the next (a rig's, or the
        plant's ``external_force`` at the stamps), held over the period like the commands;
        ``None``: none (zeros). Estimators take it as a known input.
    """

    times: np.ndarray
    central_counts: np.ndarray
    wheel_counts: np.ndarray
    commands: np.ndarray
    central_resolution: float
    wheel_resolution: float
    wheel_backlash: float = 0.0
    truth_speed: np.ndarray | None = None
    truth_position: np.ndarray | None = None
    truth_contact_speeds: np.ndarray | None = None
    initial_commands: np.ndarray | None = None
    force: np.ndarray | None = None

    def __post_init__(self) -> None:
        owner = "EncoderRecord"
        times = as_float_array(self.times, "times", owner)
        if np.any(np.diff(times) <= 0):
            raise ParameterError(parameter_message("times", owner, "be strictly increasing",
                                                   times.tolist()[:8]))
        k = times.size
        central = _int_array(self.central_counts, "central_counts", 1)
        wheel = _int_array(self.wheel_counts, "wheel_counts", 2)
        commands = as_float_array(self.commands, "commands", owner, ndim=2)
        for name, array, shape in (("central_counts", central, (k,)),
                                   ("wheel_counts", wheel, (k, wheel.shape[1])),
                                   ("commands", commands, wheel.shape)):
            if array.shape != shape:
                raise ParameterError(parameter_message(
                    name, owner, f"have shape {shape}", f"an array of shape {array.shape}"))
        for name, value in (("times", times), ("central_counts", central), ("wheel_counts", wheel),
                            ("commands", commands)):
            object.__setattr__(self, name, value)
        for name in ("central_resolution", "wheel_resolution"):
            object.__setattr__(self, name, as_float(getattr(self, name), name, owner, low=0.0, low_open=True))
        object.__setattr__(self, "wheel_backlash", as_float(self.wheel_backlash, "wheel_backlash", owner, low=0.0))
        for name, ndim, shape in (("truth_speed", 1, (k,)), ("truth_position", 1, (k,)),
                                  ("truth_contact_speeds", 2, wheel.shape)):
            value = getattr(self, name)
            if value is None:
                continue
            array = as_float_array(value, name, owner, ndim=ndim)
            if array.shape != shape:
                raise ParameterError(parameter_message(
                    name, owner, f"have shape {shape}", f"an array of shape {array.shape}"))
            object.__setattr__(self, name, array)
        if self.initial_commands is not None:
            initial = as_float_array(self.initial_commands, "initial_commands", owner)
            if initial.shape != (wheel.shape[1],):
                raise ParameterError(parameter_message(
                    "initial_commands", owner, f"have shape ({wheel.shape[1]},)",
                    f"an array of shape {initial.shape}"))
            initial.setflags(write=False)
            object.__setattr__(self, "initial_commands", initial)
        if self.force is not None:
            force = as_float_array(self.force, "force", owner, ndim=1)
            if force.shape != (k,):
                raise ParameterError(parameter_message(
                    "force", owner, f"have shape ({k},)", f"an array of shape {force.shape}"))
            force.setflags(write=False)
            object.__setattr__(self, "force", force)

    @property
    def n_samples(self) -> int:
        """Number of samples ``k``."""
        return int(self.times.size)

    @property
    def n_wheels(self) -> int:
        """Number of wheel channels ``n``."""
        return int(self.wheel_counts.shape[1])

    @property
    def period(self) -> float:
        """Median sample period, s."""
        return float(np.median(np.diff(self.times))) if self.times.size > 1 else math.nan

    @property
    def duration(self) -> float:
        """Span of the stamps, s."""
        return float(self.times[-1] - self.times[0])

    @property
    def has_truth(self) -> bool:
        """True when the true body speed is recorded."""
        return self.truth_speed is not None

    def sample(self, k: int) -> EncoderSample:
        """Sample ``k`` as an :class:`EncoderSample` (what a closed loop sees)."""
        return EncoderSample(float(self.times[k]), int(self.central_counts[k]),
                             self.wheel_counts[k], self.commands[k],
                             0.0 if self.force is None else float(self.force[k]))

    def __len__(self) -> int:
        return self.n_samples


# -- exact positions from a simulation -------------------------------------------------------
#: Gauss-Legendre nodes per smooth piece of :func:`record_simulation`: exact for polynomials
#: of degree 15; on exponential pieces of rate mu over h it errs by about
#: ``h (mu h)^16 (8!)^4 / (17 (16!)^3)`` times the speed scale, below 1e-17 m for the
#: carousel (``h <= 20 ms``, ``mu = 1 / 7.5 ms``).
GAUSS_NODES = 8


def _contact_pieces(plant: Any, t_end: float) -> tuple[list[tuple[float, float, Any]], np.ndarray]:
    """The motor law solved piece by piece between switches: ``[(a, b, MotorPiece)]`` and
    the kinks of the contact speeds (switches and ramp ends), for dynamic motors."""
    from .motors import MotorPiece

    switches = plant.switching_times()
    bounds = [0.0, *switches[(switches > 0) & (switches < t_end)].tolist(), t_end]
    speeds = plant.initial_speeds()
    tau, rate = plant.motors.lag, plant.motors.rate_limit
    pieces, kinks = [], []
    for a, b in zip(bounds, bounds[1:]):
        piece = MotorPiece.build(a, speeds, plant.command(a), tau, rate)
        pieces.append((a, b, piece))
        ends = a + piece.ramp_end[(piece.ramp_end > 0) & (a + piece.ramp_end < b)]
        kinks.extend(ends.tolist())
        speeds = piece.speeds(np.array([b - a]))[0]
    return pieces, np.array(kinks)


def contact_speeds_at(plant: Any, times: Any) -> tuple[np.ndarray, np.ndarray]:
    """Contact speeds of a :class:`~toolkit.model.Plant` at any times, from the motor law.

    Parameters
    ----------
    plant : Plant
    times : array_like of shape (T,), s, ``>= 0``

    Returns
    -------
    speeds : ndarray of shape (T, n), m/s
        Ideal motors: the (clipped) commands, piecewise constant; dynamic motors: the
        closed-form solution (:class:`~toolkit.model.motors.MotorPiece`) of each piece.
    kinks : ndarray, s
        Times where the speeds jump or change slope (switches, ramp ends).
    """
    t = np.asarray(times, dtype=float)
    switches = plant.switching_times()
    if not plant.dynamic_motors or plant.commands is None:
        if plant.commands is None:
            return np.broadcast_to(plant.command(0.0), (t.size, plant.n)).copy(), switches
        raw = np.asarray(plant.commands(t), dtype=float).reshape(t.size, plant.n)
        low, high = plant.motors.speed_limits if plant.motors is not None else (-np.inf, np.inf)
        return np.clip(raw, low, high), switches
    horizon = float(max(t.max(initial=0.0), 1e-300))
    pieces, kinks = _contact_pieces(plant, horizon)
    out = np.empty((t.size, plant.n))
    for a, b, piece in pieces:
        inside = (t >= a) & ((t < b) | (b == horizon))
        if inside.any():
            out[inside] = piece.speeds(t[inside] - a)
    return out, np.unique(np.concatenate((switches, kinks)))


def _antiderivative(speed: Any, times: np.ndarray, breaks: np.ndarray) -> np.ndarray:
    """``integral_0^t speed`` at sorted ``times`` by Gauss-Legendre on each smooth piece.

    ``speed(nodes) -> (M,) or (M, n)``; ``breaks`` are the kinks of ``speed`` (every piece
    between consecutive breaks and times is smooth)."""
    from numpy.polynomial.legendre import leggauss

    top = float(times[-1])
    grid = np.unique(np.concatenate(([0.0], breaks[(breaks > 0) & (breaks < top)], times)))
    a, b = grid[:-1], grid[1:]
    x, w = leggauss(GAUSS_NODES)
    half = 0.5 * (b - a)
    nodes = (0.5 * (a + b))[:, None] + half[:, None] * x
    values = np.asarray(speed(nodes.ravel()), dtype=float)
    values = values.reshape(a.size, GAUSS_NODES, *values.shape[1:])
    pieces = np.einsum("j,sj...->s...", w, values) * half.reshape(-1, *([1] * (values.ndim - 2)))
    cumulative = np.concatenate((np.zeros((1, *pieces.shape[1:])), np.cumsum(pieces, axis=0)))
    return cumulative[np.searchsorted(grid, times)]


def record_simulation(result: Any, plant: Any, sensors: Sensors, *,
                      rng: np.random.Generator | None = None, t_end: float | None = None,
                      truth: bool = True, central_position: float = 0.0,
                      contact_positions: Any = None) -> EncoderRecord:
    """Sample an exact simulation through the sensor law (:func:`measure`) into a record.

    Parameters
    ----------
    result : SimulationResult
        An exact run (``simulate(plant, ..., method="exact")``) with its dense output
        ``speed_at``.
    plant : Plant
        The plant simulated: its commands and motor law give the contact speeds.
    sensors : Sensors
        ``n_wheels`` must equal ``plant.n``.
    rng : numpy.random.Generator, optional
        Draws jitter, missed counts and read noise (needed when any is non-zero).
    t_end : float, s, optional
        Last sample time bound; default the run's horizon.
    truth : bool
        Keep the true body speed, position and contact speeds at the stamps (scoring only).
    central_position : float, m
        Body position at ``t = 0`` on the central encoder's count grid (default 0: on a
        count edge). An encoder counts from wherever it was powered up, so the grid's phase
        is arbitrary: draw it uniformly over a count to study its effect.
    contact_positions : array_like of shape (n,), m, optional
        The contacts' positions at ``t = 0`` on the wheel encoders' grids (default 0).

    Returns
    -------
    EncoderRecord
        Samples at ``k / rate`` for ``k = 0 .. floor(t_end rate)``; the true positions in the
        encoders' frames (``central_position`` plus the travel).

    Notes
    -----
    Positions are exact integrals of the dense output: the body position is
    ``integral_0^t V``, each contact's position ``integral_0^t v_i``, computed by
    Gauss-Legendre (``GAUSS_NODES`` nodes) on every piece between consecutive read
    instants, events, switches and motor ramp ends, on each of which the speeds are smooth
    (lines or exponentials); the error is far below 1e-12 m. Jitter moves the read instants,
    not the stamps.
    """
    owner = "record_simulation"
    if not isinstance(sensors, Sensors):
        raise ParameterTypeError(parameter_message("sensors", owner, "be a Sensors", sensors))
    if getattr(result, "dense", None) is None or not hasattr(result, "speed_at"):
        raise ParameterTypeError(parameter_message(
            "result", owner, "be an exact SimulationResult with a dense output", result))
    if sensors.n_wheels != plant.n:
        raise ParameterError(parameter_message(
            "sensors", owner, f"have n_wheels = plant.n = {plant.n}", sensors.n_wheels))
    horizon = getattr(result.dense, "t_end", None) or result.t_final
    t_end = horizon if t_end is None else as_float(t_end, "t_end", owner, low=0.0, high=horizon)
    rate = sensors.rate
    stamps = sample_times(t_end, rate)
    reads = stamps
    if sensors.jitter > 0:
        if not isinstance(rng, np.random.Generator):
            raise ParameterTypeError(parameter_message(
                "rng", owner, "be a numpy.random.Generator when the sensors jitter", rng))
        quarter = 0.25 / rate
        reads = np.clip(stamps + np.clip(rng.normal(0.0, sensors.jitter, stamps.size), -quarter, quarter),
                        0.0, t_end)
    _, contact_kinks = contact_speeds_at(plant, np.array([t_end]))
    events = np.array([e.time for e in result.events], dtype=float)
    breaks = np.unique(np.concatenate((events, np.asarray(result.t, dtype=float), contact_kinks)))
    x0 = as_float(central_position, "central_position", owner)
    if not abs(x0) < 2.0**52 * sensors.central.distance_per_count:
        raise ParameterError(parameter_message("central_position", owner,
                                               "be within 2^52 counts of the grid's origin", x0))
    c0 = np.zeros(plant.n) if contact_positions is None else \
        as_float_array(contact_positions, "contact_positions", owner)
    if c0.shape != (plant.n,):
        raise ParameterError(parameter_message("contact_positions", owner, f"have shape ({plant.n},)",
                                               f"an array of shape {c0.shape}"))
    body = x0 + _antiderivative(result.speed_at, reads, breaks)
    contacts = c0 + _antiderivative(lambda t: contact_speeds_at(plant, t)[0], reads, contact_kinks)
    state = sensors.initial_state(plant.initial_speeds(), central_position=x0, contact_positions=c0)
    central, wheel, _ = measure(sensors, body, contacts, state, rng)
    truth_fields: dict[str, Any] = {}
    if truth:
        truth_fields = {
            "truth_speed": result.speed_at(stamps),
            "truth_position": body if sensors.jitter == 0 else x0 + _antiderivative(result.speed_at, stamps, breaks),
            "truth_contact_speeds": contact_speeds_at(plant, stamps)[0]}
    commands = np.asarray([plant.command(t) for t in stamps], dtype=float).reshape(stamps.size, plant.n)
    # The plant's outside force at each stamp, held to the next as the commands are.
    force = np.array([plant.external(t) for t in stamps], dtype=float)
    return EncoderRecord(stamps, central, wheel, commands, sensors.central.distance_per_count,
                         sensors.wheel.distance_per_count, sensors.backlash,
                         initial_commands=plant.initial_speeds(), force=force, **truth_fields)
