"""Kernels of sampled closed loops: the exact plant under a law held over each period.

:func:`sampled_steps` runs samples of one loop (the sensor law, the law's commands and force,
the engine of the plant's motors); :func:`sampled_batch` runs many loops of one plant in
parallel. A law is a piecewise-constant table of commands and forces, optionally shifted by a
PI law on the speed error and clipped, optionally after a carry phase.
"""

from __future__ import annotations

import math

import numpy as np

from .segments import (DONE, FAILED_STEP, F_RATE, F_REL, F_T, F_V, I_CHUNK, I_HINT, I_MAXSTEPS,
                       I_NEV, I_NSEG, I_STUCK, I_WINDOW, N_FSTATE, N_ISTATE, PAUSE, displacement,
                       grown, samples)
from .tables import sorted_landscape
from .ideal import ideal_piece
from .lagging import (P_COMPLIANCE, P_DAMPING, P_MASS, P_RATE, P_TAU, P_TOTAL, advance_dynamic,
                      advance_outputs, dynamic_run)

#: Replaced by ``numba.prange`` when compiled (a parallel loop); ``range`` as Python.
prange = range

# A law: ints ``law_i[L_CARRY]``, ``law_i[L_SHIFT]``; floats ``law_f[L_SWITCH]`` ...
L_CARRY, L_SHIFT = 0, 1
L_SWITCH, L_START, L_REFERENCE, L_KP, L_KI, L_PERIOD, L_LOW, L_HIGH = range(8)
EST_TRUTH, EST_GIVEN = 0, 1          # estimates: the true speed, or given per sample
LAW_TABLE, LAW_GIVEN = 0, 1          # commands: the law's table, or given per sample
# The loop's state between calls (floats: time, speed, body position, releasing; ints: the
# contact the body follows, the hint of the engine's last event).
S_T, S_V, S_X, S_REL = 0, 1, 2, 3
S_STUCK, S_HINT = 0, 1

_IEEE = {"error_model": "numpy"}   # IEEE division: x / 0 is inf or NaN (as NumPy), never raises
#: The kernels of this module and their numba options (toolkit._compiled.load compiles them).
KERNELS = {"sensor_read": _IEEE, "law_output": _IEEE, "sampled_steps": _IEEE,
           "fresh_counters": {}, "lagging_period": _IEEE, "ideal_period": _IEEE,
           "sampled_batch": {"parallel": True, "error_model": "numpy"}}


def sensor_read(X: float, x: np.ndarray, motor: np.ndarray, half: float, qc: float,
                qw: float, wheel: np.ndarray) -> int:
    """The sensor law of :mod:`toolkit.model.sensors` at one read instant, noiseless (its one
    compiled form: :class:`~toolkit.model.sensors.SensorReader` without missed counts, noise
    or jitter; tested against it): the play operator of width ``2 half`` (m) moves the
    motor-side positions ``motor`` (n,) towards the contact positions ``x`` (m), then every
    position is quantized, ``floor(position / q)``. Returns the central count (body position
    ``X``, m, counts of ``qc`` m) and writes the wheel counts (counts of ``qw`` m) to
    ``wheel``."""
    for i in range(x.size):
        motor[i] = min(max(motor[i], x[i] - half), x[i] + half)
        wheel[i] = math.floor(motor[i] / qw)
    return math.floor(X / qc)


def law_output(law_i: np.ndarray, law_f: np.ndarray, carry: np.ndarray,
               law_times: np.ndarray, law_rows: np.ndarray, law_forces: np.ndarray,
               z: np.ndarray, t: float, estimate: float, out: np.ndarray) -> float:
    """The law's commands (m/s, into ``out`` (n,)) and outside force (N, returned) at sample
    time ``t`` (s) from the speed estimate (m/s), and its state ``z`` (1,) moved to the next
    sample (the PI law's integral of the speed error, m). The controllers' own arithmetic
    (:mod:`toolkit.controllers`: ``output`` then ``update``), in the same operations."""
    n = out.size
    if law_i[L_CARRY] != 0 and t < law_f[L_SWITCH]:
        for i in range(n):
            out[i] = carry[i]
        return 0.0
    inner = t
    if law_i[L_CARRY] != 0:              # the inner clock, snapped to the sample grid
        period = law_f[L_PERIOD]
        inner = t - law_f[L_START]
        grid = round(inner / period) * period
        if abs(inner - grid) <= 1e-9 * period:
            inner = grid
    K = law_times.size
    j = 0                                # the row of the table at the inner time
    while j < K and law_times[j] <= inner:
        j += 1
    if law_i[L_SHIFT] != 0:
        reference = law_f[L_REFERENCE]
        error = reference - estimate
        centre = reference + law_f[L_KP] * error + law_f[L_KI] * z[0]
        low, high = law_f[L_LOW], law_f[L_HIGH]
        for i in range(n):
            out[i] = min(max(law_rows[j, i] + centre, low), high)
        z[0] = z[0] + (reference - estimate) * law_f[L_PERIOD]
    else:
        for i in range(n):
            out[i] = law_rows[j, i]
    return law_forces[j]


