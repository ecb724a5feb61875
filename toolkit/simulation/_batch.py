"""Many constant-speed scenes at once: the exact method vectorized over scenes with NumPy.

Each scene is a body from ``V(0) = v0`` on its own contacts (constant speeds, ideal motors,
no external force, optional drag). The exact method visits at most ``N`` contact speeds per
scene and does ``O(1)`` work at each, so the batch loop runs at most ``2 N + 2`` vectorized
rounds: in each, every unfinished scene either decides at a contact speed (stick or pass,
the rule of :mod:`toolkit.simulation._exact`) or moves in closed form to the next one.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import as_float, as_float_array, check_nonnegative
from ..errors import ParameterError, parameter_message
from ._result import SimulationStatus, status_message

__all__ = ["BatchResult", "simulate_batch"]

_EPS = float(np.finfo(float).eps)
_OWNER = "simulate_batch"


@dataclass(frozen=True, eq=False)
class BatchResult:
    """Final state of every scene of :func:`simulate_batch`.

    Attributes
    ----------
    final_speeds : ndarray of shape (scenes,), m/s
        Body speed at ``t_end``.
    n_events : ndarray of shape (scenes,), int
        Events of each scene (crossings and sticks, counted as the exact method does).
    stuck : ndarray of shape (scenes,), bool
        True where the body ends stuck at a contact speed (sliding mode).
    status : SimulationStatus
    message : str
    wall_time : float, s
    """

    final_speeds: np.ndarray
    n_events: np.ndarray
    stuck: np.ndarray
    status: SimulationStatus
    message: str
    wall_time: float

    def __post_init__(self) -> None:
        for name in ("final_speeds", "n_events", "stuck"):
            array = np.array(getattr(self, name))
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @property
    def success(self) -> bool:
        """True when every scene reached ``t_end``."""
        return self.status is SimulationStatus.SUCCESS

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: ``final_speeds``, ``n_events``, ``stuck`` (lists), ``status`` (name),
        ``message``, ``wall_time``."""
        return {"final_speeds": self.final_speeds.tolist(), "n_events": self.n_events.tolist(),
                "stuck": self.stuck.tolist(), "status": self.status.name,
                "message": self.message, "wall_time": self.wall_time}

    @property
    def n_scenes(self) -> int:
        """Number of scenes."""
        return int(self.final_speeds.size)


def _per_scene(value: Any, name: str, scenes: int, low: float | None,
               low_open: bool = False) -> np.ndarray:
    if np.ndim(value) == 0:
        scalar = as_float(value, name, _OWNER, low=low, low_open=low_open)
        return np.full(scenes, scalar)
    array = as_float_array(value, name, _OWNER)
    if array.size != scenes:
        raise ParameterError(parameter_message(
            name, _OWNER, f"be a scalar or have one entry per scene ({scenes})",
            f"an array of length {array.size}"))
    if low is not None and (np.any(array <= low) if low_open else np.any(array < low)):
        raise ParameterError(parameter_message(
            name, _OWNER, f"be {'>' if low_open else '>='} {low:g}", array.min().item()))
    return array


