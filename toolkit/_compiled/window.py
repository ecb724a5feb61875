"""Kernels of first-order adaptive windowing (FOAW): the longest line the readings allow.

Compiled by :func:`toolkit._compiled.load` (``load("window")``); as written, this module
imports nothing but ``math`` and runs as Python (``NUMBA_DISABLE_JIT=1``).

Janabi-Sharifi, Hayward and Chen (IEEE TCST 8(6), 2000): the speed at sample ``k`` is the
slope of a line fitted to the last ``n + 1`` readings, with ``n`` the largest window (up to
``n_max``) such that every reading of the window lies within the uncertainty band ``d`` of
the line. End-fit: the line through the first and the last reading of the window (checked
at the readings between them). Best-fit: the least-squares line through all ``n + 1``
readings (checked at every reading of the window, since it passes through none of them in
general).
"""

from __future__ import annotations

KERNELS = {"foaw": {}}


def foaw(times, positions, m, band, best):  # noqa: ANN001, ANN201 (numba kernel)
    """Slope and window of FOAW over the ``m`` newest readings (oldest first in
    ``times[:m]``, ``positions[:m]``; the estimate is at ``times[m - 1]``).

    Returns ``(slope, n)``: the slope (position units per time unit) of the longest window
    ``n`` (``1 <= n <= m - 1``) whose readings lie within ``band`` of its line, ``(0.0, 0)``
    when ``m < 2``. The window grows from ``n = 1`` and stops at the first ``n`` that fails
    (the published rule; a longer window that would pass again is not searched).
    """
    k = m - 1
    slope = 0.0
    used = 0
    if m < 2:
        return slope, used
    tk = times[k]
    yk = positions[k]
    for n in range(1, m):
        if best:
            st = 0.0
            sy = 0.0
            for j in range(n + 1):
                st += times[k - j] - tk
                sy += positions[k - j] - yk
            tbar = st / (n + 1)
            ybar = sy / (n + 1)
            sxx = 0.0
            sxy = 0.0
            for j in range(n + 1):
                dt = times[k - j] - tk - tbar
                sxx += dt * dt
                sxy += dt * (positions[k - j] - yk - ybar)
            b = sxy / sxx
            a = ybar - b * tbar            # the line's value at t_k, relative to y_k
            first, last = 0, n + 1
        else:
            b = (yk - positions[k - n]) / (tk - times[k - n])
            a = 0.0
            first, last = 1, n
        bad = False
        for j in range(first, last):
            deviation = positions[k - j] - yk - (a + b * (times[k - j] - tk))
            if deviation > band or deviation < -band:
                bad = True
                break
        if bad:
            break
        slope = b
        used = n
    return slope, used
