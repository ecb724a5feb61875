"""Each contact's speed from least-squares lines through its wheel's counts.

:func:`contact_speed_estimates` (a record) and :class:`ContactSpeedTracker` (one row at a
time, the same formulas) give the contacts' speeds the known input of
:class:`~toolkit.estimation._input.EstimatorModel` is computed from, with their variances.
Derivations: docs/estimation.md.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..laws import quantization_variance
from .._compiled import kernels
from ..model.motors import unsaturated_response
from ._input import EstimatorModel

__all__ = ["contact_speed_estimates", "ContactSpeedTracker"]


def contact_speed_estimates(wheel_counts: Any, commands: Any, times: Any, model: EstimatorModel,
                            *, initial: Any = None
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contact speeds at the samples from wheel counts and commands (vectorized).

    Parameters
    ----------
    wheel_counts : array_like of shape (k, n), counts
    commands : array_like of shape (k, n), m/s
    times : array_like of shape (k,), s
    model : EstimatorModel
    initial : array_like of shape (n,), m/s, optional
        The command the motors had settled at before row 0
        (:attr:`EncoderRecord.initial_commands <toolkit.model.sensors.EncoderRecord>`). When
        row 0's command differs, row 0 is a command change (a motor transient follows, the
        wheel window starts ``settle`` rows later) from the speeds ``initial``; ``None``:
        the motors already run at row 0's command.

    Returns
    -------
    speeds : ndarray of shape (k, n), m/s
    variance : ndarray of shape (k,), (m/s)^2
        Per-contact variance: the least-squares slope's ``(q^2 / 12) / S`` with ``S = sum
        (t_i - tbar)^2`` over the window's readings (docs/estimation.md); in a transient the motor law's own uncertainty, taken
        as 10 % of the remaining gap, squared, plus one period's quantization ``q^2 / (6
        h^2)``.
    steady : ndarray of shape (k,), bool
        False within ``settle`` samples after a command change (the motors move).
    """
    w = np.asarray(wheel_counts, dtype=float)
    u = model.clip(commands)                       # what the motors are asked for
    t = np.asarray(times, dtype=float)
    k = t.size
    q = model.sensors.wheel.distance_per_count
    idx = np.arange(k)
    changed = np.zeros(k, dtype=bool)
    changed[1:] = np.any(u[1:] != u[:-1], axis=1)
    c0 = None if initial is None else np.asarray(initial, dtype=float)
    if c0 is not None and k:
        changed[0] = bool(np.any(u[0] != c0))
    # Last change strictly before row j (changes at j act after t_j), -inf-like when none.
    marks = np.where(changed, idx, -10**9)
    last_change = np.maximum.accumulate(np.concatenate(([-10**9], marks[:-1])))
    settle = model.settle
    start = np.maximum(last_change + settle, idx - model.max_window)
    start = np.clip(start, 0, idx)
    ok = start < idx
    speeds = np.zeros_like(w)
    variance = np.zeros(k)
    # The least-squares line of each window: readings start..j padded with zeros to
    # max_window + 1 columns and summed column by column (zeros add nothing exactly);
    # ContactSpeedTracker's row is the same formula (equal to rounding).
    rows = np.flatnonzero(ok)
    L = model.max_window + 1
    ar = np.arange(L)
    for chunk in np.array_split(rows, rows.size // 8192 + 1):
        if not chunk.size:
            continue
        s0, last = start[chunk], chunk - start[chunk]
        inside = ar <= last[:, None]
        J = np.minimum(s0[:, None] + ar, k - 1)
        t_rel = np.where(inside, t[J] - t[s0][:, None], 0.0)
        total = np.zeros(chunk.size)
        for i in range(L):
            total += t_rel[:, i]
        tt = np.where(inside, t_rel - (total / (last + 1))[:, None], 0.0)
        tt2 = tt * tt
        S = np.zeros(chunk.size)
        for i in range(L):
            S += tt2[:, i]
        w_s = w[s0]
        cov = np.zeros((chunk.size, w.shape[1]))
        for i in range(L):
            cov += (w[J[:, i]] - w_s) * tt[:, i, None]
        speeds[chunk] = cov * (q / S)[:, None]
        variance[chunk] = model.reading_variance(np.abs(speeds[chunk]).max(axis=1)) / S
    steady = (idx - last_change) >= settle
    steady &= ~changed
    transient = ~ok
    if transient.any():
        has_change = last_change >= 0
        # Row 0 with no history: the speeds the motors had settled at, else the commands.
        none = transient & ~has_change
        speeds = np.where(none[:, None], u if c0 is None else c0, speeds)
        variance = np.where(none, (q * model.sensors.rate) ** 2, variance)
        # Inside the transient after a change, the motor law (toolkit.model.motors)
        # u + (v0 - u) exp(-(t - t_change) / tau) from the speeds at the change: that row's
        # own estimate (the window's when settled; the law continued from the change before
        # when the commands change again inside a transient; the settled speeds at row 0).
        # Rows of one change are contiguous (last_change does not decrease): in order.
        floor = q * q / 6.0 / model.sensors.period**2
        rows = np.flatnonzero(transient & has_change)
        if rows.size:
            owners = last_change[rows]
            cuts = np.flatnonzero(np.diff(owners)) + 1
            for seg in np.split(rows, cuts):
                c = int(last_change[seg[0]])
                law = unsaturated_response(speeds[c], u[c], (t[seg] - t[c])[:, None], model.motor_lag, math.inf)
                speeds[seg] = law
                variance[seg] = (0.1 * np.abs(law - u[c])).max(axis=1) ** 2 + floor
    return speeds, variance, steady


class ContactSpeedTracker:
    """:func:`contact_speed_estimates` one row at a time, for a loop (O(n max_window) per sample).

    The same formulas on the same numbers as the vectorized function (a test checks they
    agree to rounding), keeping only what the next rows need: the last ``max_window + 1``
    times and wheel counts, the last command change and the speeds at it. :meth:`push` also
    returns the sample's input ingredients (:meth:`EstimatorModel.period_track` and
    :meth:`EstimatorModel.bounds` of the row).

    Parameters
    ----------
    model : EstimatorModel
    initial : array_like of shape (n,), m/s, optional
        As in :func:`contact_speed_estimates`.
    residuals : bool
        Also estimate each contact's variance from its window's residuals
        (``contact_variance``: covariance matching, for encoders noisier than their
        quantization); default False.

    Attributes
    ----------
    contact_variance : ndarray of shape (n,), (m/s)^2
        With ``residuals``: each contact's slope variance, ``s_i^2 / S`` with ``s_i^2`` the
        window's residual variance (``RSS / (m - 2)``, at least the quantization's ``q^2 /
        12``); the row's variance elsewhere (fewer than 4 readings, or a transient).
    reading_variance : ndarray of shape (n,), m^2
        With ``residuals``: each wheel's residual variance per reading, ``s_i^2`` (at least
        ``q^2 / 12``).
    white_variance : float, (m/s)^2
        The last row's variance (the white quantization's, or the transient's).
    window_length : int
        Readings in the last row's window (0 in a transient).
    command : ndarray of shape (n,), m/s
        The last row's command, clipped to the speed limits (the motor law's clip).
    changed : bool
        The last row's command differs from the row's before.
    """

    #: With ``residuals``: windows of eight readings or more refit the residual variance
    #: every this many rows (it moves little from one row to the next).
    RESIDUALS_EVERY = 5

    def __init__(self, model: EstimatorModel, initial: Any = None, residuals: bool = False) -> None:
        self.model = model
        self._residuals = residuals
        self.contact_variance = np.zeros(model.n)
        self.white_variance = 0.0
        self.window_length = 0
        self._q = model.sensors.wheel.distance_per_count
        self.reading_variance = np.full(model.n, quantization_variance(self._q))
        self._settle = model.settle
        self._keep = model.max_window + 1
        self._initial = None if initial is None else np.array(initial, dtype=float)
        self._prev: np.ndarray | None = self._initial
        self.command: np.ndarray | None = None
        self.changed = False
        # Times and counts of the last rows (row j at column j - _base), compacted when full.
        self._cap = 4 * self._keep
        self._tb = np.empty(self._cap)
        self._wb = np.empty((self._cap, model.n))
        self._base = 0
        self._j = -1
        self._last_change = -10**9
        self._change: tuple[float, np.ndarray, np.ndarray] | None = None  # (t, u, before)
        self._lag = model.motor_lag
        low, high = model.speed_limits
        # Clipping only when the motors have limits (the loop's per-sample cost otherwise).
        self._clip = self._clipped if (math.isfinite(low) or math.isfinite(high)) else (lambda u: u)
        self._limits = (low, high)
        self._law_floor = self._q * self._q / 6.0 / model.sensors.period**2

    def _clipped(self, u: np.ndarray) -> np.ndarray:
        """The command clipped by the motor law (:meth:`EstimatorModel.clip`) when it leaves the
        speed limits (the common case, inside them, costs two comparisons)."""
        low, high = self._limits
        if low <= u.min() and u.max() <= high:
            return u
        return self.model.clip(u)

    def push(self, t: float, wheel_counts: Any, command: Any
             ) -> tuple[np.ndarray, float, bool, np.ndarray]:
        """Take row ``j`` (its time, wheel counts, and the command sent then).

        Returns
        -------
        speeds : ndarray of shape (n,), m/s
        variance : float, (m/s)^2
        steady : bool
        track : ndarray of shape (2, n), m/s
            :meth:`EstimatorModel.period_track` of the row.
        """
        model, q = self.model, self._q
        j = self._j = self._j + 1
        w = np.array(wheel_counts, dtype=float)
        u = self._clip(command if type(command) is np.ndarray and command.dtype == np.float64 else
                       np.asarray(command, dtype=float))
        col = j - self._base
        if col == self._cap:                 # keep the last keep - 1 rows, then append
            kept = self._keep - 1
            self._tb[:kept] = self._tb[col - kept:col]
            self._wb[:kept] = self._wb[col - kept:col]
            self._base += col - kept
            col = kept
        self._tb[col] = t
        self._wb[col] = w
        prev = self._prev
        changed = prev is not None and u.tolist() != prev.tolist()       # (lists: cheaper on a few contacts)
        self._prev = self.command = u
        self.changed = changed
        lc = self._last_change
        start = min(max(lc + self._settle, j - model.max_window, 0), j)
        ok = start < j
        if ok:
            # The least-squares line through the window's readings: contact_speed_estimates'
            # formula and order of sums, in one kernel call (toolkit._compiled.core.window_line).
            a = start - self._base
            speeds = np.empty(model.n)
            S, peak = kernels("core", 2 * model.n * (j - start + 1)).window_line(self._tb, self._wb, a, col,
                                                                               q, speeds)
            variance = float(model.reading_variance(peak)) / S
            self.white_variance = variance
            self.window_length = j - start + 1
            if self._residuals:
                m = j - start + 1
                if m >= 4 and (m < 8 or m % self.RESIDUALS_EVERY == 0):
                    tb, wb = self._tb[a:col + 1], self._wb[a:col + 1]
                    t_rel = tb - tb[0]
                    tt = t_rel - t_rel.sum() / m
                    centred = wb - wb.mean(axis=0)
                    along = tt @ centred
                    rss = np.einsum("ij,ij->j", centred, centred) - along * along / S
                    self.reading_variance = np.maximum((q * q) * rss / (m - 2), quantization_variance(q))
                elif m < 4:
                    self.reading_variance = np.full(model.n, quantization_variance(q))
                self.contact_variance = (self.reading_variance / S if m >= 4 else np.full(model.n, variance))
        elif lc >= 0:
            t_c, u_c, before = self._change  # type: ignore[misc]
            law = unsaturated_response(before, u_c, t - t_c, self._lag, math.inf)
            speeds = law
            variance = float(np.max(0.1 * np.abs(law - u_c))) ** 2 + self._law_floor
        else:
            speeds = u if self._initial is None else self._initial
            variance = (q * model.sensors.rate) ** 2
        if not ok:
            self.white_variance = float(variance)
            self.window_length = 0
        if self._residuals and not ok:
            self.contact_variance = np.full(model.n, float(variance))
            self.reading_variance = np.full(model.n, quantization_variance(q))
        steady = (j - lc) >= self._settle and not changed
        if changed:
            # The speeds at the change: this row's own estimate (contact_speed_estimates).
            before = speeds
            self._last_change = j
            self._change = (t, u, before)
        # EstimatorModel.period_track for this row: from the speeds towards the command
        # (not steady) or the speeds held (steady); without a lag the command at once.
        track = np.empty((2, model.n))
        track[0] = speeds if steady or self._lag > 0 else u
        track[1] = speeds if steady else u
        return speeds, float(variance), steady, track
