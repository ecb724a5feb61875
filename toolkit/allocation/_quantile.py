"""The exact quantile construction for equal magnitudes (private): contact ``i`` at the
``(i - 1/2)/N`` quantile of the target written as a CDF, optimal, with its closed-form
error bound. The derivation: docs/methods.md and docs/physics.md section 8."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..errors import ParameterError, parameter_message
from ._evaluate import failure_margin, forced_error
from ._problem import AllocationProblem, AllocationResult, AllocationStatus, make_result
from .targets import EquilibriumSpeed, ForceCurve

__all__ = ["allocate_quantile", "quantile_applies", "quantile_speeds", "quantile_bound",
           "level_crossings"]


def quantile_applies(problem: AllocationProblem) -> bool:
    """True when all magnitudes are equal and positive, all boxes equal, nothing fixed,
    failed or liftable: the setting where the quantile construction is exact."""
    if problem.n == 0:
        return False
    forces = problem.forces
    lo, hi = problem.boxes()
    return bool(forces[0] > 0 and (forces == forces[0]).all() and (lo == lo[0]).all()
                and (hi == hi[0]).all()
                and not (problem.fixed | problem.failed | problem.liftable).any())


def _grid_distance(x: np.ndarray) -> np.ndarray:
    return np.abs(x - np.round(x))


def quantile_speeds(curve: ForceCurve, n: int, total_force: float) -> np.ndarray:
    """Speeds at the ``(i - 1/2)/n`` quantiles of ``G = (1 - F*/F_tot)/2`` on ``curve``'s band.

    Parameters
    ----------
    curve : ForceCurve
        Realizable (non-increasing, within ``+-F_tot``) target, N vs m/s.
    n : int
    total_force : float, N

    Returns
    -------
    ndarray of shape (n,), m/s, ascending; quantiles the band never reaches go to its ends.
    """
    p = (np.arange(1, n + 1) - 0.5) / n
    return level_crossings(curve, total_force * (1.0 - 2.0 * p))


def level_crossings(curve: ForceCurve, levels: np.ndarray) -> np.ndarray:
    """``inf {V in band : F*(V) <= level}`` for each level (N), on a non-increasing curve.

    Levels the curve never reaches go to the band's upper end; levels at or above the
    curve's start go to the lower end. Returns an ndarray of the shape of ``levels``, m/s.
    """
    xs = curve.speeds
    neg = np.maximum.accumulate(-curve.forces)   # guard against rounding in flat stretches
    target = -np.asarray(levels, dtype=float)
    k = np.searchsorted(neg, target, side="left")
    inner = (k > 0) & (k < xs.size)
    kk = np.minimum(np.maximum(k, 1), xs.size - 1)
    x0, x1, g0, g1 = xs[kk - 1], xs[kk], neg[kk - 1], neg[kk]
    rising = g1 > g0
    share = np.where(rising, (target - g0) / np.where(rising, g1 - g0, 1.0), 0.0)
    return np.where(inner, x0 + np.minimum(np.maximum(share, 0.0), 1.0) * (x1 - x0),
                    np.where(k == 0, xs[0], xs[-1]))


def quantile_bound(curve: ForceCurve, n: int, total_force: float,
                   box: tuple[float, float], inner: ForceCurve | None = None) -> float:
    """Closed-form optimal sup error (N) for ``n`` equal contacts sharing ``box`` (m/s).

    See the module docstring: the forced error outside the box and
    ``(2 F_tot / n) sup dist(n G, Z)`` inside it. ``inner`` may pass ``curve`` already
    restricted to the box (saves a copy).
    """
    lo, hi = curve.band
    bound = forced_error(curve, total_force, box)
    if box[0] > hi or box[1] < lo:                # every contact on one side of the band
        return bound
    low, high = max(lo, box[0]), min(hi, box[1])
    inner = curve.restrict(low, high) if inner is None else inner
    g = n * 0.5 * (1.0 - inner.forces / total_force)
    xs = inner.speeds
    wide = np.flatnonzero(xs[1:] > xs[:-1])
    if wide.size:
        g0, g1 = np.minimum(g[wide], g[wide + 1]), np.maximum(g[wide], g[wide + 1])
        half = np.ceil(g0 - 0.5) <= g1 - 0.5          # a half integer in [g0, g1]
        dist = np.where(half, 0.5, np.maximum(_grid_distance(g0), _grid_distance(g1)))
        worst = float(dist.max())
    else:                                          # a single speed: the target is an interval
        g_lo, g_hi = float(g.min()), float(g.max())
        worst = 0.0 if np.floor(g_hi) >= np.ceil(g_lo) else float(
            min(_grid_distance(np.array([g_lo, g_hi]))))
    return max(bound, 2.0 * total_force / n * worst)


def allocate_quantile(problem: AllocationProblem, start: float | None = None, *,
                      checked: bool = False) -> AllocationResult:
    """Solve ``problem`` by the quantile construction (equal magnitudes, one shared box).

    Raises
    ------
    ParameterError
        When the problem is outside the construction's setting (see :func:`quantile_applies`;
        ``checked=True``: the caller has just verified it).
    """
    start = time.perf_counter() if start is None else start
    if not checked and not quantile_applies(problem):
        raise ParameterError(parameter_message(
            "method", "allocate", "be 'milp' (or None) unless all contacts have equal "
            "magnitudes and one shared speed box and none is fixed, failed or liftable",
            "quantile"))
    n, total = problem.n, problem.total_force
    curve = problem.curve
    lo, hi = problem.boxes()
    box = (float(lo[0]), float(hi[0]))
    band_lo, band_hi = curve.band
    low, high = max(band_lo, box[0]), min(band_hi, box[1])
    inner = None
    if low > band_hi:
        speeds = np.full(n, box[0])
    elif high < band_lo:
        speeds = np.full(n, box[1])
    else:
        inner = curve.restrict(low, high)
        speeds = quantile_speeds(inner, n, total)
    bound = quantile_bound(curve, n, total, box, inner)
    # Quantile order is ascending; any assignment of the sorted speeds to equal contacts
    # is the same ContactSet. Keep the current order of contacts (least movement).
    order = np.argsort(problem.contacts.speeds, kind="stable")
    assigned = np.empty(n)
    assigned[order] = speeds
    result = make_result(problem, assigned, np.ones(n, dtype=bool), bound, "quantile", start,
                         gap_tolerance=1e-12)
    return _check_margin(problem, result)


def _check_margin(problem: AllocationProblem, result: AllocationResult) -> AllocationResult:
    target = problem.target
    if not isinstance(target, EquilibriumSpeed) or target.margin == 0:
        return result
    speed = float(problem.curve.speeds[np.argmax(np.diff(problem.curve.forces) < 0) + 1]) \
        if problem.curve.speeds.size > 1 else float(problem.curve.speeds[0])
    achieved = failure_margin(result.contacts, speed)
    if achieved >= target.margin:
        return result
    detail = (f"the equilibrium at {speed:g} m/s survives {max(achieved, 0)} failure(s), "
              f"fewer than the requested margin {target.margin}")
    return replace(result, status=AllocationStatus.INFEASIBLE,
                   message=f"{AllocationStatus.INFEASIBLE.value}; {detail}")
