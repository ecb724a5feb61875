"""Machinery shared by the reference (non-exact) integrators: budgets, segments, results.

Private. The scipy, Moreau-Jean and casadi methods all

- split ``[0, t_end]`` at the switching times of the commands and the external force, so
  that within a segment the commanded speeds and ``F_ext`` are constants (the integrators
  never step across a discontinuity of the right-hand side in time);
- count their work with a :class:`Meter` that raises :class:`BudgetExceeded` as soon as the
  wall-clock or step budget is spent, so a stalled method returns a status instead of hanging;
- keep their output in memory bounded by ``Budget.max_samples`` (a :class:`StepRecord` of
  their own steps, decimated when full, or only the requested ``t_eval`` times), never a list
  that grows with every step;
- assemble a :class:`~toolkit.simulation._result.SimulationResult` with :func:`build_result`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .._compiled import budget_clock
from ..errors import as_float, check_option
from ..model import FRICTION_LAWS, Plant
from ._result import Budget, SimulationResult, SimulationStatus, status_message

__all__ = ["BudgetExceeded", "Meter", "StepRecord", "segment_edges", "build_result",
           "check_smoothing", "format_setting", "samples_from_steps", "ideal_speeds", "net_forces"]

#: How often (in counted units) the wall clock is read; ``perf_counter`` costs ~50 ns.
_CLOCK_EVERY = 16
#: Rows of ``(samples, contacts)`` temporaries built at once by :func:`net_forces` (floats).
_CHUNK_VALUES = 2**20


class BudgetExceeded(Exception):
    """Raised inside an integrator to abort it when a budget is spent (never leaves a method)."""

    def __init__(self, status: SimulationStatus, detail: str) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail


class Meter:
    """Counts right-hand-side evaluations and steps against a :class:`Budget`.

    Parameters
    ----------
    budget : Budget
    counts : {"evaluations", "steps"}
        Which counter is held against ``budget.max_steps``.
    """

    def __init__(self, budget: Budget, counts: str = "evaluations") -> None:
        self.budget = budget
        self.counts = counts
        self.start = budget_clock()
        self.evaluations = 0
        self.steps = 0

    def elapsed(self) -> float:
        """Wall time since the meter was created, s."""
        return budget_clock() - self.start

    def _check(self, count: int) -> None:
        if count > self.budget.max_steps:
            raise BudgetExceeded(SimulationStatus.MAX_STEPS,
                                 f"{count - 1} {self.counts} used of max_steps = {self.budget.max_steps}")
        if count % _CLOCK_EVERY == 0 and self.elapsed() > self.budget.wall_time:
            raise BudgetExceeded(SimulationStatus.WALL_TIME,
                                 f"{self.elapsed():.3g} s used of wall_time = {self.budget.wall_time:g} s")

    def evaluation(self, n: int = 1) -> None:
        """Count ``n`` right-hand-side evaluations; raise :class:`BudgetExceeded` when over budget."""
        self.evaluations += n
        if self.counts == "evaluations":
            self._check(self.evaluations)
        elif self.evaluations % _CLOCK_EVERY == 0:
            self.check_clock()

    def step(self, n: int = 1) -> None:
        """Count ``n`` accepted steps; raise :class:`BudgetExceeded` when over budget."""
        self.steps += n
        if self.counts == "steps":
            self._check(self.steps)

    def check_clock(self) -> None:
        """Raise :class:`BudgetExceeded` if the wall-clock budget is spent."""
        if self.elapsed() > self.budget.wall_time:
            raise BudgetExceeded(SimulationStatus.WALL_TIME,
                                 f"{self.elapsed():.3g} s used of wall_time = {self.budget.wall_time:g} s")


class StepRecord:
    """The steps a stepping method keeps when it reports its own steps, in bounded memory.

    Every step is kept until ``capacity`` samples are stored; then every other stored sample
    is dropped and from then on only every 2nd step is kept; when full again every 4th, and
    so on. The first sample (the initial state) is always kept, and :meth:`arrays` appends
    the latest step if it was not kept, so a record holds at most ``capacity + 1`` samples
    whatever the number of steps, and the kept steps are uniform in step count.

    Parameters
    ----------
    t0 : float, s
        Initial time.
    y0 : array_like of shape (d,)
        Initial state.
    capacity : int
        ``Budget.max_samples`` (``>= 2``; rounded down to an even number so that the kept
        steps stay those whose index is a multiple of the stride).
    """

    def __init__(self, t0: float, y0: Any, capacity: int) -> None:
        row = np.asarray(y0, dtype=float).ravel()
        self.capacity = max(2, capacity - capacity % 2)
        size = min(self.capacity, 1024)
        self._t = np.empty(size)
        self._y = np.empty((size, row.size))
        self._t[0], self._y[0] = t0, row
        self.size = 1                     # samples stored
        self.stride = 1                   # keep the steps whose index is a multiple of this
        self.count = 0                    # steps seen
        self._last: tuple[float, Any] | None = None

    def add(self, t: float, y: Any) -> None:
        """Record step ``count + 1`` ending at time ``t`` with state ``y`` (not modified later
        by the caller: the latest step is held by reference until the next one)."""
        self.count += 1
        if self.count % self.stride:
            self._last = (t, y)
            return
        self._last = None
        if self.size == self._t.size:
            if self.size < self.capacity:             # grow, up to the capacity
                size = min(self.capacity, 2 * self.size)
                self._t = np.concatenate((self._t, np.empty(size - self.size)))
                self._y = np.concatenate((self._y, np.empty((size - self.size, self._y.shape[1]))))
            else:                                     # full: keep every other sample
                keep = (self.size + 1) // 2
                self._t[:keep] = self._t[:self.size:2]
                self._y[:keep] = self._y[:self.size:2]
                self.size, self.stride = keep, 2 * self.stride
                if self.count % self.stride:          # (cannot happen: capacity is even)
                    self._last = (t, y)
                    return
        self._t[self.size] = t
        self._y[self.size] = y
        self.size += 1

    @property
    def decimated(self) -> bool:
        """True when steps were dropped (the record keeps every ``stride``-th step)."""
        return self.stride > 1

    def note(self) -> str:
        """A sentence for the result's message when the record was decimated, else ``""``."""
        if not self.decimated:
            return ""
        return (f"record decimated to every {self.stride}th of {self.count} steps "
                f"(max_samples = {self.capacity})")

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """``(t, y)``: the kept samples and the latest step, shapes (S,) and (S, d), fresh."""
        t, y = self._t[:self.size], self._y[:self.size]
        if self._last is not None:
            t = np.append(t, self._last[0])
            y = np.vstack((y, np.asarray(self._last[1], dtype=float).reshape(1, -1)))
        return t.copy(), y.copy()