def sampled_steps(k0: int, k1: int, times: np.ndarray, f: np.ndarray, params: np.ndarray,
                  dynamic: bool, try_quiet: bool, low: float, high: float,
                  budget_i: np.ndarray, rate_ev: float, est_kind: int, law_kind: int,
                  law_i: np.ndarray, law_f: np.ndarray, carry: np.ndarray,
                  law_times: np.ndarray, law_rows: np.ndarray, law_forces: np.ndarray,
                  z: np.ndarray, sensors: bool, sens_f: np.ndarray, play: np.ndarray,
                  state_f: np.ndarray, state_i: np.ndarray, speeds: np.ndarray,
                  x: np.ndarray, speed: np.ndarray, position: np.ndarray,
                  estimate: np.ndarray, variance: np.ndarray, commands: np.ndarray,
                  force: np.ndarray, contact: np.ndarray, central: np.ndarray,
                  wheel: np.ndarray) -> tuple[int, int]:
    """Samples ``k0 .. k1 - 1`` of a sampled loop (``times`` (S,), s): at each, the estimate
    (the true speed, or the caller's), the law's commands and force (or the caller's), the
    plant over the period (:func:`lagging_period` or :func:`ideal_period`: the engines of
    ``advance``, the same numbers), the exact displacements, and the next sample's record
    (speed, position, contact speeds, and with ``sensors`` the counts of :func:`sensor_read`).
    The plant: magnitudes ``f``, constants ``params`` (``P_TOTAL`` ..), command limits
    ``low``, ``high``; ``budget_i``: ``[max rounds, Zeno window]`` per step, ``rate_ev`` the
    event rate. ``sens_f``: ``[qc, qw, half]``. ``state_f``, ``state_i``, ``speeds``, ``x``
    and ``play`` carry the plant's and the sensors' state between calls. Returns ``(code,
    k)``: ``DONE`` and the next sample to run, or the code of a step the budget stopped
    (``MAX_STEPS``, ``ZENO``; ``FAILED_STEP`` for a speed that left the floating-point range)
    and the number of samples recorded (the failed step's start is the last)."""
    n = f.size
    S = times.size
    seg = np.empty((64, 7))
    ev = np.empty((64, 4))
    fstate = np.zeros(N_FSTATE)
    istate = np.zeros(N_ISTATE, dtype=np.int64)
    motor = np.empty((5, n))
    out = np.empty((2, n))
    u = np.empty(n)
    scratch = np.empty((3, n + 1))            # the staircase of ideal motors' commands
    first = np.empty(n, dtype=np.int64)
    order = np.empty(n, dtype=np.int64)
    rows2 = np.empty((1, n))
    K = -1
    qc, qw, half = sens_f[0], sens_f[1], sens_f[2]
    for k in range(k0, k1):
        if est_kind == EST_TRUTH:
            estimate[k] = speed[k]
            variance[k] = 0.0
        if law_kind == LAW_TABLE:
            force[k] = law_output(law_i, law_f, carry, law_times, law_rows, law_forces, z,
                                  times[k], estimate[k], commands[k])
        if k + 1 == S:
            return DONE, k + 1
        t0, t1 = times[k], times[k + 1]
        for i in range(n):
            u[i] = min(max(commands[k, i], low), high)
        fresh_counters(fstate, istate, budget_i, rate_ev)       # one step: advance's _Recorder
        if dynamic:
            code, V, body, seg, ev = lagging_period(f, params, try_quiet, t0, t1, force[k], speeds,
                                                    u, state_f, state_i, motor, fstate, istate,
                                                    seg, ev, out)
            if code != DONE:
                return code, k + 1
            for i in range(n):
                speeds[i] = out[0, i]
                x[i] = x[i] + out[1, i]
        else:
            same = K >= 0
            for i in range(n):
                same = same and rows2[0, i] == u[i]
            if not same:                         # the staircase of the new commands
                for i in range(n):
                    rows2[0, i] = u[i]
                K = sorted_landscape(rows2, f.reshape((1, n)), 0, order, scratch, first)
            code, V, body, seg, ev = ideal_period(f, params, K, scratch, first, t0, t1, force[k], u,
                                                  state_f, state_i, fstate, istate, seg, ev)
            if code != DONE:
                return code, k + 1
            span = t1 - t0
            for i in range(n):
                speeds[i] = u[i]
                x[i] = x[i] + u[i] * span
        if not (V - V == 0.0):
            return FAILED_STEP, k + 1
        state_f[S_T] = t1
        state_f[S_V] = V
        state_f[S_X] = state_f[S_X] + body
        speed[k + 1] = V
        position[k + 1] = state_f[S_X]
        for i in range(n):
            contact[k + 1, i] = speeds[i]
        if sensors:
            central[k + 1] = sensor_read(state_f[S_X], x, play, half, qc, qw, wheel[k + 1])
    return DONE, k1


