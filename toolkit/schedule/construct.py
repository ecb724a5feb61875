"""Constructive contact-speed schedules and their certificates (private to
:mod:`toolkit.schedule`).

Period by period the best of a few closed-form candidates (follow a lag-compensated path,
push up, push down), evaluated by implicit steps of the exact Coulomb law with a short
look-ahead; :func:`tracking_lower_bound` certifies how well any schedule can track
(docs/physics.md section 4; the construction: docs/methods.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from .. import laws
from ..model.motors import lag_memory, reach, unsaturated_response

#: Shifts of the follow target, in units of the period's reference change (plus -kappa).
_SHIFTS = (0.0, -0.5, 0.5, 1.0, 2.0)
#: Fractions of the way to the speed limit for contacts on the wrong side of the body.
_SHARES = (0.1, 0.25, 0.5, 1.0)
#: Look-ahead periods after each candidate's own (the first with a choice of shifts).
_AHEAD = 3
#: Implicit substeps per period of the candidate evaluation.
_STEPS = 8
#: Sup errors closer than this (m/s) tie; the squared error breaks the tie.
_TIE = 1e-7


@dataclass(frozen=True)
class Construction:
    """A constructive schedule (private).

    Attributes
    ----------
    commands : ndarray of shape (K, n), m/s
        Projected commands of each period.
    contact_speeds : ndarray of shape (K + 1, n), m/s
        Contact speeds at the period starts (closed form).
    body_speed : ndarray of shape (K + 1,), m/s
        The evaluator's body speed at the period starts (implicit steps of the exact law).
    choices : tuple of str
        Which candidate each free period uses.
    """

    commands: np.ndarray
    contact_speeds: np.ndarray
    body_speed: np.ndarray
    choices: tuple[str, ...]


def implicit_step(V: np.ndarray, v: np.ndarray, forces: np.ndarray, mass: float, damping: float,
                  external: float, h: float) -> np.ndarray:
    """One implicit (Moreau) step of ``m V' in sum f_i Sign(v_i - V) + F_ext - c V`` per row:
    :func:`toolkit.laws.implicit_step` on each row's staircase (its contacts sorted).

    Parameters
    ----------
    V : ndarray of shape (C,), m/s
        Body speed of each row at the start of the step.
    v : ndarray of shape (C, n), m/s
        Contact speeds at the end of the step.
    forces : ndarray of shape (n,), N
    mass, damping, external, h : float
        kg, N s/m, N, s.

    Returns
    -------
    ndarray of shape (C,), m/s
    """
    order = np.argsort(v, axis=1)
    f = forces[order]
    swept = np.concatenate((np.zeros((v.shape[0], 1)), np.cumsum(f, axis=1)), axis=1)
    plateaus = f.sum(axis=1)[:, None] - 2.0 * swept        # force between consecutive contacts
    W, _ = laws.implicit_step(np.take_along_axis(v, order, axis=1), plateaus, mass / h + damping,
                              mass * V / h + external)
    return W


def _steady_shift(tau: float, period: float) -> float:
    """``kappa``: half the peak of the lag path's bulge over a steady ramp, in units of dR."""
    if tau <= 0:
        return 0.5                                       # a jump: centre the constant on the ramp
    X = period / tau
    d = lag_memory(X, 1.0)[0]                            # (the motor law in units of tau)
    x = math.log(X / (1.0 - d)) if X > 1.0 - d else 0.0
    return 0.5 * max(0.0, (1.0 - lag_memory(x, 1.0)[0]) / (1.0 - d) - x / X)


