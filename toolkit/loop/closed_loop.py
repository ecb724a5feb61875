"""Closed loop at the sample rate: exact plant, motors, encoders, estimator and controller.

At each sample the sensor law reads the exact plant, the estimator observes, the controller
commands, and :func:`toolkit.simulation.advance` continues the plant exactly over the
period. A loop the compiled kernels support runs in :class:`toolkit.simulation.SampledRun`;
others run in Python around ``advance``; both give the same numbers. The sample's steps and
where the loop runs: docs/methods.md."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._compiled import budget_clock
from ..errors import as_float, as_float_array
from ..controllers.base import ControlLaw, Controller
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..model import Plant, sample_count, sample_times
from ..model.sensors import EncoderRecord, EncoderSample, SensorReader, Sensors, measure  # noqa: F401
from ..simulation import (Budget, ExactState, SampledLaw, SampledRun, SimulationStatus, advance,
                          refuse_backlash, sampled_supported)

__all__ = ["ClosedLoopResult", "simulate_closed_loop", "nominal_model", "HostStep", "PlantSide",
           "MAX_SAMPLES", "LOOP_RATE"]

#: Most samples one closed-loop run may take (the arrays it keeps grow with them).
MAX_SAMPLES = 10_000_000
#: Sample rate of a loop without sensors unless given, Hz.
LOOP_RATE = 50.0
#: Run loops the kernel supports in the kernel (:class:`toolkit.simulation.SampledRun`);
#: False: every loop in Python around ``advance`` (tests compare the two).
_COMPILED = True


@dataclass(frozen=True, eq=False)
class ClosedLoopResult:
    """One closed-loop run, sampled at the controller rate.

    Attributes
    ----------
    times : ndarray of shape (k,), s
        Nominal sample times ``k / rate``.
    speed : ndarray of shape (k,), m/s
        True body speed at each (actual) sample instant.
    estimate, variance : ndarray of shape (k,), m/s and (m/s)^2
        What the controller was given (the true speed and 0 without sensors).
    commands : ndarray of shape (k, n), m/s
        Commands sent at each sample (held until the next).
    force : ndarray of shape (k,), N
        Outside force applied by the controller over each period.
    contact_speeds : ndarray of shape (k, n), m/s
        Actual contact speeds at each sample.
    position : ndarray of shape (k,), m
        True body position.
    record : EncoderRecord or None
        The encoder counts with the commands and the truth (None without sensors).
    status : SimulationStatus
    message : str
    wall_time : float, s
    """

    times: np.ndarray
    speed: np.ndarray
    estimate: np.ndarray
    variance: np.ndarray
    commands: np.ndarray
    force: np.ndarray
    contact_speeds: np.ndarray
    position: np.ndarray
    record: EncoderRecord | None
    status: SimulationStatus
    message: str
    wall_time: float

    @property
    def estimation_error(self) -> np.ndarray:
        """``estimate - speed`` at each sample, m/s."""
        return self.estimate - self.speed


def _check(plant: Any, controller: Any, sensors: Any, estimator: Any, rate: Any, t_end: Any
           ) -> tuple[float, int]:
    owner = "simulate_closed_loop"
    if not isinstance(plant, Plant):
        raise ParameterTypeError(parameter_message("plant", owner, "be a Plant", plant))
    refuse_backlash(plant, owner)         # the plant steps are the exact engine's (advance)
    if not hasattr(controller, "bind"):
        raise ParameterTypeError(parameter_message(
            "controller", owner, "be a controller (toolkit.controllers)", controller))
    if sensors is not None:
        Sensors.checked(sensors, plant.n, owner)
        if rate is not None and as_float(rate, "rate", owner) != sensors.rate:
            raise ParameterError(parameter_message(
                "rate", owner, f"equal the sensors' rate ({sensors.rate:g} Hz) or be None", rate))
        rate = sensors.rate
    elif estimator is not None:
        raise ParameterError(parameter_message(
            "estimator", owner, "come with the sensors it reads (sensors=Sensors(...))", estimator))
    rate = LOOP_RATE if rate is None else as_float(rate, "rate", owner, low=0.0, low_open=True)
    t_end = as_float(t_end, "t_end", owner, low=0.0, low_open=True)
    samples = sample_count(t_end, rate)
    period = 1.0 / rate
    if samples > MAX_SAMPLES or not (period > 0 and t_end + period > t_end):
        raise ParameterError(parameter_message(
            "rate", owner, f"give at most {MAX_SAMPLES} samples over t_end = {t_end:g} s with a "
            "period the simulation clock resolves", rate))
    return rate, samples


def _run_sampled(plant: Plant, law: ControlLaw, program: SampledLaw | None, times: np.ndarray,
                 sensors: Sensors | None, estimator: Any, v0: float,
                 budget: Budget | None) -> SampledRun:
    """The loop in the compiled kernel (:class:`toolkit.simulation.SampledRun`): the plant
    steps and the sensor law always; the law too when it has a compiled form (``program``);
    a Python estimator (or law) is called per sample between two kernel calls."""
    run = SampledRun(plant, times, v0=v0, sensors=sensors, law=program,
                     estimator=estimator is not None, budget=budget)
    samples = times.size
    if estimator is None and program is not None:
        run.run_to(samples)                       # every sample in one kernel call
        return run
    t_list = times.tolist()
    output, update = law.output, law.update
    z = law.initial_state()
    previous, previous_force = plant.initial_speeds(), 0.0
    observe = commanded = None
    if estimator is not None:
        observe, commanded = estimator.observe, estimator.commanded
    central, wheel, estimate, variance = run.central, run.wheel, run.estimate, run.variance
    commands, force, speed = run.commands, run.force, run.speed
    for k in range(samples):
        t = t_list[k]
        if observe is not None:
            est, var = observe(EncoderSample(t, int(central[k]), wheel[k], previous,
                                             previous_force))
            estimate[k], variance[k] = est, var
        else:
            est = float(speed[k])
        if program is None:
            action = output(t, z, est)
            commands[k] = action.commands
            force[k] = float(action.force)
            z = update(t, z, est)
        if not run.run_to(k + 1):
            break
        previous, previous_force = commands[k], float(force[k])
        if commanded is not None:
            commanded(previous, previous_force)
    return run


class HostStep:
    """The host's half of one sample, as every loop runs it (offline here, live in
    :mod:`toolkit.live`): the estimator observes the counts, the law acts on its estimate,
    the estimator is told the command, the law's state moves on.

    Parameters
    ----------
    law : ControlLaw
        The controller bound to the plant and period.
    estimator : Estimator or None
        Reset by the caller; None: the law acts on the true speed (an ideal loop).
    initial_commands : ndarray of shape (n,), m/s
        The commands before the first sample (the motors' settled speeds).
    """

    def __init__(self, law: ControlLaw, estimator: Any, initial_commands: np.ndarray) -> None:
        self.output, self.update = law.output, law.update
        self.z = law.initial_state()
        self.observe = self.commanded = None
        if estimator is not None:
            self.observe, self.commanded = estimator.observe, estimator.commanded
        self.previous, self.previous_force = initial_commands, 0.0

    def __call__(self, t: float, central: int, wheel: np.ndarray, true_speed: float = math.nan
                 ) -> tuple[float, float, np.ndarray, float]:
        """Sample at ``t`` (s) with its counts; returns the estimate (m/s), its variance
        ((m/s)^2), the commands (m/s, shape (n,)) and the outside force (N) to send:
        :meth:`act`, then :meth:`settle`."""
        out = self.act(t, central, wheel, true_speed)
        self.settle()
        return out

    def act(self, t: float, central: int, wheel: np.ndarray, true_speed: float = math.nan
            ) -> tuple[float, float, np.ndarray, float]:
        """What the command needs: the estimate from the counts, then the law's action (a live
        loop sends it before :meth:`settle`)."""
        if self.observe is not None:
            est, var = self.observe(EncoderSample(t, central, wheel, self.previous, self.previous_force))
        else:
            est, var = true_speed, 0.0
        action = self.output(t, self.z, est)
        u, f = action.commands, float(action.force)
        self._acted = (t, est, u, f)
        return est, var, u, f

    def settle(self) -> None:
        """The rest of the sample, once the command is sent: the estimator told the command,
        the law's state moved on."""
        t, est, u, f = self._acted
        if self.commanded is not None:
            self.commanded(u, f)
        self.previous, self.previous_force = u, f
        self.z = self.update(t, self.z, est)


