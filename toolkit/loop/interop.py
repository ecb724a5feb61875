"""python-control interop: the plant, an estimator and a controller as discrete-time
``control.NonlinearIOSystem`` blocks that ``control.interconnect`` joins.

Nothing is re-implemented: the exact plant step, the sensor law, the filter and the control
law are the toolkit's own, so ``control.input_output_response`` of
:func:`closed_loop_system` reproduces :func:`toolkit.simulate_closed_loop` sample for sample.
The blocks' states, and how an estimator's object state survives python-control's repeated
output calls: docs/methods.md. ``control`` is imported inside the functions."""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import as_float, as_float_array
from ..errors import ParameterError, ParameterTypeError, SolverError, parameter_message
from ..estimation import Estimator
from ..model import Plant, sample_times
from ..model.sensors import EncoderSample, Sensors, SensorState, measure
from ..simulation import Budget, ExactState, SimulationStatus, advance

__all__ = ["IOBlock", "LoopSystem", "plant_system", "estimator_system", "controller_system",
           "closed_loop_system", "viscous_system"]


@dataclass(frozen=True, eq=False)
class IOBlock:
    """A discrete-time ``control.NonlinearIOSystem`` and the state it starts from.

    Attributes
    ----------
    system : control.NonlinearIOSystem
        ``dt = period``; its signals are named (see each constructor).
    initial_state : ndarray of shape (system.nstates,)
    period : float, s
        Sample period ``1 / rate``.
    """

    system: Any
    initial_state: np.ndarray
    period: float


@dataclass(frozen=True, eq=False)
class LoopSystem:
    """The interconnection of plant, estimator (with sensors) and controller.

    Attributes
    ----------
    system : control.InterconnectedSystem
        No inputs; outputs ``speed`` (true body speed, m/s), ``estimate`` (what the controller
        was given, m/s), ``command[0..n-1]`` (m/s), ``force`` (N) and, with sensors,
        ``variance`` (the estimate's, (m/s)^2).
    initial_state : ndarray
        The blocks' initial states, in the order plant, estimator, controller.
    period : float, s
    blocks : tuple of IOBlock
    """

    system: Any
    initial_state: np.ndarray
    period: float
    blocks: tuple[IOBlock, ...]

    def times(self, t_end: float) -> np.ndarray:
        """Sample times (:func:`toolkit.model.sample_times`), s: pass them to
        ``control.input_output_response`` (the same grid as :func:`toolkit.simulate_closed_loop`)."""
        t_end = as_float(t_end, "t_end", "LoopSystem.times", low=0.0, low_open=True)
        return sample_times(t_end, 1.0 / self.period)


def _rate(rate: Any, sensors: Sensors | None, owner: str) -> float:
    if sensors is not None:
        if rate is not None and as_float(rate, "rate", owner) != sensors.rate:
            raise ParameterError(parameter_message(
                "rate", owner, f"equal the sensors' rate ({sensors.rate:g} Hz) or be None", rate))
        return sensors.rate
    return 50.0 if rate is None else as_float(rate, "rate", owner, low=0.0, low_open=True)


def _index(t: float, rate: float) -> int:
    """The sample index of a sample time ``t = k / rate`` (:func:`toolkit.model.sample_times`)."""
    return int(round(t * rate))


# -- plant ----------------------------------------------------------------------------------

class _PlantLayout:
    """Where each quantity sits in the plant block's state vector (n contacts)."""

    def __init__(self, n: int, sensors: bool) -> None:
        self.n = n
        self.V, self.v = 0, slice(1, 1 + n)
        self.X, self.x = 1 + n, slice(2 + n, 2 + 2 * n)
        self.mode = slice(2 + 2 * n, 5 + 2 * n)          # stuck, hint (-1: none), releasing
        end = 5 + 2 * n
        if sensors:
            self.motor = slice(end, end + n)
            self.central_count = end + n
            self.wheel_count = slice(end + n + 1, end + 2 * n + 1)
            self.central_offset = end + 2 * n + 1
            self.wheel_offset = slice(end + 2 * n + 2, end + 3 * n + 2)
            self.central_read = end + 3 * n + 2
            self.wheel_read = slice(end + 3 * n + 3, end + 4 * n + 3)
            end += 4 * n + 3
        self.size = end


def _index_or_none(value: float) -> int | None:
    return None if value < 0 else int(value)


