"""Reference method: Moreau-Jean time stepping (implicit Euler with the set-valued force).

``simulate(plant, t_end, method="moreau", step=1e-3)``. Each step solves ``m (W - V) / h in
F(W) + F_ext - c W`` exactly on the staircase (:func:`toolkit.laws.implicit_step`), or
by a search over the kinks of compliant contacts; dynamic motors are advanced first by the
motor law's implicit step; drive backlash adds a play per contact whose engaged drives enter
the staircase as half steps. Steps land on every switch; only the requested samples are kept.
The method, its order and the backlash model: docs/physics.md, section 11.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from ..errors import as_float
from ..errors import ParameterError, parameter_message
from ..model import Plant
from ..model import implicit_step as motor_implicit_step
from ..laws import implicit_step, tie_tolerance
from ._reference import BudgetExceeded, Meter, StepRecord, build_result, format_setting, segment_edges
from ._result import Budget, SimulationResult, SimulationStatus

__all__ = ["simulate_moreau", "moreau_step_staircase"]


#: One Moreau-Jean step on a Coulomb staircase: ``(W, stuck)`` from ``(levels, plateaus, a, b)``
#: (the model's law, :func:`toolkit.laws.implicit_step`).
moreau_step_staircase = implicit_step


def _staircase(speeds: np.ndarray, forces_sorted_by: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Levels and plateau forces of contacts at ``speeds`` (the :meth:`ContactSet.staircase`
    of moving contacts, rebuilt every step without the constructor's validation).

    Plateau forces below ``4 (K + 1) eps F_tot`` are snapped to 0 as in
    :attr:`ContactSet.tie_tolerance`, so an exactly balanced band stays force-free.
    """
    active = forces_sorted_by > 0
    order = np.argsort(speeds[active], kind="stable")
    s, w = speeds[active][order], forces_sorted_by[active][order]
    starts = np.concatenate(([0], np.flatnonzero(np.diff(s) > 0) + 1))
    levels, steps = s[starts], np.add.reduceat(w, starts)
    below = np.concatenate(([0.0], np.cumsum(steps)))
    total = below[-1]
    plateaus = total - 2.0 * below
    tolerance = tie_tolerance(levels.size, total)
    plateaus[np.abs(plateaus) <= tolerance] = 0.0
    return levels, plateaus


def _compliant_step(plant: Plant, speeds: np.ndarray, a: float, b: float,
                    meter: Meter) -> float:
    """Solve ``a W - b = F(W)`` for the continuous piecewise-linear compliant force law.

    ``g(W) = a W - b - F(W)`` is strictly increasing and linear between the kinks
    ``v_i +- k f_i``: evaluate it at the kinks (all at once for up to 64 contacts, by binary
    search beyond), then solve the linear piece that holds the zero.
    """
    f = plant.contacts.forces
    k = plant.compliance
    kinks = np.sort(np.concatenate((speeds - k * f, speeds + k * f)))
    total = plant.contacts.total_force

    def g(W: np.ndarray) -> np.ndarray:
        meter.evaluation(int(np.size(W)))
        return a * W - b - np.sum(plant.contact_forces(W[..., None], speeds), axis=-1)

    if kinks.size <= 128:
        values = g(kinks)
        j = int(np.searchsorted(values, 0.0))
        if j == 0:                                   # F = +F_tot below every kink
            return (b + total) / a
        if j == kinks.size:                          # F = -F_tot above every kink
            return (b - total) / a
        lo, hi, g_lo, g_hi = j - 1, j, values[j - 1], values[j]
    else:
        ends = g(kinks[[0, -1]])
        if ends[0] >= 0.0:
            return (b + total) / a
        if ends[1] <= 0.0:
            return (b - total) / a
        lo, hi, g_lo, g_hi = 0, kinks.size - 1, ends[0], ends[1]
        while hi - lo > 1:
            mid = (lo + hi) // 2
            g_mid = float(g(kinks[mid:mid + 1])[0])
            if g_mid < 0.0:
                lo, g_lo = mid, g_mid
            else:
                hi, g_hi = mid, g_mid
    if g_hi == 0.0:
        return float(kinks[hi])
    # g is linear on [kinks[lo], kinks[hi]]
    return float(kinks[lo] - g_lo * (kinks[hi] - kinks[lo]) / (g_hi - g_lo))