class PlantSide:
    """The device's half of the loop: the exact plant held between samples
    (:func:`~toolkit.simulation.advance`) and the sensor law read at them.

    Parameters
    ----------
    plant : Plant
    sensors : Sensors or None
    v0 : float, m/s
    rng : numpy.random.Generator
        The sensors' draws (missed counts, read noise), then each period's jitter.
    offsets : ndarray of shape (k, n), m/s, or None
        The motors' wander about the commands, one row per period (past the end: the last).
    budget : Budget or None
    """

    def __init__(self, plant: Plant, sensors: Sensors | None, v0: float, rng: np.random.Generator,
                 offsets: np.ndarray | None = None, budget: Budget | None = None) -> None:
        self.plant, self.rng, self.offsets, self.budget = plant, rng, offsets, budget
        self.state = ExactState.initial(plant, v0)
        self.X, self.x = 0.0, np.zeros(plant.n)
        self.reader = None
        self.jitter = 0.0
        if sensors is not None:
            self.reader = SensorReader(sensors, sensors.initial_state(self.state.contact_speeds), rng)
            self.jitter = sensors.jitter
        self.status, self.message = SimulationStatus.SUCCESS, ""

    def read(self) -> tuple[int, np.ndarray]:
        """The encoders' counts now (the sensor law)."""
        return self.reader.read(self.X, self.x)

    def next_instant(self, t_next: float, period: float) -> float:
        """The instant the next sample is read: ``t_next`` plus the sensors' jitter."""
        if self.jitter > 0:
            t_next += float(np.clip(self.rng.normal(0.0, self.jitter), -0.25 * period, 0.25 * period))
        return t_next

    def hold(self, k: int, command: np.ndarray, force: float, t1: float) -> bool:
        """Hold the command of period ``k`` (plus the wander) up to ``t1`` (s); False when the
        plant step failed (``status`` and ``message`` say why)."""
        held = command if self.offsets is None else command + self.offsets[min(k, self.offsets.shape[0] - 1)]
        step = advance(self.plant, self.state, held, t1, external=force, budget=self.budget)
        if step.status is not SimulationStatus.SUCCESS:
            self.status, self.message = step.status, step.message
            return False
        self.state = step.state
        self.X, self.x = self.X + step.body_displacement, self.x + step.contact_displacements
        return True


