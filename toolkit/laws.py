"""The formulas that several layers evaluate, each written once.

Plain functions of floats or arrays over NumPy only, so that NumPy code calls them as they
are and the compiled kernels (``toolkit._compiled``) compile them as they are: this module
imports nothing of the toolkit, the one module of the toolkit a kernel module may import.
The exponentials take the function to use (``exp``, ``expm1``): NumPy's on arrays, ``math``'s
on floats (the kernels: compiled code calls libm's, as ``math`` does, and NumPy's own vector
exponential may differ from it in the last bit).
"""

from __future__ import annotations

import numpy as np

EPS = float(np.finfo(np.float64).eps)


def tie_tolerance(levels, total):
    """Force below which a sum of ``levels`` signed contact forces counts as zero, N.

    ``4 (K + 1) eps F_tot``: a bound on the rounding error of a prefix sum of ``K + 1``
    terms each at most ``F_tot`` in magnitude.

    Parameters
    ----------
    levels : int
        Number ``K`` of distinct contact speeds (or breakpoints) summed over.
    total : float or ndarray, N
        ``F_tot``, the total friction force (or the largest magnitude summed).
    """
    return 4.0 * (levels + 1) * EPS * total


def cell_centre(count, resolution):
    """Position at the centre of an encoder's count cell, ``(c + 1/2) q`` (m).

    Parameters
    ----------
    count : int or ndarray
        Encoder count ``c = floor(x / q)``.
    resolution : float or ndarray, m
        Count size ``q``.
    """
    return (count + 0.5) * resolution


def quantization_variance(resolution, second=0.0):
    """Variance of the position within one count cell, ``q^2 / 12`` (m^2).

    The variance of a uniform distribution over a cell of width ``q``; with ``second``, that
    of the difference of two independent readings, ``(q^2 + q2^2) / 12``.

    Parameters
    ----------
    resolution : float or ndarray, m
        Count size ``q``.
    second : float or ndarray, m
        Count size ``q2`` of a second reading (0: one reading).
    """
    return (resolution * resolution + second * second) / 12.0


def lag_decay(elapsed, lag, exp=np.exp):
    """Share of a first-order motor's gap to its command left after ``s``, ``exp(-s / tau)``.

    The slope of :func:`lag_response` in the start speed.

    Parameters
    ----------
    elapsed : float or ndarray, s
        Time ``s >= 0`` since the command step.
    lag : float or ndarray, s
        Time constant ``tau > 0``.
    exp : callable
        The exponential (``numpy.exp`` on arrays, ``math.exp`` on floats).
    """
    return exp(-elapsed / lag)


def lag_response(command, start, elapsed, lag, exp=np.exp):
    """Speed of a first-order motor ``s`` after a command step, ``u + (v0 - u) exp(-s / tau)``.

    Parameters
    ----------
    command : float or ndarray, m/s
        Commanded speed ``u``.
    start : float or ndarray, m/s
        Speed ``v0`` at the step.
    elapsed : float or ndarray, s
        Time ``s >= 0`` since the step.
    lag : float or ndarray, s
        Time constant ``tau > 0``.
    exp : callable
        The exponential (``numpy.exp`` on arrays, ``math.exp`` on floats).
    """
    return command + (start - command) * exp(-elapsed / lag)


def lag_travel(command, start, elapsed, lag, expm1=np.expm1):
    """Distance a first-order motor travels in the ``s`` after a command step (m): the
    integral of :func:`lag_response`, ``u s + (v0 - u) tau (1 - exp(-s / tau))``.

    Parameters
    ----------
    command, start : float or ndarray, m/s
        ``u`` and ``v0`` as in :func:`lag_response`.
    elapsed : float or ndarray, s
        ``s >= 0``.
    lag : float or ndarray, s
        ``tau > 0``.
    expm1 : callable
        ``exp(x) - 1`` (``numpy.expm1`` on arrays, ``math.expm1`` on floats).
    """
    return command * elapsed + (start - command) * (lag * -expm1(-elapsed / lag))


def implicit_step(levels, plateaus, a, b, k=None):
    """One implicit (Moreau) step of ``m V' in F(V) + F_ext - c V``: the new speed ``W``.

    Solves ``a W - b in F(W)`` with ``a = m / h + c`` and ``b = m V / h + F_ext`` on the
    staircase of ``F``: levels ``s_k`` (ascending) and plateau forces ``P_k`` below ``s_k``
    and ``P_{k+1}`` above (non-increasing). ``a W - b`` increases and ``F`` does not, so the
    solution is unique: the first level whose upper end ``a s_k - P_{k+1}`` reaches ``b`` if
    its lower end ``a s_k - P_k`` is at most ``b`` (the body sticks there), else the open
    plateau before it, ``W = (b + P_k) / a``.

    Parameters
    ----------
    levels : ndarray of shape (K,) or (R, K), m/s
        One staircase, or one per row (repeated levels allowed).
    plateaus : ndarray of shape (K + 1,) or (R, K + 1), N
    a : float, N s/m
        ``m / h + c > 0``.
    b : float or ndarray of shape (R,), N
    k : int, optional
        One staircase only: the number of levels whose upper end is below ``b``, when the
        caller has searched already.

    Returns
    -------
    W : float or ndarray of shape (R,), m/s
    stuck : bool or ndarray of shape (R,)
        True where ``W`` is a level (the set-valued force was used).
    """
    if np.ndim(levels) == 1:
        if k is None:
            k = int(np.searchsorted(a * levels - plateaus[1:], b, side="left"))
        if k < levels.size and a * levels[k] - plateaus[k] <= b:
            return float(levels[k]), True
        return float((b + plateaus[k]) / a), False
    b = np.asarray(b, dtype=float)
    count = np.sum(a * levels - plateaus[..., 1:] < b[..., None], axis=-1)
    rows = np.arange(levels.shape[0])
    level = levels[rows, np.minimum(count, levels.shape[-1] - 1)]
    plateau = plateaus[rows, count]
    stuck = (count < levels.shape[-1]) & (a * level - plateau <= b)
    return np.where(stuck, level, (b + plateau) / a), stuck