def fresh_counters(fstate: np.ndarray, istate: np.ndarray, budget_i: np.ndarray, rate_ev: float) -> None:
    """The engines' state reset for one step with fresh budget counters (``budget_i``:
    ``[max rounds, Zeno window]``, ``rate_ev`` the event rate)."""
    for j in range(N_FSTATE):
        fstate[j] = 0.0
    for j in range(N_ISTATE):
        istate[j] = 0
    istate[I_STUCK] = -1
    istate[I_HINT] = -1
    istate[I_MAXSTEPS] = budget_i[0]
    istate[I_WINDOW] = budget_i[1]
    istate[I_CHUNK] = 1 << 14
    fstate[F_RATE] = rate_ev


def lagging_period(f: np.ndarray, params: np.ndarray, try_quiet: bool, t0: float, t1: float,
                   E: float, speeds: np.ndarray, u: np.ndarray, state_f: np.ndarray, state_i: np.ndarray,
                   motor: np.ndarray, fstate: np.ndarray, istate: np.ndarray, seg: np.ndarray,
                   ev: np.ndarray, out: np.ndarray) -> tuple[int, float, float, np.ndarray, np.ndarray]:
    """One sample period ``[t0, t1)`` (s) of lagging or rate-limited motors from contact speeds
    ``speeds`` under commands ``u`` and force ``E`` (:func:`advance_dynamic`, resumed while it pauses; the loop's state in
    ``state_f``, ``state_i``): returns ``(code, V, body displacement, seg, ev)`` with the
    contact speeds and displacements in ``out``."""
    n = f.size
    tau = params[P_TAU]
    code, quiet, body = advance_dynamic(
        f, params, try_quiet and state_i[S_HINT] < 0 and state_f[S_REL] == 0.0,
        t0, t1, state_f[S_V], state_i[S_STUCK], state_i[S_HINT], state_f[S_REL], speeds, u, E,
        motor, fstate, istate, seg, ev, out)
    if quiet:
        state_f[S_REL] = 0.0
        state_i[S_HINT] = -1
        return code, fstate[F_V], body, seg, ev
    bounds = np.empty(2)
    externals = np.empty(1)
    while code == PAUSE:             # buffers full or a chunk of rounds: grow
        if min(seg.shape[0] - istate[I_NSEG], ev.shape[0] - istate[I_NEV]) < 16:
            seg = grown(seg)
            ev = grown(ev)
        bounds[0] = t0
        bounds[1] = t1
        externals[0] = E
        code = dynamic_run(f, params[P_TOTAL], params[P_MASS], params[P_DAMPING],
                           params[P_COMPLIANCE], tau, params[P_RATE], bounds, u.reshape((1, n)),
                           externals, motor, fstate, istate, seg, ev)
        if code != PAUSE:
            body = advance_outputs(motor, tau, t0, fstate, istate, seg, out)
    if code == DONE:
        state_i[S_STUCK] = istate[I_STUCK]
        state_i[S_HINT] = istate[I_HINT]
        state_f[S_REL] = fstate[F_REL]
    return code, fstate[F_V], body, seg, ev