def _run_python(plant: Plant, law: ControlLaw, times: np.ndarray, sensors: Sensors | None,
                estimator: Any, v0: float, seed: Any, budget: Budget | None,
                offsets: np.ndarray | None = None) -> tuple[Any, ...]:
    """The loop in Python around :class:`PlantSide` (:func:`~toolkit.simulation.advance` and
    the sensor law) and :class:`HostStep`: noisy sensors, jitter, the motors' wander
    (``offsets``), and the plants and budgets the kernel does not run
    (:func:`toolkit.simulation.sampled_supported`)."""
    rng = np.random.default_rng(seed)
    samples, n = times.size, plant.n
    period = float(times[1] - times[0]) if samples > 1 else 0.0
    t_list = times.tolist()
    speed, estimate, variance = [0.0] * samples, [0.0] * samples, [0.0] * samples
    position, force = [0.0] * samples, [0.0] * samples
    commands, contact = np.empty((samples, n)), np.empty((samples, n))
    central, wheel = [0] * samples, np.zeros((samples, n), dtype=np.int64)
    side = PlantSide(plant, sensors, v0, rng, offsets, budget)
    host = HostStep(law, estimator, side.state.contact_speeds)
    last = samples
    c, w = 0, wheel[0]
    for k in range(samples):
        t = t_list[k]
        state = side.state
        speed[k], position[k], contact[k] = state.V, side.X, state.contact_speeds
        if side.reader is not None:
            c, w = side.read()
            central[k] = c
            wheel[k] = w
        estimate[k], variance[k], u, f = host(t, c, w, state.V)
        commands[k] = u
        force[k] = f
        if k + 1 == samples:
            break
        if not side.hold(k, u, f, side.next_instant(t_list[k + 1], period)):
            last = k + 1
            break
    return (np.array(speed), np.array(estimate), np.array(variance), np.array(position),
            np.array(force), np.array(central, dtype=np.int64), wheel, commands, contact, side.status,
            side.message, last)


def nominal_model(plant: Plant, sensors: Sensors) -> Any:
    """The :class:`~toolkit.estimation.EstimatorModel` of the default estimator of
    :func:`simulate_closed_loop` (a :class:`~toolkit.estimation.KalmanEstimator` on it): the
    plant's nominal friction magnitudes, mass, drag, motor lag and speed limits, read by
    ``sensors``. It holds nothing of the contact speeds, so plants that differ only in those
    share it."""
    from ..estimation import EstimatorModel

    motors = plant.motors
    return EstimatorModel(plant.contacts.forces, plant.mass, sensors,
                          motor_lag=motors.lag if motors is not None else 0.0, damping=plant.damping,
                          speed_limits=motors.speed_limits if motors is not None else (-math.inf, math.inf))