def segment_edges(plant: Plant, t_end: float) -> np.ndarray:
    """``[0, t_1, ..., t_end]``: the switching times of the plant strictly inside ``(0, t_end)``.

    Returns
    -------
    ndarray of shape (k + 2,), s
        Within ``[edges[j], edges[j+1])`` the commands and ``F_ext`` are constant.
    """
    switches = plant.switching_times()
    inside = switches[(switches > 0.0) & (switches < t_end)]
    return np.concatenate(([0.0], inside, [t_end]))


def check_smoothing(friction: str, epsilon: Any, owner: str,
                    choices: tuple[str, ...] = FRICTION_LAWS) -> float:
    """Validate the friction law and its smoothing width; return ``epsilon`` as a float (m/s)."""
    check_option(friction, "friction", owner, choices)
    return as_float(epsilon, "epsilon", owner, low=0.0, low_open=True)


def format_setting(**parts: Any) -> str:
    """``"tanh eps=1e-06 rtol=1e-08"``: a compact human description of a method's setting."""
    words = []
    for name, value in parts.items():
        if value is None:
            continue
        if name in ("friction", "integrator"):
            words.append(str(value))
        else:
            words.append(f"{name}={value:.3g}" if isinstance(value, float) else f"{name}={value}")
    return " ".join(words)