def construct(*, forces: np.ndarray, mass: float, damping: float,
              external: Callable[[float], float], tau: float, rate: float, period: float,
              lo: float, hi: float, start: np.ndarray, v0: float, K: int, pinned: bool,
              reference: Callable[[Any], np.ndarray],
              project: Callable[[np.ndarray, np.ndarray], np.ndarray],
              squared: bool) -> Construction:
    """Build a schedule of ``K`` periods greedily from the closed-form candidates.

    Parameters
    ----------
    forces : ndarray of shape (n,), N
    mass, damping : float
        kg, N s/m.
    external : callable
        ``F_ext(t)``, N.
    tau, rate, period : float
        Motor lag (s, 0 = none), rate limit (m/s^2, inf = none) and controller period (s).
    lo, hi : float, m/s
        Speed limits of the commands.
    start : ndarray of shape (n,), m/s
        Contact speeds (and commands, motors settled) at ``t = 0``.
    v0 : float, m/s
    K : int
        Number of periods.
    pinned : bool
        The first period keeps ``start`` (dynamic motors: new commands act from ``period``).
    reference : callable
        ``V_ref(t)`` for arrays of times, m/s.
    project : callable
        ``project(u, v) -> u``: rows of commands onto the motor model for rows of contact
        speeds (speed limits, ``|u - v| <= r tau``).
    squared : bool
        Rank candidates by the squared error only (braking as fast as possible) instead of
        the sup error first.

    Returns
    -------
    Construction
    """
    n = start.size
    # Fraction of a gap the lag leaves after one period (the motor law at s = period).
    d = float(unsaturated_response(1.0, 0.0, period, tau, math.inf)) if tau > 0 else 0.0
    kappa = _steady_shift(tau, period)
    shifts = tuple(sorted(set((*_SHIFTS, -kappa, -2.0 * kappa))))
    h = period / _STEPS
    offsets = h * np.arange(1, _STEPS + 1)

    def follow(P: np.ndarray, v: np.ndarray) -> np.ndarray:
        return project((P[:, None] - d * v) / (1.0 - d), v)

    def run(V: np.ndarray, v: np.ndarray, u: np.ndarray, t0: float) -> tuple[np.ndarray, ...]:
        """Body speeds at the substeps (C, S) and the end states, one period from t0."""
        out = np.empty((V.size, _STEPS))
        for j, s in enumerate(offsets):
            V = implicit_step(V, unsaturated_response(v, u, s, tau, rate), forces, mass,
                              damping, external(t0 + s - 0.5 * h), h)
            out[:, j] = V
        return out, V, unsaturated_response(v, u, period, tau, rate)

    ahead_shifts = np.array(sorted({0.0, -kappa, 0.5}))
    commands = np.empty((K, n))
    speeds = [start.copy()]
    body = [float(v0)]
    choices = []
    V, v = np.array([float(v0)]), start[None, :].copy()
    for k in range(K):
        t0 = k * period
        if k == 0 and pinned:
            u = start[None, :].copy()
            choices.append("pinned")
        else:
            R1, R0 = float(reference(t0 + period)), float(reference(t0))
            targets = np.array([R1 + s * (R1 - R0) for s in shifts])
            vv = np.repeat(v, targets.size, axis=0)
            plain = follow(targets, vv)
            # Contacts on the wrong side of the body are sent across it: to a fraction of
            # the way from the body to the speed limit beyond the target.
            up = (targets >= V[0])[:, None]
            wrong = np.where(up, vv <= V[0], vv >= V[0])
            limit = np.where(up, hi, lo)
            pushed = [project(np.where(wrong, V[0] + share * (limit - V[0]), plain), vv)
                      for share in _SHARES]
            names = ([f"follow {s:+.3f} dR" for s in shifts]
                     + [f"follow {s:+.3f} dR, wrong side {share:g} of the way to the limit"
                        for share in _SHARES for s in shifts]
                     + ["push up", "push down"])
            cand = np.vstack((plain, *pushed, project(np.full((2, n), [[hi], [lo]]),
                                                      np.repeat(v, 2, axis=0))))
            C = cand.shape[0]
            path, V1, v1 = run(np.repeat(V, C), np.repeat(v, C, axis=0), cand, t0)
            R2 = float(reference(t0 + 2 * period))
            A = ahead_shifts.size
            ahead = follow(np.tile(R2 + ahead_shifts * (R2 - R1), C), np.repeat(v1, A, axis=0))
            path2, Vj, vj = run(np.repeat(V1, A), np.repeat(v1, A, axis=0), ahead, t0 + period)
            pieces = [np.repeat(path, A, axis=0), path2]
            for j in range(2, _AHEAD + 1):                  # then the steady follow policy
                Rn, Rp = (float(reference(t0 + (j + 1) * period)),
                          float(reference(t0 + j * period)))
                steady = follow(np.full(C * A, Rn - kappa * (Rn - Rp)), vj)
                piece, Vj, vj = run(Vj, vj, steady, t0 + j * period)
                pieces.append(piece)
            times = t0 + np.concatenate([j * period + offsets for j in range(_AHEAD + 1)])
            miss = np.hstack(pieces) - reference(times)[None, :]
            # Rows are (candidate, first look-ahead shift) pairs: rank them, keep the candidate.
            l2 = np.sum(miss ** 2, axis=1)
            if squared:
                row = int(np.argmin(l2))
            else:
                sup = np.max(np.abs(miss), axis=1)
                near = np.flatnonzero(sup <= sup.min() + _TIE)
                row = int(near[np.argmin(l2[near])])
            best = row // A
            u = cand[best:best + 1]
            choices.append(names[best])
        commands[k] = u[0]
        if choices[-1] == "pinned":
            _, V, v = run(V, v, u, t0)
        else:                                              # the chosen row's own end state
            V, v = V1[best:best + 1], v1[best:best + 1]
        speeds.append(v[0].copy())
        body.append(float(V[0]))
    return Construction(commands, np.array(speeds), np.array(body), tuple(choices))