def simulate_moreau(plant: Plant, t_end: float, *, v0: float, t_eval: np.ndarray | None,
                    budget: Budget, step: float = 1e-3) -> SimulationResult:
    """Moreau-Jean time stepping with the set-valued Coulomb force resolved exactly.

    Parameters
    ----------
    plant, t_end, v0, budget
        As in :func:`toolkit.simulation.simulate` (checked there); ``budget.max_steps``
        counts steps.
    t_eval : ndarray of shape (T,) or None, s
        Report times (linear interpolation between the two steps around each time, the net
        force of the step that ends at or after it), sampled while stepping: nothing else is
        stored. ``None``: every step, up to ``budget.max_samples``; beyond that a decimated
        record (:class:`~toolkit.simulation._reference.StepRecord`), said in the message.
    step : float, s
        Step length ``h > 0`` (shortened to land on switches and ``t_end``).

    Returns
    -------
    SimulationResult
        ``force`` is ``m (W - V) / h`` of each step (the net force actually applied, the
        stiction force included); no events are reported. Memory does not grow with the
        number of steps: a run over ``1e12`` steps is stopped by its budget with the steps
        so far.
    """
    h = as_float(step, "step", "simulate_moreau", low=0.0, low_open=True)
    meter = Meter(budget, counts="steps")
    dynamic = plant.dynamic_motors
    speeds = plant.initial_speeds()
    play = None
    if plant.backlash > 0:
        if plant.compliance > 0:
            raise ParameterError(parameter_message(
                "plant", "simulate(method='moreau')", "have motors.compliance = 0 when "
                "motors.backlash > 0 (backlash is modelled with stiff motors only)",
                f"compliance = {plant.compliance:g} (m/s)/N, backlash = {plant.backlash:g} m"))
        play = initial_play(0.5 * plant.backlash, speeds, v0)
    out = _Output(t_eval, v0, plant.net_force(0.0, v0, speeds), speeds if dynamic else None,
                  budget.max_samples)
    status, detail = SimulationStatus.SUCCESS, ""
    edges = segment_edges(plant, t_end)
    try:
        with np.errstate(over="ignore", invalid="ignore"):   # non-finite W: caught per step
            _segments(plant, edges, h, v0, speeds, meter, out, play)
    except BudgetExceeded as stop:
        status, detail = stop.status, stop.detail
    t_out, V_out, force_out, speeds_out = out.arrays()
    note = out.note()
    detail = "; ".join(part for part in (detail, note) if part)
    return build_result(
        plant, method="moreau", setting=format_setting(h=h), t=t_out, V=V_out,
        contact_speeds=speeds_out, force=force_out, meter=meter, status=status, detail=detail)


class _Output:
    """What a Moreau run keeps: the requested times, sampled as the steps pass them, or its
    steps in a :class:`StepRecord` (memory bounded by ``max_samples`` either way)."""

    def __init__(self, t_eval: np.ndarray | None, v0: float, force0: float,
                 speeds0: np.ndarray | None, max_samples: int) -> None:
        self.t_eval = t_eval
        self.dynamic = speeds0 is not None
        row = [v0, force0] + ([] if speeds0 is None else speeds0.tolist())
        if t_eval is None:
            self.record: StepRecord | None = StepRecord(0.0, row, max_samples)
            self.next_t = math.inf
            return
        self.record = None
        T = t_eval.size
        self.times = t_eval.tolist()
        self.V = np.empty(T)
        self.force = np.empty(T)
        self.speeds = np.empty((T, speeds0.size)) if speeds0 is not None else None
        k = 0
        while k < T and self.times[k] <= 0.0:     # requests at t = 0: the initial state
            self.V[k], self.force[k] = v0, force0
            if self.speeds is not None:
                self.speeds[k] = speeds0
            k += 1
        self.k = k
        self.next_t = self.times[k] if k < T else math.inf

    def add(self, t0: float, V: float, t1: float, W: float, force: float,
            speeds0: np.ndarray | None = None, speeds1: np.ndarray | None = None) -> None:
        """One step from ``(t0, V)`` to ``(t1, W)`` with net force ``force`` (and contact
        speeds ``speeds0`` -> ``speeds1`` with dynamic motors)."""
        record = self.record
        if record is not None:
            if speeds1 is None:
                record.add(t1, (W, force))
            else:
                record.add(t1, [W, force, *speeds1.tolist()])
            return
        if self.next_t > t1:
            return
        times, k, T = self.times, self.k, len(self.times)
        slope = (W - V) / (t1 - t0)
        while k < T and times[k] <= t1:           # np.interp's formula; W itself at t1
            x = times[k]
            self.V[k] = W if x == t1 else V + slope * (x - t0)
            self.force[k] = force
            if speeds1 is not None:
                self.speeds[k] = speeds1 if x == t1 else (
                    speeds0 + (speeds1 - speeds0) / (t1 - t0) * (x - t0))
            k += 1
        self.k = k
        self.next_t = times[k] if k < T else math.inf

    def note(self) -> str:
        return "" if self.record is None else self.record.note()

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """``(t, V, force, contact speeds or None)`` of what was reached."""
        if self.record is not None:
            t, y = self.record.arrays()
            return t, y[:, 0], y[:, 1], (y[:, 2:] if self.dynamic else None)
        k = self.k
        speeds = None if self.speeds is None else self.speeds[:k]
        return self.t_eval[:k], self.V[:k], self.force[:k], speeds