def samples_from_steps(step_t: np.ndarray, step_y: np.ndarray,
                       t_eval: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Report the states of a stepping method at ``t_eval`` (linear interpolation) or its steps.

    Parameters
    ----------
    step_t : ndarray of shape (S,), s
        Step times, non-decreasing.
    step_y : ndarray of shape (S, d)
        States at the step times.
    t_eval : ndarray of shape (T,) or None
        Requested times; those beyond the last step (a run stopped by a budget) are dropped.

    Returns
    -------
    t : ndarray of shape (T',), s
    y : ndarray of shape (T', d)
    """
    if t_eval is None:
        return step_t, step_y
    keep = t_eval[t_eval <= step_t[-1]]
    columns = [np.interp(keep, step_t, step_y[:, j]) for j in range(step_y.shape[1])]
    return keep, np.stack(columns, axis=1) if columns else np.empty((keep.size, 0))


def ideal_speeds(plant: Plant, t: np.ndarray) -> np.ndarray:
    """Contact speeds of ideal motors (the clipped commands) at times ``t``, shape (T, n), m/s.

    Constant commands give a read-only zero-stride view of one row (no ``T x n`` copy).
    """
    if plant.commands is None:
        return np.broadcast_to(plant.command(0.0), (t.size, plant.n))
    limits = plant.motors.speed_limits if plant.motors is not None else (-np.inf, np.inf)
    return np.clip(plant.commands(t).reshape(t.size, plant.n), *limits)


def external_forces(plant: Plant, t: np.ndarray) -> np.ndarray:
    """External force at times ``t`` (s), shape (T,), N."""
    ext = plant.external_force
    return ext(t) if callable(ext) else np.full(t.size, float(ext))


def net_forces(plant: Plant, t: np.ndarray, V: np.ndarray, speeds: np.ndarray, *,
               friction: str = "sign", epsilon: float = 0.0) -> np.ndarray:
    """Net force of a friction law at many samples at once, N, shape (T,).

    The vectorized counterpart of :meth:`Plant.net_force`: ``Plant.contact_forces`` applied
    to a column of body speeds against rows of contact speeds, in chunks of rows so that the
    ``(samples, contacts)`` temporary stays below ``2**20`` values.
    """
    if t.size == 0:
        return np.empty(0)
    eps = epsilon if friction != "sign" else 0.0
    chunk = max(1, _CHUNK_VALUES // max(1, plant.n))
    friction_force = np.empty(t.size)
    for lo in range(0, t.size, chunk):
        contact = plant.contact_forces(V[lo:lo + chunk, None], speeds[lo:lo + chunk],
                                       friction=friction, epsilon=eps)
        friction_force[lo:lo + chunk] = np.sum(contact, axis=1)
    return friction_force + external_forces(plant, t) - plant.damping * V


def build_result(plant: Plant, *, method: str, setting: str, t: np.ndarray, V: np.ndarray,
                 contact_speeds: np.ndarray | None, force: np.ndarray | None,
                 meter: Meter, status: SimulationStatus, detail: str = "", friction: str = "sign",
                 epsilon: float = 0.0,
                 dense: Callable[[np.ndarray], np.ndarray] | None = None) -> SimulationResult:
    """Assemble the result of a reference method.

    ``contact_speeds=None`` means ideal motors: the clipped commands at ``t``.
    ``force=None`` means: the net force of the method's own friction law at each sample.
    """
    t = np.asarray(t, dtype=float)
    V = np.asarray(V, dtype=float)
    if contact_speeds is None:
        contact_speeds = ideal_speeds(plant, t)
    if force is None:
        force = net_forces(plant, t, V, contact_speeds, friction=friction, epsilon=epsilon)
    finite = bool(np.all(np.isfinite(V)))
    if status is SimulationStatus.SUCCESS and not finite:
        status, detail = SimulationStatus.FAILED, "the state became non-finite"
    return SimulationResult(
        method=method, setting=setting, t=t, V=V,
        contact_speeds=np.asarray(contact_speeds, dtype=float).reshape(t.size, plant.n),
        force=np.asarray(force, dtype=float).reshape(t.size), events=(), status=status,
        message=status_message(status, detail), n_events=0, n_evaluations=meter.evaluations,
        n_steps=meter.steps, wall_time=meter.elapsed(), dense=dense)