def speed_rate(push: Any, damping: float, speed: Any, mass: float, h: Any) -> Any:
    """Bound on ``|V'|`` (m/s^2) over an interval of length ``h`` (s) starting at ``|V| <= speed``.

    ``m V' = F + F_ext - c V`` with ``|F + F_ext| <= push`` (N). While ``|V| <= speed + A s``
    the slope is at most ``(push + c (speed + A h)) / m``, which equals ``A`` for
    ``A = (push + c speed) / (m - c h)`` (``c h < m``): a bootstrap bound. Otherwise (a drag
    time ``m / c`` below ``h``) by comparison ``|V| <= max(speed, push / c)`` throughout and
    ``A = (push + max(c speed, push)) / m``. Elementwise on arrays.
    """
    if damping <= 0:
        return np.asarray(push, dtype=float) / mass + 0.0 * np.asarray(h, dtype=float)
    short = damping * np.asarray(h, dtype=float) < 0.5 * mass
    bootstrap = (push + damping * speed) / np.where(short, mass - damping * h, mass)
    return np.where(short, bootstrap, (push + np.maximum(damping * speed, push)) / mass)


# -- certificate: the funnel of the extreme forces -----------------------------------------------
def tracking_lower_bound(*, forces: np.ndarray, mass: float, damping: float,
                         external: Callable[[float], float], tau: float, rate: float,
                         lo: float, hi: float, t: np.ndarray, reference: np.ndarray,
                         t_free: float, V_free: float, v_free: np.ndarray,
                         forced: float, grid: int = 48) -> float:
    """A certified lower bound on ``max_j |V(t_j) - reference_j|`` over every schedule.

    From ``t_free`` on (the first time a new command acts; before it the motion is forced
    and its error ``forced`` is given) each contact is at most as high as its fastest rise
    towards ``hi`` and at least as low as its fastest fall towards ``lo``
    (:func:`toolkit.model.motors.reach`), so ``m V' <= F_up(t, V) + F_ext - c V`` with
    ``F_up`` the Coulomb force of the highest contacts (and symmetrically below). For a tube
    half-width ``e`` the set of speeds reachable while ``|V(t_j) - reference_j| <= e`` at
    every sample is inside an interval whose ends follow these extreme rates (evaluated
    conservatively over each step, at the lowest/highest speed the body can reach within
    it: every step starts in the tube, so ``|V| <= max |reference| + e`` there, and
    :func:`speed_rate` bounds the in-step slope with drag) clipped to the tube; when it
    empties, no schedule achieves ``e``. The largest such ``e`` on a grid (refined twice) is returned: a valid lower bound, never above the
    true optimum.

    Parameters
    ----------
    forces : ndarray of shape (n,), N
    mass, damping : float
    external : callable
        ``F_ext(t)`` (N), constant between the sample times.
    tau, rate, lo, hi : float
        Motor lag (s), rate limit (m/s^2), speed limits (m/s).
    t : ndarray of shape (T,), s
        Sample times from ``t_free`` on, increasing (breakpoints of ``F_ext`` among them).
    reference : ndarray of shape (T,), m/s
    t_free, V_free : float
        s, m/s: the body speed when new commands start acting.
    v_free : ndarray of shape (n,), m/s
        Contact speeds then.
    forced : float, m/s
        The tracking error already forced before ``t_free``.
    grid : int
        Tube widths tried per refinement.

    Returns
    -------
    float, m/s
    """
    s = t - t_free
    up, down = reach(tau, rate, v_free, hi, s), reach(tau, rate, v_free, lo, s)
    f = forces
    total = float(f.sum())
    ext = np.array([external(0.5 * (a + b)) for a, b in zip(t[:-1], t[1:])])
    low_e = forced
    high_e = max(forced, float(np.max(np.abs(reference - V_free)))) + 1e-12
    # Every step starts inside the tube (|V| <= max |reference| + e <= ... + high_e) or at
    # V_free: within the step the speed changes at most at this rate (drag included).
    speed_cap = max(abs(V_free), float(np.max(np.abs(reference))) + high_e)
    h = np.diff(t)
    accel = speed_rate(total + np.abs(ext), damping, speed_cap, mass, h)

    def feasible(widths: np.ndarray) -> np.ndarray:
        a = np.full(widths.size, V_free)
        b = np.full(widths.size, V_free)
        ok = np.abs(V_free - reference[0]) <= widths
        for j in range(h.size):
            slack = accel[j] * h[j]
            low_b = b - slack                                     # lowest V in the step
            high_a = a + slack
            f_up = np.where(up[j + 1][None, :] >= low_b[:, None], 1.0, -1.0) @ f
            f_dn = np.where(down[j + 1][None, :] > high_a[:, None], 1.0, -1.0) @ f
            b_new = b + h[j] * (f_up + ext[j] - damping * low_b) / mass
            a_new = a + h[j] * (f_dn + ext[j] - damping * high_a) / mass
            b = np.minimum(b_new, reference[j + 1] + widths)
            a = np.maximum(a_new, reference[j + 1] - widths)
            ok &= a <= b
            if not ok.any():
                break
            a, b = np.minimum(a, b), np.maximum(a, b)
        return ok

    if feasible(np.array([low_e]))[0]:
        return forced
    for _ in range(2):
        widths = np.linspace(low_e, high_e, grid)
        ok = feasible(widths)
        first = int(np.argmax(ok)) if ok.any() else grid - 1
        low_e, high_e = float(widths[max(first - 1, 0)]), float(widths[first])
        if first == 0:
            break
    return low_e
