"""Sampled loops of the exact plant, run by the compiled kernels: :class:`SampledRun`, :func:`sampled_batch`.

A sampled-data loop reads the sensors at ``t_k``, estimates the speed, evaluates a law and
holds its commands and outside force until ``t_{k+1}`` while the plant follows the exact
engine. :class:`SampledRun` runs such a loop in the kernel ``sampled_steps`` (the plant step,
the displacements, the noiseless sensor law and, with :class:`SampledLaw`, the law); what the
kernels cannot run (an estimator, a law without compiled form) the caller gives per sample.
:func:`sampled_batch` runs many loops of one plant in parallel. Details: docs/physics.md, section 11.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._compiled import core as _core
from .._compiled import parallel
from ..errors import as_float, as_float_array
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..model import Plant
from ._exact import _dynamic_plant, _kernels, _STEP_CAP, _ZENO_FLOOR
from ._result import Budget, SimulationStatus
from ._stepper import ExactState, advance

__all__ = ["SampledLaw", "SampledRun", "sampled_batch", "sampled_supported"]

_DEFAULT_BUDGET = Budget()
#: Per-step wall-clock budgets below this (s) take the Python loop: the kernel runs many steps
#: between two looks at the clock.
_MIN_WALL_TIME = 1.0
#: Interpreted work (about us) of one sample of the kernel, and per contact.
_SAMPLE_WORK, _CONTACT_WORK = 150, 25


@dataclass(frozen=True, eq=False)
class SampledLaw:
    """A control law in the form the compiled loop evaluates (the controllers' own arithmetic).

    Commands are a piecewise-constant table: row ``rows[j]`` (m/s) and outside force
    ``forces[j]`` (N) on ``[times[j-1], times[j])`` of the law's clock (``times`` (K,) s,
    ascending; K = 0: one constant row). Optionally:

    - ``pi = (reference, kp, ki)``: the rows are shifted by
      ``reference + kp e + ki z`` with ``e = reference - estimate`` (m/s) and clipped to
      ``limits`` (m/s); the state ``z`` (m) integrates ``e`` over each ``period`` (s);
    - ``carry``: before ``switch`` (s) every contact is commanded ``carry`` (m/s, shape (n,),
      no force, ``z`` held); after, the law runs with its clock ``t - start`` (snapped to the
      sample grid within ``1e-9`` periods).

    Parameters
    ----------
    rows : array_like of shape (K + 1, n), m/s
    times : array_like of shape (K,), s
    forces : array_like of shape (K + 1,), N, optional
    pi : tuple of 3 floats, optional
    limits : tuple of 2 floats, m/s
    period : float, s
    carry : array_like of shape (n,), m/s, optional
    switch, start : float, s
    """

    rows: np.ndarray
    times: np.ndarray = dataclasses.field(default_factory=lambda: np.empty(0))
    forces: np.ndarray | None = None
    pi: tuple[float, float, float] | None = None
    limits: tuple[float, float] = (-math.inf, math.inf)
    period: float = 0.0
    carry: np.ndarray | None = None
    switch: float = 0.0
    start: float = 0.0

    def __post_init__(self) -> None:
        owner = "SampledLaw"
        rows = as_float_array(self.rows, "rows", owner, ndim=2)
        times = np.asarray(self.times, dtype=float).reshape(-1)
        if rows.shape[0] != times.size + 1 or (times.size and np.any(np.diff(times) < 0)):
            raise ParameterError(parameter_message(
                "rows", owner, "have one row more than the ascending switching times",
                f"{rows.shape[0]} rows for {times.size} times"))
        forces = (np.zeros(rows.shape[0]) if self.forces is None
                  else as_float_array(self.forces, "forces", owner).reshape(-1))
        if forces.size != rows.shape[0]:
            raise ParameterError(parameter_message(
                "forces", owner, f"have one force per row ({rows.shape[0]})", forces.size))
        carry = None
        if self.carry is not None:
            carry = as_float_array(self.carry, "carry", owner).reshape(-1)
            if carry.size != rows.shape[1]:
                raise ParameterError(parameter_message(
                    "carry", owner, f"hold one speed per contact ({rows.shape[1]})", carry.size))
        if (self.pi is not None or carry is not None) and not self.period > 0:
            raise ParameterError(parameter_message(
                "period", owner, "be > 0 with a PI shift or a carry phase", self.period))
        for name, value in (("rows", rows), ("times", times), ("forces", forces), ("carry", carry)):
            if value is not None:
                value = np.ascontiguousarray(value)
                value.setflags(write=False)
                object.__setattr__(self, name, value)

    @property
    def n(self) -> int:
        """Contacts commanded."""
        return int(self.rows.shape[1])

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The kernel's ``law_i`` (``L_CARRY``, ``L_SHIFT``), ``law_f`` (``L_SWITCH`` ..
        ``L_HIGH``) and the carry row (zeros without a carry phase)."""
        law_i = np.array([self.carry is not None, self.pi is not None], dtype=np.int64)
        reference, kp, ki = self.pi if self.pi is not None else (0.0, 0.0, 0.0)
        law_f = np.array([self.switch, self.start, reference, kp, ki, self.period,
                          self.limits[0], self.limits[1]], dtype=float)
        carry = self.carry if self.carry is not None else np.zeros(self.n)
        for array in (law_i, law_f, carry):       # read-only like the table: one kernel type
            array.setflags(write=False)
        return law_i, law_f, carry