def _sensor_state(x: np.ndarray, at: _PlantLayout) -> SensorState:
    return SensorState(motor=x[at.motor].copy(), central_count=int(x[at.central_count]),
                       wheel_count=x[at.wheel_count].astype(np.int64),
                       central_offset=int(x[at.central_offset]),
                       wheel_offset=x[at.wheel_offset].astype(np.int64))


def _store_sensors(x: np.ndarray, at: _PlantLayout, state: SensorState, central: np.ndarray,
                   wheel: np.ndarray) -> None:
    x[at.motor] = state.motor
    x[at.central_count] = state.central_count
    x[at.wheel_count] = state.wheel_count
    x[at.central_offset] = state.central_offset
    x[at.wheel_offset] = state.wheel_offset
    x[at.central_read] = central[0]
    x[at.wheel_read] = wheel[0]


def plant_system(plant: Plant, *, sensors: Sensors | None = None, rate: float | None = None,
                 v0: float = 0.0, seed: Any = None, budget: Budget | None = None,
                 name: str = "plant") -> IOBlock:
    """The exact plant (and its encoders) as a discrete-time ``control.NonlinearIOSystem``.

    Parameters
    ----------
    plant : Plant
        Contacts (their speeds are the contact speeds at ``t = 0``), mass, drag, motors; its
        own ``commands`` and ``external_force`` are not used (the inputs are).
    sensors : Sensors, optional
        Encoders read at each sample (``jitter`` must be 0); their rate is the sample rate.
    rate : float, Hz, optional
        Sample rate without sensors (default 50 Hz).
    v0 : float, m/s
        Body speed at ``t = 0``.
    seed : int or numpy.random.SeedSequence, optional
        Seeds the sensors' missed counts and read noise (restarted at every run from 0).
    budget : Budget, optional
        Guards of each plant step; a step that stops raises :class:`~toolkit.errors.SolverError`
        (python-control has no way to end a run early).
    name : str

    Returns
    -------
    IOBlock
        Inputs ``command[0..n-1]`` (m/s, held over the period) and ``force`` (N, outside
        force over the period); outputs ``speed`` (m/s) and, with sensors,
        ``central_count`` and ``wheel_count[0..n-1]`` (counts read at ``t_k``).
    """
    import control   # python-control: loaded only by the interop

    owner = "plant_system"
    if not isinstance(plant, Plant):
        raise ParameterTypeError(parameter_message("plant", owner, "be a Plant", plant))
    if sensors is not None:
        Sensors.checked(sensors, plant.n, owner)
        if sensors.jitter != 0.0:
            raise ParameterError(parameter_message(
                "sensors", owner, "have jitter = 0 (a discrete-time system reads at k dt; "
                "simulate_closed_loop handles jitter)", f"jitter {sensors.jitter:g} s"))
    if budget is not None and not isinstance(budget, Budget):
        raise ParameterTypeError(parameter_message("budget", owner, "be a Budget or None", budget))
    rate = _rate(rate, sensors, owner)
    period = 1.0 / rate
    v0 = as_float(v0, "v0", owner)
    n = plant.n
    at = _PlantLayout(n, sensors is not None)
    speeds0 = plant.initial_speeds()
    rng: list[np.random.Generator] = []

    def first_reading(x: np.ndarray) -> None:
        """Restart the generator from the seed and read the counts at t = 0 into ``x``."""
        rng[:] = [np.random.default_rng(seed)]
        state = sensors.initial_state(speeds0)       # type: ignore[union-attr]
        c, w, state = measure(sensors, [0.0], np.zeros((1, n)), state, rng[0])
        _store_sensors(x, at, state, c, w)

    x0 = np.zeros(at.size)
    x0[at.V], x0[at.v], x0[at.mode] = v0, speeds0, (-1.0, -1.0, 0.0)
    if sensors is not None:
        first_reading(x0)

    def update(t: float, x: np.ndarray, u: np.ndarray, params: dict) -> np.ndarray:
        k = _index(t, rate)
        stuck, hint, releasing = x[at.mode]
        state = ExactState(k / rate, float(x[at.V]), x[at.v].copy(), _index_or_none(stuck),
                           _pending=(_index_or_none(hint), float(releasing)))
        step = advance(plant, state, np.asarray(u[:n], dtype=float), (k + 1) / rate,
                       external=float(u[n]), budget=budget)
        if step.status is not SimulationStatus.SUCCESS:
            raise SolverError(f"The plant step from t = {k / rate:g} s stopped: {step.message}.")
        out = np.array(x, dtype=float)
        new = step.state
        out[at.V], out[at.v] = new.V, new.contact_speeds
        out[at.X] = x[at.X] + step.body_displacement
        out[at.x] = x[at.x] + step.contact_displacements
        hint, releasing = new._pending
        out[at.mode] = (-1.0 if new.stuck is None else new.stuck, -1.0 if hint is None else hint,
                        releasing)
        if sensors is not None:
            if k == 0:                                # a new run: the generator restarts
                first_reading(np.zeros(at.size))
            c, w, sensor_state = measure(sensors, [out[at.X]], out[at.x][None, :],
                                         _sensor_state(x, at), rng[0])
            _store_sensors(out, at, sensor_state, c, w)
        return out

    outputs = ["speed"]
    if sensors is not None:
        outputs += ["central_count"] + [f"wheel_count[{i}]" for i in range(n)]

    def output(t: float, x: np.ndarray, u: np.ndarray, params: dict) -> np.ndarray:
        if sensors is None:
            return x[at.V:at.V + 1]
        return np.concatenate(([x[at.V]], [x[at.central_read]], x[at.wheel_read]))

    system = control.NonlinearIOSystem(
        update, output, inputs=[f"command[{i}]" for i in range(n)] + ["force"], outputs=outputs,
        states=at.size, dt=period, name=name)
    return IOBlock(system, x0, period)


