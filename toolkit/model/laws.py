"""The formulas that several layers evaluate, each written once.

Plain functions of floats or arrays over NumPy only, so that NumPy code calls them as they
are and the compiled kernels wrap them with ``numba.njit`` (this module imports nothing of
the toolkit: it is a leaf below the kernels).
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


def quantization_variance(resolution):
    """Variance of the position within one count cell, ``q^2 / 12`` (m^2).

    The variance of a uniform distribution over a cell of width ``q``.

    Parameters
    ----------
    resolution : float or ndarray, m
        Count size ``q``.
    """
    return resolution * resolution / 12.0


def lag_response(command, start, elapsed, lag):
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
    """
    return command + (start - command) * np.exp(-elapsed / lag)