def sampled_supported(plant: Plant, sensors: Any = None, budget: Budget | None = None) -> bool:
    """Whether :class:`SampledRun` runs this loop: any plant ``advance`` steps except ideal
    motors with compliance; noiseless sensors without jitter (or none); a per-step wall-clock
    budget of at least 1 s (the kernel looks at the clock between runs of many steps)."""
    budget = _DEFAULT_BUDGET if budget is None else budget
    if plant.backlash > 0 or (not plant.dynamic_motors and plant.compliance > 0):
        return False
    if budget.wall_time < _MIN_WALL_TIME:
        return False
    return sensors is None or (sensors.missed_count_prob == 0 and sensors.count_noise == 0
                               and sensors.jitter == 0)


class _Plant:
    """The kernel's view of a plant (shared by :class:`SampledRun` and :func:`sampled_batch`)."""

    def __init__(self, plant: Plant, budget: Budget, quiet: bool) -> None:
        self.dynamic = plant.dynamic_motors
        if self.dynamic:
            dyn = _dynamic_plant(plant)
            self.forces, self.params = dyn.forces, dyn.params
            self.try_quiet = quiet and dyn.quiet and budget.wall_time >= 1e-3
        else:
            self.forces = np.ascontiguousarray(plant.contacts.forces, dtype=float)
            params = np.zeros(_core.N_PARAMS)
            params[_core.P_TOTAL] = float(plant.contacts.total_force)
            params[_core.P_MASS], params[_core.P_DAMPING] = plant.mass, plant.damping
            params.setflags(write=False)              # (as the dynamic plant's: one kernel type)
            self.params, self.try_quiet = params, False
        limits = plant.motors.speed_limits if plant.motors is not None else (-math.inf, math.inf)
        self.low, self.high = float(limits[0]), float(limits[1])
        n = plant.n
        self.budget_i = np.array([min(budget.max_steps, _STEP_CAP, max(budget.max_samples // 2, 1)),
                                  2 * (2 * n + 2) + _ZENO_FLOOR], dtype=np.int64)
        self.rate = float(budget.max_event_rate)

    def args(self) -> tuple[Any, ...]:
        return (self.forces, self.params, self.dynamic, self.try_quiet, self.low, self.high,
                self.budget_i, self.rate)


_EMPTY_LAW = SampledLaw(np.zeros((1, 1)))


class SampledRun:
    """One sampled loop of ``plant`` at the sample ``times`` (s, ``k / rate``), in the kernel.

    Parameters
    ----------
    plant : Plant
        Motors start settled at ``plant.initial_speeds()``.
    times : ndarray of shape (S,), s
        Sample times from 0, ascending.
    v0 : float, m/s
    sensors : Sensors, optional
        Noiseless encoders (:func:`sampled_supported`), read at every sample into
        ``central`` and ``wheel``.
    law : SampledLaw, optional
        The law in the kernel; ``None``: the caller writes ``commands[k]`` and ``force[k]``.
    estimator : bool
        True: the caller writes ``estimate[k]`` and ``variance[k]``; False: the true speed.
    budget : Budget, optional
        The guards of each plant step (as ``advance``'s).

    Attributes
    ----------
    speed, position, estimate, variance, force : ndarray of shape (S,)
        m/s, m, m/s, (m/s)^2, N.
    commands, contact : ndarray of shape (S, n), m/s
    central : ndarray of shape (S,), int64; wheel : ndarray of shape (S, n), int64
    k : int
        The next sample to run.
    status : SimulationStatus; message : str; last : int
        How the run ended (``last``: the samples recorded).
    """

    def __init__(self, plant: Plant, times: np.ndarray, *, v0: float = 0.0, sensors: Any = None,
                 law: SampledLaw | None = None, estimator: bool = False,
                 budget: Budget | None = None) -> None:
        from . import _stepper

        if not isinstance(plant, Plant):
            raise ParameterTypeError(parameter_message("plant", "SampledRun", "be a Plant", plant))
        budget = _DEFAULT_BUDGET if budget is None else budget
        if not sampled_supported(plant, sensors, budget):
            raise ParameterError(parameter_message(
                "plant", "SampledRun", "be a loop the kernel runs (sampled_supported)", plant))
        if law is not None and law.n != plant.n:
            raise ParameterError(parameter_message(
                "law", "SampledRun", f"command {plant.n} contacts", law.n))
        self.plant, self.budget, self.law, self.sensors = plant, budget, law, sensors
        self.times = np.ascontiguousarray(times, dtype=float)
        S, n = self.times.size, plant.n
        self._plant = _Plant(plant, budget, _stepper._QUIET)
        self.speed, self.position = np.empty(S), np.empty(S)
        self.estimate, self.variance, self.force = np.zeros(S), np.zeros(S), np.zeros(S)
        self.commands, self.contact = np.zeros((S, n)), np.empty((S, n))
        self.central = np.zeros(S, dtype=np.int64)
        self.wheel = np.zeros((S, n), dtype=np.int64)
        self._est = _core.EST_GIVEN if estimator else _core.EST_TRUTH
        law = _EMPTY_LAW if law is None else law
        self._law_kind = _core.LAW_TABLE if self.law is not None else _core.LAW_GIVEN
        self._law = (*law.arrays(), law.times, law.rows, law.forces)
        self._z = np.zeros(1)
        self._state_f = np.zeros(4)
        self._state_f[_core.S_V] = v0 = float(v0)
        self._state_i = np.full(2, -1, dtype=np.int64)
        self._speeds = np.array(plant.initial_speeds(), dtype=float)
        self._x = np.zeros(n)
        self.speed[0], self.position[0], self.contact[0] = v0, 0.0, self._speeds
        if sensors is not None:
            state = sensors.initial_state(self._speeds)
            self._play = np.array(state.motor, dtype=float)
            self._sens = np.array([sensors.central.distance_per_count,
                                   sensors.wheel.distance_per_count, 0.5 * sensors.backlash])
            self.central[0] = _kernels().sensor_read(0.0, self._x, self._play, self._sens[2],
                                                     self._sens[0], self._sens[1], self.wheel[0])
        else:
            self._play, self._sens = np.zeros(n), np.ones(3)
        self.k = 0
        self.status, self.message, self.last = SimulationStatus.SUCCESS, "", S

    @property
    def z(self) -> np.ndarray:
        """The law's state (the PI integral, m), shape (1,)."""
        return self._z

    @property
    def done(self) -> bool:
        """True once every sample ran or a step failed."""
        return self.k >= self.last

    def run_to(self, k_stop: int) -> bool:
        """Run samples ``k .. k_stop - 1``; False when a plant step failed (then
        ``status``, ``message`` and ``last`` say how)."""
        k_stop = min(int(k_stop), self.last)
        if self.k >= k_stop:
            return self.status is SimulationStatus.SUCCESS
        code, reached = _kernels((k_stop - self.k) * (_SAMPLE_WORK + _CONTACT_WORK * self.plant.n)
                                 ).sampled_steps(
            self.k, k_stop, self.times, *self._plant.args(), self._est, self._law_kind,
            *self._law, self._z, self.sensors is not None, self._sens, self._play,
            self._state_f, self._state_i, self._speeds, self._x, self.speed, self.position,
            self.estimate, self.variance, self.commands, self.force, self.contact, self.central,
            self.wheel)
        self.k = int(reached)
        if code != _core.DONE:
            self._failed(self.k - 1)
            return False
        return True

    def _failed(self, k: int) -> None:
        """A step the kernel stopped: run it again through ``advance`` (the same engine and
        inputs) for its status and message."""
        stuck, hint = (int(v) for v in self._state_i)
        state = ExactState._trusted(float(self.times[k]), float(self._state_f[_core.S_V]),
                                    self._speeds.copy(), None if stuck < 0 else stuck,
                                    (None if hint < 0 else hint, float(self._state_f[_core.S_REL])))
        step = advance(self.plant, state, self.commands[k], float(self.times[k + 1]),
                       external=float(self.force[k]), budget=self.budget)
        status = step.status if step.status is not SimulationStatus.SUCCESS else SimulationStatus.FAILED
        self.status, self.message, self.last = status, step.message, k + 1


def sampled_batch(plant: Plant, laws: list[SampledLaw], samples: Any, rate: float, *,
                  v0: Any = 0.0, contact_speeds: Any = None,
                  budget: Budget | None = None) -> dict[str, np.ndarray]:
    """Many sampled loops of ``plant`` on the true speed, in parallel over the cores.

    Parameters
    ----------
    plant : Plant
        Shared by every run (contacts' magnitudes, mass, drag, motors).
    laws : list of SampledLaw
        One per run, each with the same number of switching times.
    samples : array_like of int, shape (R,)
        Samples of each run (its length ``(samples - 1) / rate``).
    rate : float, Hz
        Sample rate: the samples are at ``k / rate`` (:func:`toolkit.model.sample_times`).
    v0 : float or array_like of shape (R,), m/s
    contact_speeds : array_like of shape (R, n), m/s, optional
        Where each run's motors start, settled (default: ``plant.initial_speeds()``).
    budget : Budget, optional

    Returns
    -------
    dict
        ``times`` (S,), s; ``speed`` (R, S), m/s, NaN past each run's end;
        ``commands`` (R, S, n); ``force`` (R, S); ``contact`` (R, S, n); ``codes`` (R,)
        (0 done, else the kernel's stop code); ``reached`` (R,) samples recorded. Each run
        equals :class:`SampledRun` of that law (the same kernel).
    """
    from . import _stepper

    budget = _DEFAULT_BUDGET if budget is None else budget
    if not sampled_supported(plant, None, budget):
        raise ParameterError(parameter_message(
            "plant", "sampled_batch", "be a plant the kernel runs (sampled_supported)", plant))
    R = len(laws)
    counts = np.asarray(samples, dtype=np.int64).reshape(R)
    if R == 0 or counts.min() < 1:
        raise ParameterError(parameter_message("samples", "sampled_batch",
                                               "be at least 1 per run, with at least one run",
                                               counts.tolist()))
    rate = as_float(rate, "rate", "sampled_batch", low=0.0, low_open=True)
    K = {law.times.size for law in laws}
    if len(K) != 1 or any(law.n != plant.n for law in laws):
        raise ParameterError(parameter_message(
            "laws", "sampled_batch", f"share one number of switching times and command {plant.n} contacts",
            sorted(K)))
    S, n = int(counts.max()), plant.n
    times = np.arange(S) / rate
    kernel_plant = _Plant(plant, budget, _stepper._QUIET)
    packed = [law.arrays() for law in laws]
    law_i = np.array([p[0] for p in packed])
    law_f = np.array([p[1] for p in packed])
    carry = np.array([p[2] for p in packed])
    law_times = np.array([law.times for law in laws]).reshape(R, -1)
    law_rows = np.array([law.rows for law in laws])
    law_forces = np.array([law.forces for law in laws])
    if contact_speeds is None:
        start = np.tile(plant.initial_speeds(), (R, 1))
    else:
        start = np.array(as_float_array(contact_speeds, "contact_speeds", "sampled_batch", ndim=2))
        if start.shape != (R, n):
            raise ParameterError(parameter_message(
                "contact_speeds", "sampled_batch", f"have shape ({R}, {n})", start.shape))
    speeds0 = np.broadcast_to(np.asarray(v0, dtype=float), (R,)).copy()
    speed = np.full((R, S), np.nan)
    commands, force = np.zeros((R, S, n)), np.zeros((R, S))
    contact = np.full((R, S, n), np.nan)
    codes, reached = np.zeros(R, dtype=np.int64), np.zeros(R, dtype=np.int64)
    work = int(counts.sum()) * (_SAMPLE_WORK + _CONTACT_WORK * n)
    with parallel(work):                          # on the cores left idle
        _kernels(work).sampled_batch(
            counts, times, *kernel_plant.args(), law_i, law_f, carry, law_times, law_rows,
            law_forces, speeds0, start, speed, commands, force, contact, codes, reached)
    return {"times": times, "speed": speed, "commands": commands, "force": force,
            "contact": contact, "codes": codes, "reached": reached}