def simulate_batch(speeds: Any, forces: Any, mass: Any, t_end: float, *, v0: Any = 0.0,
                   damping: Any = 0.0) -> BatchResult:
    """Simulate many scenes of constant contact speeds exactly, vectorized over scenes.

    Parameters
    ----------
    speeds : array_like of shape (scenes, N), m/s
        Contact speeds of each scene (finite).
    forces : array_like of shape (scenes, N), N, or None
        Friction magnitudes ``f_i >= 0`` with a positive sum per scene; ``None`` = 1 N each.
    mass : float or array_like of shape (scenes,), kg
        Moving inertia, ``> 0``.
    t_end : float, s
        Horizon, ``> 0``.
    v0 : float or array_like of shape (scenes,), m/s
        Initial body speeds.
    damping : float or array_like of shape (scenes,), N s/m
        Bearing drag ``c >= 0``.

    Returns
    -------
    BatchResult
        Final speeds equal the single-run exact method (``simulate(..., method="exact")``)
        to rounding; event counts equal its event counts.

    Examples
    --------
    >>> result = simulate_batch([[-1.0, 0.5, 2.0], [0.0, 1.0, 3.0]], None, 1.0, 5.0)
    >>> result.final_speeds.tolist()
    [0.5, 1.0]
    """
    started = time.perf_counter()
    v = as_float_array(speeds, "speeds", _OWNER, ndim=2)
    S, N = v.shape
    if forces is None:
        f = np.ones_like(v)
    else:
        f = as_float_array(forces, "forces", _OWNER, ndim=2)
        check_nonnegative(f, "forces", _OWNER)
        if f.shape != v.shape:
            raise ParameterError(parameter_message(
                "forces", _OWNER, f"have the shape of 'speeds' {v.shape}", f"shape {f.shape}"))
    m = _per_scene(mass, "mass", S, 0.0, low_open=True)
    c = _per_scene(damping, "damping", S, 0.0)
    V = _per_scene(v0, "v0", S, None).copy()
    t_end = as_float(t_end, "t_end", _OWNER, low=0.0, low_open=True)

    # Sort each scene; lifted contacts (f = 0) go to +inf where nothing reaches them.
    v = np.where(f > 0, v, np.inf)
    order = np.argsort(v, axis=1, kind="stable")
    v = np.take_along_axis(v, order, axis=1)
    f = np.take_along_axis(f, order, axis=1)
    csum = np.concatenate((np.zeros((S, 1)), np.cumsum(f, axis=1)), axis=1)
    total = csum[:, -1]
    if np.any(total <= 0):
        bad = int(np.flatnonzero(total <= 0)[0])
        raise ParameterError(parameter_message(
            "forces", _OWNER, "have a positive sum in every scene", f"scene {bad} with sum 0"))
    tol = 4.0 * (N + 1) * _EPS * total
    positions = np.arange(N)
    new = np.ones((S, N), dtype=bool)
    new[:, 1:] = v[:, 1:] != v[:, :-1]
    start = np.maximum.accumulate(np.where(new, positions, 0), axis=1)          # group start
    last = np.where(np.append(new[:, 1:], np.ones((S, 1), dtype=bool), axis=1), positions, N)
    end = np.minimum.accumulate(last[:, ::-1], axis=1)[:, ::-1] + 1             # group end
    rows = np.arange(S)
    plateau = total[:, None] - 2.0 * csum                                       # (S, N + 1)
    plateau = np.where(np.abs(plateau) <= tol[:, None], 0.0, plateau)
    lam = c / m

    t = np.zeros(S)
    j = np.sum(v < V[:, None], axis=1)                  # interval index, or level position
    at = (j < N) & (v[rows, np.minimum(j, N - 1)] == V)
    active = np.ones(S, dtype=bool)
    stuck = np.zeros(S, dtype=bool)
    events = np.zeros(S, dtype=np.int64)
    for _ in range(2 * N + 2):
        idx = np.flatnonzero(active & at)
        if idx.size:                                    # decide at a contact speed
            p = j[idx]
            lo, hi = start[idx, p], end[idx, p]
            W = csum[idx, hi] - csum[idx, lo]
            G = (total[idx] - csum[idx, hi]) - csum[idx, lo]
            G = np.where(np.abs(G) <= tol[idx], 0.0, G) - c[idx] * V[idx]
            bound = W + 4.0 * (N + 1) * _EPS * (total[idx] + c[idx] * np.abs(V[idx]))
            events[idx] += 1
            stays = np.abs(G) <= bound
            stuck[idx[stays]] = True
            active[idx[stays]] = False
            at[idx] = False
            j[idx] = np.where(G > 0, hi, lo)
        idx = np.flatnonzero(active & ~at)
        if not idx.size:
            break
        jj, Vi, ci, mi = j[idx], V[idx], c[idx], m[idx]
        r0 = (plateau[idx, jj] - ci * Vi) / mi
        li = lam[idx]
        up = r0 > 0
        target = np.where(up, v[idx, np.minimum(jj, N - 1)], v[idx, np.maximum(jj - 1, 0)])
        target = np.where(up & (jj == N), np.inf, np.where(~up & (jj == 0), -np.inf, target))
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            y = (target - Vi) / r0
            x = li * y
            reach = np.where(li > 0, np.where(x < 1.0, -np.log1p(-np.minimum(x, 1.0)) / np.where(
                li > 0, li, 1.0), np.inf), y)
        reach = np.where(np.isfinite(target) & (r0 != 0), reach, np.inf)
        finish = t[idx] + reach >= t_end
        # Scenes that end inside their interval (or coast with r0 = 0).
        fin = idx[finish]
        rest = (t_end - t[fin])
        with np.errstate(divide="ignore", invalid="ignore"):
            lf = lam[fin]
            em = np.where(lf > 0, -np.expm1(-lf * rest) / np.where(lf > 0, lf, 1.0), rest)
        moved = V[fin] + r0[finish] * em
        low = np.where(j[fin] > 0, v[fin, np.maximum(j[fin] - 1, 0)], -np.inf)
        high = np.where(j[fin] < N, v[fin, np.minimum(j[fin], N - 1)], np.inf)
        V[fin] = np.minimum(np.maximum(moved, low), high)
        active[fin] = False
        # Scenes that reach the next contact speed.
        go = idx[~finish]
        t[go] += reach[~finish]
        V[go] = target[~finish]
        at[go] = True
        down = go[~up[~finish]]
        j[down] = start[down, j[down] - 1]
    status = SimulationStatus.SUCCESS if not active.any() else SimulationStatus.MAX_STEPS
    return BatchResult(V, events, stuck, status,
                       status_message(status, f"{S} scenes, {int(events.sum())} events"),
                       time.perf_counter() - started)