def simulate_closed_loop(plant: Plant, controller: Controller, t_end: float, *,
                         sensors: Sensors | None = None, estimator: Any = None,
                         rate: float | None = None, v0: float = 0.0, seed: Any = None,
                         budget: Budget | None = None, wander: Any = None) -> ClosedLoopResult:
    """Run ``controller`` on ``plant`` from ``t = 0`` to ``t_end`` at the sample rate.

    Parameters
    ----------
    plant : Plant
        Contacts (their speeds are the contact speeds at ``t = 0``: motors start settled
        there), mass, drag, motors. Its own ``commands`` are ignored (the controller's
        are used) and so is its ``external_force`` (a controller's rig force replaces it).
    controller : Controller
        E.g. :class:`~toolkit.controllers.VirtualViscosity`.
    t_end : float, s
    sensors : Sensors, optional
        Encoders read at each sample; ``None``: the controller sees the true speed.
    estimator : Estimator, optional
        Turns the counts into a speed estimate (needs ``sensors``); default with sensors: a
        :class:`~toolkit.estimation.KalmanEstimator` on the plant's nominal parameters
        (``nominal_model``).
    rate : float, Hz, optional
        Sample rate without sensors (default 50 Hz); with sensors their rate is used.
    v0 : float, m/s
        Body speed at ``t = 0``.
    seed : int or numpy.random.SeedSequence, optional
        Seeds the sensors' missed counts, read noise and jitter.
    budget : Budget, optional
        Guards of each plant step.
    wander : array_like of shape (k, n), m/s, optional
        The motors' wander about their commands (a true world's,
        :meth:`toolkit.model.truth.TrueWorld.wander`): over the period after sample ``j`` the
        motors run towards ``command + wander[j]`` (rows past the end: the last one). The
        record and the result log the commands sent.

    Returns
    -------
    ClosedLoopResult
    """
    rate, samples = _check(plant, controller, sensors, estimator, rate, t_end)
    offsets = None
    if wander is not None:
        offsets = as_float_array(wander, "wander", "simulate_closed_loop", ndim=2)
        if offsets.shape[1] != plant.n:
            raise ParameterError(parameter_message("wander", "simulate_closed_loop",
                                                   f"have one column per contact ({plant.n})",
                                                   f"an array of shape {offsets.shape}"))
    started = budget_clock()
    period = 1.0 / rate
    law: ControlLaw = controller.bind(plant, period)
    if sensors is not None and estimator is None:
        from ..estimation import KalmanEstimator   # filterpy: only with sensors
        estimator = KalmanEstimator(nominal_model(plant, sensors))
    times = sample_times(t_end, rate)
    initial = plant.initial_speeds()
    if sensors is not None:
        estimator.reset(speed=float(v0), contact_speeds=initial)
    if _COMPILED and offsets is None and sampled_supported(plant, sensors, budget):
        program = getattr(law, "sampled", None)
        run = _run_sampled(plant, law, None if program is None else program(), times,
                           sensors, estimator, float(v0), budget)
        speed, estimate, variance, position = run.speed, run.estimate, run.variance, run.position
        force, central, wheel, commands = run.force, run.central, run.wheel, run.commands
        contact, status, message, last = run.contact, run.status, run.message, run.last
    else:
        (speed, estimate, variance, position, force, central, wheel, commands, contact, status,
         message, last) = _run_python(plant, law, times, sensors, estimator, float(v0), seed,
                                      budget, offsets)
    keep = slice(0, last)
    record = None
    if sensors is not None:
        record = EncoderRecord(times=times[keep], central_counts=central[keep],
                               wheel_counts=wheel[keep], commands=commands[keep],
                               central_resolution=sensors.central.distance_per_count,
                               wheel_resolution=sensors.wheel.distance_per_count,
                               wheel_backlash=sensors.backlash, truth_speed=speed[keep],
                               truth_position=position[keep], truth_contact_speeds=contact[keep],
                               initial_commands=plant.initial_speeds(), force=force[keep])
    return ClosedLoopResult(times[keep], speed[keep], estimate[keep], variance[keep],
                            commands[keep], force[keep], contact[keep], position[keep], record,
                            status, message or status.value, budget_clock() - started)
