"""Allocation targets: what force-speed behaviour the contacts should produce.

Four frozen value objects, validated when built: :class:`ForceCurve` (samples, linear
between them, a repeated speed a vertical step), :class:`Viscosity`,
:class:`FrictionFraction` and :class:`EquilibriumSpeed`. Each becomes a :class:`ForceCurve`
over its band (:meth:`to_curve`), against which errors are measured. A target is only a
request: :func:`toolkit.allocation.allocate` projects an unrealizable one (and reports the
projection) or refuses it with ``strict=True``."""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from typing import Any, Protocol, Union, runtime_checkable

import numpy as np

from ..errors import as_float, as_float_array, as_int
from ..errors import ParameterError, ParameterTypeError, parameter_message

__all__ = ["ForceCurve", "Viscosity", "FrictionFraction", "EquilibriumSpeed", "Target",
           "parse_band"]


def parse_band(band: Any, name: str, owner: str, center: float = 0.0) -> tuple[float, float]:
    """Turn a half-width ``h`` (-> ``(center - h, center + h)``) or a pair ``(lo, hi)`` into a band.

    Parameters
    ----------
    band : float or pair of float, m/s
    name, owner : str
        For error messages.
    center : float, m/s
        Centre of a band given as a half-width.

    Returns
    -------
    (lo, hi) : tuple of float, m/s, with ``lo < hi``

    Raises
    ------
    ParameterError
        A half-width ``<= 0`` or a pair with ``lo >= hi``: a band of zero width would ask
        for a law at a single speed, which every staircase with its steps there meets with
        error 0 (a Coulomb step, not the requested law).
    """
    if isinstance(band, numbers.Real) and not isinstance(band, bool):
        half = as_float(band, name, owner, low=0.0, low_open=True)
        return center - half, center + half
    if isinstance(band, (str, bytes)) or not hasattr(band, "__len__"):
        raise ParameterTypeError(parameter_message(
            name, owner, "be a half-width or a pair (lo, hi) in m/s", band))
    pair = as_float_array(band, name, owner)
    if pair.size != 2:
        raise ParameterError(parameter_message(
            name, owner, "be a half-width or a pair (lo, hi) in m/s", band))
    lo, hi = float(pair[0]), float(pair[1])
    if not lo < hi:
        raise ParameterError(parameter_message(
            name, owner, "satisfy lo < hi (a band of positive width)", band))
    return lo, hi