# -- estimator ------------------------------------------------------------------------------

class _SteppedEstimator:
    """An estimator stepped by python-control: observe on a copy, commit in the update."""

    def __init__(self, estimator: Estimator, n: int, v0: float, rate: float,
                 contact_speeds: np.ndarray | None) -> None:
        self.estimator, self.n, self.v0, self.rate = estimator, n, v0, rate
        self.contact_speeds = contact_speeds
        self.k = -1                                   # samples committed; -1: never run
        self.committed: Estimator | None = None
        self.seen: dict[bytes, tuple[Estimator, tuple[float, float]]] = {}

    def _base(self, x: np.ndarray) -> tuple[int, Estimator]:
        k = int(x[0])
        if k == 0 and self.k != 0:                    # a new run from the initial state
            fresh = copy.deepcopy(self.estimator)
            fresh.reset(speed=self.v0, contact_speeds=self.contact_speeds)
            self.k, self.committed, self.seen = 0, fresh, {}
        if k != self.k or self.committed is None:
            raise SolverError(
                f"The estimator block must be run from its initial state, one sample after the "
                f"other: its state says sample {k}, it has observed {max(self.k, 0)}.")
        return k, self.committed

    def _observed(self, x: np.ndarray, u: np.ndarray) -> tuple[Estimator, tuple[float, float]]:
        k, base = self._base(x)
        counts = np.asarray(u[:self.n + 1], dtype=float)
        key = counts.tobytes()
        if key not in self.seen:
            trial = copy.deepcopy(base)
            result = trial.observe(EncoderSample(k / self.rate, int(counts[0]),
                                                 counts[1:].astype(np.int64),
                                                 np.asarray(u[self.n + 1:2 * self.n + 1], dtype=float),
                                                 float(u[2 * self.n + 1])))
            self.seen[key] = (trial, result)
        return self.seen[key]

    def output(self, t: float, x: np.ndarray, u: np.ndarray) -> tuple[float, float]:
        return self._observed(x, u)[1]

    def update(self, t: float, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        trial, (V, P) = self._observed(x, u)
        trial.commanded(np.array(u[self.n + 1:2 * self.n + 1], dtype=float), float(u[2 * self.n + 1]))
        self.committed, self.seen, self.k = trial, {}, self.k + 1
        return np.array([float(self.k), V, P])


def estimator_system(estimator: Estimator, sensors: Sensors, *, v0: float = 0.0,
                     contact_speeds: Any = None, name: str = "estimator") -> IOBlock:
    """A steppable estimator (e.g. :class:`~toolkit.estimation.KalmanEstimator`) as a
    discrete-time ``control.NonlinearIOSystem``.

    Parameters
    ----------
    estimator : Estimator
        Stepped by its own ``observe`` / ``commanded`` (the smoother, offline, cannot be);
        left untouched: each run steps a copy, reset to ``v0``.
    sensors : Sensors
        The encoders it reads (their rate is the block's).
    v0 : float, m/s
        The speed the estimator is reset to (as :func:`toolkit.simulate_closed_loop` does).
    contact_speeds : array_like of shape (n,), m/s, optional
        The speeds the motors had settled at before the first sample (the plant's
        ``initial_speeds()``, as :func:`toolkit.simulate_closed_loop` tells its estimator);
        ``None``: the first command's.
    name : str

    Returns
    -------
    IOBlock
        Inputs ``central_count``, ``wheel_count[0..n-1]`` (the counts read at ``t_k``),
        ``command[0..n-1]`` (m/s, the command sent at ``t_k``) and ``force`` (N, the
        outside force applied from ``t_k``, a known input like the command); outputs ``estimate`` (m/s)
        and ``variance`` ((m/s)^2) at ``t_k``; states: samples observed, the last estimate
        and its variance.
    """
    import control   # python-control: loaded only by the interop

    owner = "estimator_system"
    if not isinstance(estimator, Estimator):
        raise ParameterTypeError(parameter_message("estimator", owner, "be an Estimator", estimator))
    if not isinstance(sensors, Sensors):
        raise ParameterTypeError(parameter_message("sensors", owner, "be a Sensors", sensors))
    n, period = sensors.n_wheels, sensors.period
    if contact_speeds is not None:
        contact_speeds = as_float_array(contact_speeds, "contact_speeds", owner)
        if contact_speeds.shape != (n,):
            raise ParameterError(parameter_message(
                "contact_speeds", owner, f"hold one speed per wheel encoder ({n})", contact_speeds.tolist()))
    stepped = _SteppedEstimator(estimator, n, as_float(v0, "v0", owner), sensors.rate, contact_speeds)

    def update(t: float, x: np.ndarray, u: np.ndarray, params: dict) -> np.ndarray:
        return stepped.update(t, x, u)

    def output(t: float, x: np.ndarray, u: np.ndarray, params: dict) -> np.ndarray:
        return np.array(stepped.output(t, x, u))

    counts = ["central_count"] + [f"wheel_count[{i}]" for i in range(n)]
    system = control.NonlinearIOSystem(
        update, output, inputs=counts + [f"command[{i}]" for i in range(n)] + ["force"],
        outputs=["estimate", "variance"], states=["samples", "last_estimate", "last_variance"],
        dt=period, name=name)
    return IOBlock(system, np.array([0.0, float(v0), 0.0]), period)


# -- controller -----------------------------------------------------------------------------

def controller_system(controller: Any, plant: Plant, *, rate: float = 50.0,
                      name: str = "controller") -> IOBlock:
    """A controller's law (``controller.bind(plant, 1 / rate)``) as a discrete-time
    ``control.NonlinearIOSystem``.

    Parameters
    ----------
    controller : Controller
        E.g. :class:`~toolkit.controllers.VirtualViscosity`.
    plant : Plant
        The plant it is bound to.
    rate : float, Hz
    name : str

    Returns
    -------
    IOBlock
        Input ``estimate`` (m/s); outputs ``command[0..n-1]`` (m/s) and ``force`` (N); the
        state is the law's own (``law.n_states`` entries; a law without state gets one
        unused entry, python-control's static systems having no sample time).
    """
    import control   # python-control: loaded only by the interop

    owner = "controller_system"
    if not hasattr(controller, "bind"):
        raise ParameterTypeError(parameter_message(
            "controller", owner, "be a controller (toolkit.controllers)", controller))
    if not isinstance(plant, Plant):
        raise ParameterTypeError(parameter_message("plant", owner, "be a Plant", plant))
    period = 1.0 / as_float(rate, "rate", owner, low=0.0, low_open=True)
    law = controller.bind(plant, period)
    m = law.n_states

    def update(t: float, x: np.ndarray, u: np.ndarray, params: dict) -> np.ndarray:
        return np.asarray(law.update(t, x[:m], float(u[0])), dtype=float) if m else x

    def output(t: float, x: np.ndarray, u: np.ndarray, params: dict) -> np.ndarray:
        action = law.output(t, x[:m], float(u[0]))
        return np.concatenate((action.commands, [action.force]))

    system = control.NonlinearIOSystem(
        update, output, inputs=["estimate"],
        outputs=[f"command[{i}]" for i in range(plant.n)] + ["force"],
        states=max(m, 1), dt=period, name=name)
    x0 = np.asarray(law.initial_state(), dtype=float) if m else np.zeros(1)
    return IOBlock(system, x0, period)


def closed_loop_system(plant: Plant, controller: Any, *, sensors: Sensors | None = None,
                       estimator: Estimator | None = None, rate: float | None = None,
                       v0: float = 0.0, seed: Any = None, budget: Budget | None = None) -> LoopSystem:
    """Plant, estimator and controller joined by ``control.interconnect`` at the sample rate.

    The same loop as :func:`toolkit.simulate_closed_loop` (with ``sensors``, ``estimator``
    is required here: the block steps a copy of it). Simulate it with
    ``control.input_output_response(loop.system, loop.times(t_end), 0, loop.initial_state)``.

    Parameters
    ----------
    plant, controller, sensors, rate, v0, seed, budget
        As :func:`toolkit.simulate_closed_loop` (sensors without jitter).
    estimator : Estimator, optional
        Needs ``sensors`` and is needed with them.

    Returns
    -------
    LoopSystem
    """
    import control   # python-control: loaded only by the interop

    owner = "closed_loop_system"
    if sensors is None and estimator is not None:
        raise ParameterError(parameter_message(
            "estimator", owner, "come with the sensors it reads (sensors=Sensors(...))", estimator))
    if sensors is not None and estimator is None:
        raise ParameterError(parameter_message(
            "estimator", owner, "be given with sensors (e.g. a KalmanEstimator)", estimator))
    rate = _rate(rate, sensors, owner)
    n = plant.n if isinstance(plant, Plant) else 0
    plant_block = plant_system(plant, sensors=sensors, rate=rate, v0=v0, seed=seed, budget=budget)
    law_block = controller_system(controller, plant, rate=rate)
    blocks = [plant_block]
    commands = [f"command[{i}]" for i in range(n)]
    connections = [[f"plant.{c}", f"controller.{c}"] for c in commands]
    connections.append(["plant.force", "controller.force"])
    estimate = "plant.speed"
    if sensors is not None:
        est_block = estimator_system(estimator, sensors, v0=v0,    # type: ignore[arg-type]
                                     contact_speeds=plant.initial_speeds())
        blocks.append(est_block)
        connections += [[f"estimator.{c}", f"plant.{c}"]
                        for c in ["central_count"] + [f"wheel_count[{i}]" for i in range(n)]]
        connections += [[f"estimator.{c}", f"controller.{c}"] for c in commands + ["force"]]
        estimate = "estimator.estimate"
    connections.append(["controller.estimate", estimate])
    blocks.append(law_block)
    outlist = ["plant.speed", estimate] + [f"controller.{c}" for c in commands] + ["controller.force"]
    outputs = ["speed", "estimate"] + commands + ["force"]
    if sensors is not None:
        outlist.append("estimator.variance")
        outputs.append("variance")
    system = control.interconnect(
        [b.system for b in blocks], connections=connections, inplist=[], outlist=outlist,
        outputs=outputs, dt=plant_block.period, name="closed_loop")
    return LoopSystem(system, np.concatenate([b.initial_state for b in blocks]), plant_block.period,
                      tuple(blocks))


def viscous_system(slope: float, mass: float, *, damping: float = 0.0, rate: float | None = None) -> Any:
    """The linear law ``m dV/dt = -(k + c) (V - V_ref)`` a viscous staircase stands for, as
    ``control.ss``: input ``V_ref`` (m/s), output ``V`` (m/s), pole ``-(k + c) / m``.

    Parameters
    ----------
    slope : float, N s/m
        Commanded ``k = -dF/dV``, ``> 0``.
    mass : float, kg
    damping : float, N s/m
        Bearing drag ``c >= 0`` (pulls towards 0, so it enters the pole only; the reference
        gain is ``k / (k + c)``).
    rate : float, Hz, optional
        With a rate, the exact zero-order-hold discretization (``control.c2d``).

    Returns
    -------
    control.StateSpace
        The time constant of its step response is ``m / (k + c)``: the closed form a
        virtual-viscosity startup is compared with.
    """
    import control   # python-control: loaded only by the interop

    owner = "viscous_system"
    k = as_float(slope, "slope", owner, low=0.0, low_open=True)
    m = as_float(mass, "mass", owner, low=0.0, low_open=True)
    c = as_float(damping, "damping", owner, low=0.0)
    system = control.ss([[-(k + c) / m]], [[k / m]], [[1.0]], [[0.0]], inputs=["V_ref"], outputs=["V"],
                        name="viscous")
    if rate is None:
        return system
    return control.c2d(system, 1.0 / as_float(rate, "rate", owner, low=0.0, low_open=True), "zoh")