def _segments(plant: Plant, edges: np.ndarray, h: float, V: float, speeds: np.ndarray,
              meter: Meter, out: _Output, play: np.ndarray | None = None) -> None:
    """Step over every segment between switches, handing each step to ``out``.

    ``play``: the drives' play ``g_i`` (m) with backlash, ``None`` without.

    The steps of a segment are generated one at a time (nominal ``h``, the last one
    shortened to land on the segment's end), never listed: their number may be huge.
    """
    dynamic = plant.dynamic_motors
    for t0, t1 in zip(edges[:-1], edges[1:]):
        t0, t1 = float(t0), float(t1)
        count = max(1, math.ceil((t1 - t0) / h * (1.0 - 1e-12)))
        if play is not None:
            V, speeds, play = _backlash_segment(plant, t0, t1, h, count, V, speeds, play,
                                                0.5 * plant.backlash, meter, out)
        elif dynamic or plant.compliance > 0:
            V, speeds = _general_segment(plant, t0, t1, h, count, V, speeds, meter, out)
        else:
            V = _staircase_segment(plant, t0, t1, h, count, V, meter, out)


def _finite_step(t: float, W: float, force: float) -> float:
    """``force``, after checking that the step's speed and force are finite (else FAILED)."""
    if not (math.isfinite(W) and math.isfinite(force)):
        raise BudgetExceeded(SimulationStatus.FAILED, f"the state became non-finite at t = {t:.6g} s "
                             f"(V = {W:.3g} m/s, force = {force:.3g} N)")
    return force


def _staircase_segment(plant: Plant, t0: float, t1: float, h: float, count: int, V: float,
                       meter: Meter, out: _Output) -> float:
    """Steps over a segment with constant contact speeds: one staircase, binary searches."""
    cs = plant.contacts.with_speeds(plant.command(t0))
    stair = cs.staircase()
    levels, plateaus = stair.levels, stair.plateaus
    ext, m, c = plant.external(t0), plant.mass, plant.damping
    cache: dict[float, tuple[float, list[float]]] = {}
    t_prev = t0
    last = t1 - (t0 + (count - 1) * h)
    for j in range(1, count + 1):
        t_next, hj = (t0 + j * h, h) if j < count else (t1, last)
        if hj not in cache:
            a = m / hj + c
            cache[hj] = (a, (a * levels - plateaus[1:]).tolist())
        a, upper = cache[hj]
        b = m * V / hj + ext
        W, _ = implicit_step(levels, plateaus, a, b, bisect.bisect_left(upper, b))
        meter.evaluations += 1
        meter.step()
        out.add(t_prev, V, t_next, W, _finite_step(t_next, W, m * (W - V) / hj))
        t_prev, V = t_next, W
    return V


def _motor_steps(plant: Plant, t0: float, t1: float, h: float, count: int, speeds: np.ndarray):
    """The ``count`` steps of a segment with its command held: yields ``(t_next, h_j,
    speeds before, speeds after)``, the contact speeds advanced by the motor law's implicit
    step (dynamic motors) or set to the command (ideal motors); the last step ends at ``t1``."""
    command = plant.command(t0)
    last = t1 - (t0 + (count - 1) * h)
    dynamic = plant.dynamic_motors
    for j in range(1, count + 1):
        t_next, hj = (t0 + j * h, h) if j < count else (t1, last)
        before = speeds
        speeds = motor_implicit_step(plant.motors, speeds, command, hj) if dynamic else command
        yield t_next, hj, before, speeds


