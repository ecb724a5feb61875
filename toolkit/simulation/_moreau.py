"""Reference method: Moreau-Jean time stepping (implicit Euler with the set-valued force).

``simulate(plant, t_end, method="moreau", step=1e-3)``.

One step of length ``h`` from ``V`` solves the inclusion

    m (W - V) / h  in  F(W) + F_ext - c W,        F(W) = sum_i f_i Sign(v_i - W)

for the new speed ``W``, with the contact speeds ``v_i`` and ``F_ext`` of the step's end
(implicit Euler). Writing ``a = m / h + c`` and ``b = m V / h + F_ext``, ``W`` is the zero of
``g(W) = a W - b - F(W)``: since ``F`` is non-increasing (maximal monotone), ``g`` is strictly
increasing, so the zero exists, is unique and is found exactly on the staircase of
:meth:`toolkit.model.ContactSet.staircase` (levels ``s_k``, plateau forces ``P_k`` below
``s_k`` and ``P_{k+1}`` above):

- at a level, ``g(s_k) = [a s_k - b - P_k, a s_k - b - P_{k+1}]``; both ends increase with
  ``k``, so a binary search finds the first level whose upper end is ``>= 0``;
- if its lower end is ``<= 0`` the zero is the level itself: the body **sticks** at ``s_k``
  (the contacts there supply the stiction force that balances the rest);
- otherwise the zero lies on the open plateau before it: ``W = (b + P_k) / a``.

So a body at an equilibrium stays there exactly (no chattering) and inside a zero-force band
with ``c = 0`` it keeps its speed exactly (no creep). The method is first-order accurate: the
error of the stick and crossing times is ``O(h)``; with drag, the exponential is approximated
by ``(1 + c h / m)^(-k)``.

Motor compliance makes ``F`` continuous and piecewise linear (kinks at ``v_i +- k f_i``); the
zero of ``g`` is then found by binary search over the kinks and a linear solve between them.
Dynamic motors are advanced first, by the model's implicit Euler step of the motor law
(:func:`toolkit.model.motors.implicit_step`, solved exactly: a monotone scalar equation per
contact); their speeds then enter the body's step.

Steps land exactly on every command or external-force switch; the step before a switch (and
before ``t_end``) is shortened. ``budget.max_steps`` counts steps.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from .._validation import as_float
from ..model import Plant, implicit_step
from ._reference import (BudgetExceeded, Meter, build_result, format_setting,
                         samples_from_steps, segment_edges)
from ._result import Budget, SimulationResult, SimulationStatus

__all__ = ["simulate_moreau", "moreau_step_staircase"]


def moreau_step_staircase(levels: np.ndarray, plateaus: np.ndarray, a: float,
                          b: float) -> tuple[float, bool]:
    """Solve ``a W - b in F(W)`` on a Coulomb staircase (one Moreau-Jean step).

    Parameters
    ----------
    levels : ndarray of shape (K,), m/s
        Distinct contact speeds, ascending.
    plateaus : ndarray of shape (K + 1,), N
        Force below ``levels[0]``, between consecutive levels, above ``levels[-1]``.
    a : float, N s/m
        ``m / h + c > 0``.
    b : float, N
        ``m V / h + F_ext``.

    Returns
    -------
    W : float, m/s
        The unique solution.
    stuck : bool
        True when ``W`` is a contact speed (the set-valued force was used).
    """
    upper = a * levels - plateaus[1:]            # increasing: a s_k - P_{k+1}
    k = int(np.searchsorted(upper, b, side="left"))
    return _resolve(levels, plateaus, a, b, k)


def _resolve(levels: np.ndarray, plateaus: np.ndarray, a: float, b: float,
             k: int) -> tuple[float, bool]:
    if k < levels.size and a * levels[k] - plateaus[k] <= b:
        return float(levels[k]), True
    return float((b + plateaus[k]) / a), False


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
    tolerance = 4.0 * (levels.size + 1) * np.finfo(float).eps * total
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
        Report times (linear interpolation between steps, the net force of the step that
        ends at or after each time); ``None``: every step.
    step : float, s
        Step length ``h > 0`` (shortened to land on switches and ``t_end``).

    Returns
    -------
    SimulationResult
        ``force`` is ``m (W - V) / h`` of each step (the net force actually applied, the
        stiction force included); no events are reported.
    """
    h = as_float(step, "step", "simulate_moreau", low=0.0, low_open=True)
    meter = Meter(budget, counts="steps")
    dynamic = plant.dynamic_motors
    speeds = plant.initial_speeds()
    times, values, forces, rows = [0.0], [v0], [plant.net_force(0.0, v0, speeds)], [speeds]
    status, detail = SimulationStatus.SUCCESS, ""
    edges = segment_edges(plant, t_end)
    try:
        with np.errstate(over="ignore", invalid="ignore"):   # non-finite W: caught per step
            _segments(plant, edges, h, v0, speeds, meter, times, values, forces, rows)
    except BudgetExceeded as stop:
        status, detail = stop.status, stop.detail
    step_t = np.array(times)
    state = np.column_stack((values, forces))
    if dynamic:
        state = np.column_stack((state, np.array(rows[:len(times)])))
    t_out, y_out = samples_from_steps(step_t, state, t_eval)
    if t_eval is not None:                       # force of the step containing each time
        index = np.minimum(np.searchsorted(step_t, t_out, side="left"), step_t.size - 1)
        y_out[:, 1] = state[index, 1]
    return build_result(
        plant, method="moreau", setting=format_setting(h=h), t=t_out, V=y_out[:, 0],
        contact_speeds=y_out[:, 2:] if dynamic else None, force=y_out[:, 1], meter=meter,
        status=status, detail=detail)