@dataclass(frozen=True, eq=False)
class ForceCurve:
    """A target force-speed curve from samples, linear between them.

    Parameters
    ----------
    speeds : array_like of shape (k,), m/s
        Body speeds, finite and non-decreasing. The band of the target is
        ``[speeds[0], speeds[-1]]``. A speed given twice is a vertical step: the target is
        the whole interval between the two forces there (like a Coulomb contact).
    forces : array_like of shape (k,), N
        Target net force at each speed. Non-finite values are accepted here (a request can
        be unrealizable); :func:`~toolkit.allocation.allocate` projects or refuses them.
    weights : array_like of shape (k,), optional
        Non-negative quadrature weights (m/s) for the L1 error: with weights,
        ``error_l1 = sum_k weights[k] * |F_achieved(V_k) - F_target(V_k)|``; without,
        ``error_l1`` is the exact integral over the band.

    Examples
    --------
    >>> curve = ForceCurve([-0.35, 0.35], [3.0, -3.0])
    >>> curve.band
    (-0.35, 0.35)
    """

    speeds: np.ndarray
    forces: np.ndarray
    weights: np.ndarray | None = None

    def __post_init__(self) -> None:
        owner = "ForceCurve"
        speeds = as_float_array(self.speeds, "speeds", owner)
        forces = as_float_array(self.forces, "forces", owner, finite=False)
        if forces.shape != speeds.shape:
            raise ParameterError(parameter_message(
                "forces", owner, f"have the same length as 'speeds' ({speeds.size})",
                f"an array of length {forces.size}"))
        if np.any(np.diff(speeds) < 0):
            raise ParameterError(parameter_message(
                "speeds", owner, "be non-decreasing (sorted)", speeds.tolist()))
        object.__setattr__(self, "speeds", speeds)
        object.__setattr__(self, "forces", forces)
        if self.weights is not None:
            weights = as_float_array(self.weights, "weights", owner)
            if weights.shape != speeds.shape:
                raise ParameterError(parameter_message(
                    "weights", owner, f"have the same length as 'speeds' ({speeds.size})",
                    f"an array of length {weights.size}"))
            if np.any(weights < 0):
                raise ParameterError(parameter_message("weights", owner, "be >= 0",
                                                       float(weights[weights < 0][0])))
            object.__setattr__(self, "weights", weights)
        object.__setattr__(self, "_steps", bool(np.any(speeds[1:] == speeds[:-1])))

    @classmethod
    def _trusted(cls, speeds: np.ndarray, forces: np.ndarray) -> ForceCurve:
        """Build without validation from float arrays already known to be valid (sorted,
        equal lengths): curves the toolkit derives from validated ones. Private."""
        curve = object.__new__(cls)
        for name, array in (("speeds", speeds), ("forces", forces)):
            array = np.asarray(array, dtype=float)
            array.setflags(write=False)
            object.__setattr__(curve, name, array)
        object.__setattr__(curve, "weights", None)
        object.__setattr__(curve, "_steps", bool(np.any(curve.speeds[1:] == curve.speeds[:-1])))
        return curve

    @property
    def band(self) -> tuple[float, float]:
        """``(lo, hi)``: the range of body speeds the target covers, m/s."""
        return float(self.speeds[0]), float(self.speeds[-1])

    def to_curve(self, total_force: float, limits: tuple[float, float] | None = None
                 ) -> ForceCurve:
        """Return ``self`` (already a sampled curve)."""
        return self

    def value_right(self, V: Any) -> np.ndarray:
        """Right limit ``F(V+)`` of the target at speeds inside the band (N)."""
        if not self._steps:
            return _interp_continuous(self.speeds, self.forces, V)
        return _interp(self.speeds, self.forces, np.asarray(V, dtype=float), "right")

    def value_left(self, V: Any) -> np.ndarray:
        """Left limit ``F(V-)`` of the target at speeds inside the band (N)."""
        if not self._steps:
            return _interp_continuous(self.speeds, self.forces, V)
        return _interp(self.speeds, self.forces, np.asarray(V, dtype=float), "left")

    def restrict(self, lo: float, hi: float) -> ForceCurve:
        """The same curve cut to ``[lo, hi]`` (inside the band), weights dropped.

        ``self`` itself when that changes nothing (the whole band, no steps, no weights).
        """
        if (lo == self.speeds[0] and hi == self.speeds[-1] and not self._steps
                and self.weights is None):
            return self
        inner = (self.speeds > lo) & (self.speeds < hi)
        speeds = np.concatenate(([lo], self.speeds[inner], [hi]))
        forces = np.concatenate((self.value_right(lo)[None], self.forces[inner],
                                 self.value_left(hi)[None]))
        if lo == hi:
            speeds, forces = np.array([lo, lo]), np.array([float(self.value_left(lo)),
                                                           float(self.value_right(lo))])
        return ForceCurve._trusted(speeds, forces)


def _interp_continuous(xs: np.ndarray, ys: np.ndarray, x: Any) -> np.ndarray:
    """:func:`_interp` for a curve without repeated speeds (both limits agree), leaner.

    The same arithmetic as :func:`_interp` (``y0 + share (y1 - y0)``, the samples
    themselves at the sample speeds, the end values outside), so both give bitwise the
    same values, consistent with the inverse in ``_quantile.level_crossings``.
    """
    x = np.asarray(x, dtype=float)
    if xs.size == 1:
        return np.full(x.shape, ys[0])
    idx = np.searchsorted(xs, x, side="right").clip(1, xs.size - 1)
    x0, y0, y1 = xs[idx - 1], ys[idx - 1], ys[idx]
    share = ((x - x0) / (xs[idx] - x0)).clip(0.0, 1.0)
    return np.where(share >= 1.0, y1, y0 + share * (y1 - y0))


def _interp(xs: np.ndarray, ys: np.ndarray, x: np.ndarray, side: str) -> np.ndarray:
    """Piecewise-linear interpolation with one-sided limits at repeated abscissae.

    Uses segment ``[idx - 1, idx]`` with ``idx = searchsorted(xs, x, side)``, so at a repeated
    speed the left limit is the first sample there and the right limit the last one; values
    at segment ends are the samples themselves (no rounding).
    """
    if xs.size == 1:
        return np.full(np.shape(x), ys[0])
    idx = np.minimum(np.maximum(np.searchsorted(xs, x, side=side), 1), xs.size - 1)
    x0, x1, y0, y1 = xs[idx - 1], xs[idx], ys[idx - 1], ys[idx]
    width = x1 - x0
    flat = width <= 0
    share = (x - x0) / np.where(flat, 1.0, width)
    if side == "right":
        share = np.where(flat, 1.0, share)
    share = np.minimum(np.maximum(share, 0.0), 1.0)
    return np.where(share >= 1.0, y1, y0 + share * (y1 - y0))