def _general_segment(plant: Plant, t0: float, t1: float, h: float, count: int, V: float,
                     speeds: np.ndarray, meter: Meter, out: _Output) -> tuple[float, np.ndarray]:
    """Steps with dynamic motors and/or compliance: staircase or kinks rebuilt every step."""
    ext, m, c = plant.external(t0), plant.mass, plant.damping
    t_prev = t0
    dynamic = plant.dynamic_motors
    for t_next, hj, before, speeds in _motor_steps(plant, t0, t1, h, count, speeds):
        a, b = m / hj + c, m * V / hj + ext
        if plant.compliance > 0:
            W = _compliant_step(plant, speeds, a, b, meter)
        else:
            levels, plateaus = _staircase(speeds, forces_sorted_by=plant.contacts.forces)
            W, _ = moreau_step_staircase(levels, plateaus, a, b)
            meter.evaluation()
        meter.step()
        force = _finite_step(t_next, W, m * (W - V) / hj)
        if dynamic:
            out.add(t_prev, V, t_next, W, force, before, speeds)
        else:
            out.add(t_prev, V, t_next, W, force)
        t_prev, V = t_next, W
    return V, speeds


def initial_play(half: float, speeds: np.ndarray, v0: float) -> np.ndarray:
    """The drives' play at ``t = 0``, m: each at the edge that pushes towards its contact.

    ``g_i = -half sign(v_i - v0)``; for a contact riding with the body (``v_i = v0``)
    ``-half sign(v_i)``; ``0`` (mid-play) for a contact at rest under a body at rest.

    Parameters
    ----------
    half : float, m
        Half the backlash, ``b / 2``.
    speeds : ndarray of shape (n,), m/s
        Contact (motor) speeds at ``t = 0``.
    v0 : float, m/s
        Body speed at ``t = 0``.
    """
    push = np.sign(speeds - v0)
    push = np.where(push == 0.0, np.sign(speeds), push)
    return -half * push


def play_staircase(speeds: np.ndarray, forces: np.ndarray, play: np.ndarray,
                   half: float) -> tuple[np.ndarray, np.ndarray]:
    """Levels and plateau forces of the engaged drives (a contact in its play is left out).

    A drive at ``g_i = -half`` contributes ``f_i`` below its level and ``0`` above; at
    ``g_i = +half`` ``0`` below and ``-f_i`` above; with ``half = 0`` both (the Coulomb
    contact of :func:`_staircase`). Plateau forces below ``4 (K + 1) eps F`` (``F`` the
    engaged contacts' total) are snapped to 0, as in :func:`_staircase`.

    Parameters
    ----------
    speeds : ndarray of shape (n,), m/s
        Motor speeds.
    forces : ndarray of shape (n,), N
    play : ndarray of shape (n,), m
        ``g_i`` in ``[-half, half]``.
    half : float, m

    Returns
    -------
    levels : ndarray of shape (K,), m/s
    plateaus : ndarray of shape (K + 1,), N
        Non-increasing; ``[0.0]`` with no engaged drive.
    """
    lower, upper = play == -half, play == half
    engaged = (lower | upper) & (forces > 0)
    order = np.argsort(speeds[engaged], kind="stable")
    s = speeds[engaged][order]
    below = np.where(lower, forces, 0.0)[engaged][order]     # force below the level, N
    above = np.where(upper, -forces, 0.0)[engaged][order]    # force above the level, N
    if s.size == 0:
        return s, np.zeros(1)
    starts = np.concatenate(([0], np.flatnonzero(np.diff(s) > 0) + 1))
    levels, drops = s[starts], np.add.reduceat(below - above, starts)
    first = float(np.sum(below))
    plateaus = first - np.concatenate(([0.0], np.cumsum(drops)))
    tolerance = tie_tolerance(levels.size, float(np.sum(forces[engaged])))
    plateaus[np.abs(plateaus) <= tolerance] = 0.0
    return levels, plateaus


def _backlash_segment(plant: Plant, t0: float, t1: float, h: float, count: int, V: float,
                      speeds: np.ndarray, play: np.ndarray, half: float, meter: Meter,
                      out: _Output) -> tuple[float, np.ndarray, np.ndarray]:
    """Steps with drive backlash: the engaged drives' staircase rebuilt every step, then
    every play advanced with its wheel rolling at the body's new speed."""
    ext, m, c = plant.external(t0), plant.mass, plant.damping
    forces = plant.contacts.forces
    t_prev = t0
    dynamic = plant.dynamic_motors
    for t_next, hj, before, speeds in _motor_steps(plant, t0, t1, h, count, speeds):
        a, b = m / hj + c, m * V / hj + ext
        levels, plateaus = play_staircase(speeds, forces, play, half)
        W, _ = moreau_step_staircase(levels, plateaus, a, b)
        meter.evaluation()
        meter.step()
        force = _finite_step(t_next, W, m * (W - V) / hj)
        play = np.clip(play + hj * (W - speeds), -half, half)
        if dynamic:
            out.add(t_prev, V, t_next, W, force, before, speeds)
        else:
            out.add(t_prev, V, t_next, W, force)
        t_prev, V = t_next, W
    return V, speeds, play