def _segments(plant: Plant, edges: np.ndarray, h: float, V: float, speeds: np.ndarray,
              meter: Meter, times: list[float], values: list[float], forces: list[float],
              rows: list[np.ndarray]) -> None:
    """Step over every segment between switches, appending to the output lists."""
    dynamic = plant.dynamic_motors
    for t0, t1 in zip(edges[:-1], edges[1:]):
        t0, t1 = float(t0), float(t1)
        count = max(1, math.ceil((t1 - t0) / h * (1.0 - 1e-12)))
        # (time at the end of the step, step length): nominal h, the last one shortened
        grid = [(t0 + j * h, h) for j in range(1, count)]
        grid.append((t1, t1 - (t0 + (count - 1) * h)))
        if dynamic or plant.compliance > 0:
            V, speeds = _general_segment(plant, t0, grid, V, speeds, meter,
                                         times, values, forces, rows)
        else:
            V = _staircase_segment(plant, t0, grid, V, meter, times, values, forces)


def _finite_step(t: float, W: float, force: float) -> float:
    """``force``, after checking that the step's speed and force are finite (else FAILED)."""
    if not (math.isfinite(W) and math.isfinite(force)):
        raise BudgetExceeded(SimulationStatus.FAILED, f"the state became non-finite at t = {t:.6g} s "
                             f"(V = {W:.3g} m/s, force = {force:.3g} N)")
    return force


def _staircase_segment(plant: Plant, t0: float, grid: list[tuple[float, float]], V: float,
                       meter: Meter,
                       times: list[float], values: list[float], forces: list[float]) -> float:
    """Steps over a segment with constant contact speeds: one staircase, binary searches."""
    cs = plant.contacts.with_speeds(plant.command(t0))
    stair = cs.staircase()
    levels, plateaus = stair.levels, stair.plateaus
    ext, m, c = plant.external(t0), plant.mass, plant.damping
    cache: dict[float, tuple[float, list[float]]] = {}
    for t_next, h in grid:
        if h not in cache:
            a = m / h + c
            cache[h] = (a, (a * levels - plateaus[1:]).tolist())
        a, upper = cache[h]
        b = m * V / h + ext
        W, _ = _resolve(levels, plateaus, a, b, bisect.bisect_left(upper, b))
        meter.evaluations += 1
        meter.step()
        forces.append(_finite_step(t_next, W, m * (W - V) / h))
        times.append(t_next)
        values.append(W)
        V = W
    return V


def _general_segment(plant: Plant, t0: float, grid: list[tuple[float, float]], V: float,
                     speeds: np.ndarray, meter: Meter, times: list[float], values: list[float],
                     forces: list[float], rows: list[np.ndarray]) -> tuple[float, np.ndarray]:
    """Steps with dynamic motors and/or compliance: staircase or kinks rebuilt every step."""
    command = plant.command(t0)
    ext, m, c = plant.external(t0), plant.mass, plant.damping
    for t_next, h in grid:
        if plant.dynamic_motors:
            speeds = implicit_step(plant.motors, speeds, command, h)
        else:
            speeds = command
        a, b = m / h + c, m * V / h + ext
        if plant.compliance > 0:
            W = _compliant_step(plant, speeds, a, b, meter)
        else:
            levels, plateaus = _staircase(speeds, forces_sorted_by=plant.contacts.forces)
            W, _ = moreau_step_staircase(levels, plateaus, a, b)
            meter.evaluation()
        meter.step()
        forces.append(_finite_step(t_next, W, m * (W - V) / h))
        times.append(t_next)
        values.append(W)
        rows.append(speeds)
        V = W
    return V, speeds