@dataclass(frozen=True, eq=False)
class Viscosity:
    """An effective viscosity: ``F(V) = -slope (V - center)`` over a band.

    Parameters
    ----------
    slope : float, N s/m
        ``|dF/dV|``, ``>= 0``.
    center : float, m/s
        Speed of zero force (the equilibrium).
    band : float or pair of float, m/s
        Half-width ``> 0`` around ``center``, or ``(lo, hi)`` with ``lo < hi``: where the
        viscous law should hold.
    """

    slope: float
    center: float
    band: Any

    def __post_init__(self) -> None:
        owner = "Viscosity"
        object.__setattr__(self, "slope", as_float(self.slope, "slope", owner, low=0.0))
        object.__setattr__(self, "center", as_float(self.center, "center", owner))
        object.__setattr__(self, "band", parse_band(self.band, "band", owner, self.center))

    def to_curve(self, total_force: float, limits: tuple[float, float] | None = None
                 ) -> ForceCurve:
        """Two samples at the band ends (the law is linear)."""
        lo, hi = self.band
        speeds = np.array([lo, hi])
        return ForceCurve._trusted(speeds, -self.slope * (speeds - self.center))


@dataclass(frozen=True, eq=False)
class FrictionFraction:
    """A reduced (or reversed) friction: ``F(V) = -fraction * F_tot`` over a band.

    Parameters
    ----------
    fraction : float
        ``mu / mu0``: 1 is full friction against forward sliding, 0 no net friction,
        negative values push forward. ``|fraction| > 1`` is unrealizable and is projected
        (or refused with ``strict=True``) by :func:`~toolkit.allocation.allocate`.
    band : float or pair of float, m/s
        Half-width ``> 0`` around 0 (``v`` -> ``(-v, v)``) or ``(lo, hi)`` with ``lo < hi``:
        the sliding speeds.
    """

    fraction: float
    band: Any

    def __post_init__(self) -> None:
        owner = "FrictionFraction"
        object.__setattr__(self, "fraction", as_float(self.fraction, "fraction", owner))
        object.__setattr__(self, "band", parse_band(self.band, "band", owner))

    def to_curve(self, total_force: float, limits: tuple[float, float] | None = None
                 ) -> ForceCurve:
        """A constant ``-fraction * total_force`` over the band."""
        lo, hi = self.band
        level = -self.fraction * total_force
        return ForceCurve([lo, hi], [level, level])


@dataclass(frozen=True, eq=False)
class EquilibriumSpeed:
    """The body should settle at ``speed`` and stay there if ``margin`` contacts fail.

    The sampled form is the stiffest restoring law, a Coulomb step
    ``F(V) = F_tot sign(speed - V)`` over the speeds the contacts can reach: an allocation
    that matches it puts every contact at ``speed``.

    Parameters
    ----------
    speed : float, m/s
    margin : int, ``>= 0``
        Number of contacts that may fail (stop at any speed) without moving the equilibrium
        off ``speed``. An allocation satisfies it when the magnitude ``W`` at ``speed``,
        the magnitudes ``L`` below and ``U`` above it satisfy
        ``W >= |U - L| + 2 * (sum of the margin largest magnitudes)``.
    """

    speed: float
    margin: int = 0

    def __post_init__(self) -> None:
        owner = "EquilibriumSpeed"
        object.__setattr__(self, "speed", as_float(self.speed, "speed", owner))
        object.__setattr__(self, "margin", as_int(self.margin, "margin", owner, low=0))

    def to_curve(self, total_force: float, limits: tuple[float, float] | None = None
                 ) -> ForceCurve:
        """The step ``F_tot sign(speed - V)`` over ``limits`` widened to include ``speed``.

        ``limits`` defaults to ``speed +- 1 m/s``.
        """
        lo, hi = limits if limits is not None else (self.speed - 1.0, self.speed + 1.0)
        lo, hi = min(lo, self.speed), max(hi, self.speed)
        speeds = [lo, self.speed, self.speed, hi]
        forces = [total_force, total_force, -total_force, -total_force]
        if lo == self.speed:
            speeds, forces = speeds[1:], forces[1:]
        if hi == self.speed:
            speeds, forces = speeds[:-1], forces[:-1]
        return ForceCurve(speeds, forces)


Target = Union[ForceCurve, Viscosity, FrictionFraction, EquilibriumSpeed]


@runtime_checkable
class _HasCurve(Protocol):
    def to_curve(self, total_force: float, limits: tuple[float, float] | None = None
                 ) -> ForceCurve: ...
