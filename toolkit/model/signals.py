"""Signals of time: piecewise-constant external forces and contact-speed commands, and the
sample instants of a run at a rate."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import as_float_array
from ..errors import ParameterError, parameter_message

__all__ = ["PiecewiseConstant", "sample_count", "sample_times"]


def sample_count(duration: float, rate: float) -> int:
    """Samples of a run of ``duration`` s at ``rate`` Hz, both ends included: ``floor(duration
    rate) + 1``, where a product within a relative 1e-9 below a whole number counts as it
    (10 s at 50 Hz is 501 samples however the 10 s was rounded)."""
    return math.floor(duration * rate * (1.0 + 1e-9)) + 1


def sample_times(duration: float, rate: float) -> np.ndarray:
    """The sample instants ``k / rate`` (s), ``k`` from 0 to ``sample_count(duration, rate) - 1``:
    the one grid of every sampled run (encoder records, closed loops, python-control)."""
    return np.arange(sample_count(duration, rate)) / rate


@dataclass(frozen=True, eq=False)
class PiecewiseConstant:
    """A signal that is ``values[0]`` before ``times[0]``, ``values[j]`` on
    ``[times[j-1], times[j])`` and ``values[-1]`` from ``times[-1]`` on.

    Parameters
    ----------
    times : array_like of shape (k,), s
        Switching times, strictly increasing and finite (``k = 0`` gives a constant).
    values : array_like of shape (k + 1,) or (k + 1, n)
        The value on each piece: scalars (a scalar signal, e.g. a force in N) or rows of
        ``n`` values (a vector signal, e.g. contact speed commands in m/s). Finite.

    Examples
    --------
    >>> u = PiecewiseConstant([1.0, 2.0], [0.0, 3.0, -1.0])
    >>> u(0.5), u(1.0), u(5.0)
    (0.0, 3.0, -1.0)
    """

    times: np.ndarray
    values: np.ndarray

    def __post_init__(self) -> None:
        owner = "PiecewiseConstant"
        times = as_float_array(self.times, "times", owner, allow_empty=True)
        if np.any(np.diff(times) <= 0):
            raise ParameterError(parameter_message(
                "times", owner, "be strictly increasing", times.tolist()))
        try:
            ndim = 2 if np.ndim(self.values) >= 2 else 1
        except ValueError:                   # ragged nested lists
            ndim = 2
        values = as_float_array(self.values, "values", owner, ndim=ndim)
        if values.shape[0] != times.size + 1:
            raise ParameterError(parameter_message(
                "values", owner, f"have one more row than 'times' ({times.size + 1})",
                f"an array of shape {values.shape}"))
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)

    @property
    def width(self) -> int | None:
        """Number of components of a vector signal, ``None`` for a scalar signal."""
        return None if self.values.ndim == 1 else int(self.values.shape[1])

    def __call__(self, t: Any) -> Any:
        """The value at time(s) ``t`` (s).

        Returns
        -------
        float, ndarray of shape (n,), or ndarray of shape ``t.shape`` (+ ``(n,)``)
            A float for a scalar signal at a scalar time; a row for a vector signal.
        """
        query = np.asarray(t, dtype=float)
        index = np.searchsorted(self.times, query, side="right")
        result = self.values[index]
        if query.ndim == 0 and self.values.ndim == 1:
            return float(result)
        return np.array(result)

    def breakpoints_in(self, t0: float, t1: float) -> np.ndarray:
        """The switching times in the half-open interval ``(t0, t1]``, s, ascending."""
        lo = np.searchsorted(self.times, t0, side="right")
        hi = np.searchsorted(self.times, t1, side="right")
        return self.times[lo:hi].copy()

    def next_switch(self, t: float) -> float:
        """The first switching time strictly after ``t`` (s), ``inf`` if there is none."""
        index = int(np.searchsorted(self.times, t, side="right"))
        return float(self.times[index]) if index < self.times.size else float("inf")