def ideal_period(f: np.ndarray, params: np.ndarray, K: int, land: np.ndarray, first: np.ndarray,
                 t0: float, t1: float, E: float, u: np.ndarray, state_f: np.ndarray,
                 state_i: np.ndarray, fstate: np.ndarray, istate: np.ndarray, seg: np.ndarray,
                 ev: np.ndarray) -> tuple[int, float, float, np.ndarray, np.ndarray]:
    """One sample period ``[t0, t1)`` (s) of ideal motors at the commands ``u`` (their
    staircase ``land`` of ``K`` levels) under force ``E`` (:func:`ideal_piece`, resumed while
    it pauses): returns ``(code, V, body displacement, seg, ev)``."""
    m, c = params[P_MASS], params[P_DAMPING]
    fstate[F_T] = t0
    fstate[F_V] = state_f[S_V]
    istate[I_STUCK] = state_i[S_STUCK]
    code = ideal_piece(True, K, land, first, u, f, land[1, K], m, c, E, t1, fstate, istate, seg, ev)
    while code == PAUSE:
        if min(seg.shape[0] - istate[I_NSEG], ev.shape[0] - istate[I_NEV]) < 16:
            seg = grown(seg)
            ev = grown(ev)
        code = ideal_piece(True, K, land, first, u, f, land[1, K], m, c, E, t1, fstate, istate, seg, ev)
    if code != DONE:
        return code, fstate[F_V], 0.0, seg, ev
    state_i[S_STUCK] = istate[I_STUCK]
    return code, fstate[F_V], displacement(seg, istate[I_NSEG], 0.0, t1), seg, ev


def sampled_batch(samples: np.ndarray, times: np.ndarray, f: np.ndarray, params: np.ndarray,
                  dynamic: bool, try_quiet: bool, low: float, high: float,
                  budget_i: np.ndarray, rate_ev: float, law_i: np.ndarray, law_f: np.ndarray,
                  carry: np.ndarray, law_times: np.ndarray, law_rows: np.ndarray,
                  law_forces: np.ndarray, v0: np.ndarray, start_speeds: np.ndarray,
                  speed: np.ndarray, commands: np.ndarray, force: np.ndarray,
                  contact: np.ndarray, codes: np.ndarray, reached: np.ndarray) -> None:
    """Many sampled loops of one plant on the true speed (no sensors, no estimator), each
    through :func:`sampled_steps` from rest of its motors at ``start_speeds[r]`` and body
    speed ``v0[r]`` over ``samples[r]`` samples of ``times``, with its own law (row ``r`` of
    ``law_i`` .. ``law_forces``), in parallel over runs (``prange``). Per run: the speeds
    (rows of ``speed``, ``contact``), commands and forces, the code and the samples
    recorded."""
    R = samples.size
    n = f.size
    for r in prange(R):
        S = samples[r]
        state_f = np.zeros(4)
        state_i = np.full(2, -1, dtype=np.int64)
        state_f[S_V] = v0[r]
        speeds = start_speeds[r].copy()
        x = np.zeros(n)
        z = np.zeros(1)
        play = np.zeros(n)
        estimate = np.empty(S)
        variance = np.empty(S)
        position = np.empty(S)
        central = np.empty(0, dtype=np.int64)
        wheel = np.empty((0, n), dtype=np.int64)
        speed[r, 0] = v0[r]
        position[0] = 0.0
        for i in range(n):
            contact[r, 0, i] = speeds[i]
        codes[r], reached[r] = sampled_steps(
            0, S, times[:S], f, params, dynamic, try_quiet, low, high, budget_i, rate_ev,
            EST_TRUTH, LAW_TABLE, law_i[r], law_f[r], carry[r], law_times[r], law_rows[r],
            law_forces[r], z, False, np.zeros(3), play, state_f, state_i, speeds, x,
            speed[r], position, estimate, variance, commands[r], force[r], contact[r],
            central, wheel)
