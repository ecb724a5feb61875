"""Planar contact sets: the force and torque of Coulomb contacts that slip in the plane.

Contact ``i`` sits at ``r_i`` (m, relative to the body's reference point), moves with its
own velocity ``v_i`` (m/s: the body velocity at ``r_i`` at which it would not slip) and
carries a friction magnitude ``f_i`` (N). For a body twist ``(V, omega)`` its slip is
``s_i = v_i - (V + omega J r_i)`` and it pushes the body with ``f_i s_i / |s_i|``, or with
``f_i M_i s_i / sqrt(s_i^T M_i s_i)`` for an elliptical (anisotropic) limit surface
``M_i``. At zero slip the force is set-valued (the disc or ellipse of friction). The net
force and torque are minus the gradient of the dissipation potential
``Phi(V, omega) = sum f_i sqrt(s_i^T M_i s_i)`` (docs/planar.md section 1).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._compiled import kernels
from ..errors import (ParameterError, ParameterTypeError, as_float, as_float_array, check_nonnegative,
                      parameter_message)
from ..model import ContactSet
from ..laws import tie_tolerance
from .equilibrium import PlanarEquilibrium, _canonical, solve_equilibrium

__all__ = ["PlanarContactSet", "WrenchSet", "LineReduction", "limit_factors", "wrench_batch", "geometric_median"]

_EPS = float(np.finfo(float).eps)
_NO_LIMITS = np.zeros((0, 2, 2))
_NO_LIMITS.setflags(write=False)


def _as_points(value: Any, name: str, owner: str, n: int | None = None) -> np.ndarray:
    """An (n, 2) read-only float array (a single (2,) point is refused: say which contact)."""
    array = as_float_array(value, name, owner, ndim=2)
    if array.shape[1] != 2 or (n is not None and array.shape[0] != n):
        rows = "n" if n is None else str(n)
        raise ParameterError(parameter_message(
            name, owner, f"have shape ({rows}, 2) (one planar vector per contact)",
            f"an array of shape {array.shape}"))
    return array


def limit_factors(anisotropy: Any, n: int, owner: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Factors ``D_i`` (``M_i = D_i D_i^T``) and limit matrices ``M_i`` of n contacts.

    Parameters
    ----------
    anisotropy : None, array_like of shape (n, 2) or (n, 2, 2)
        ``None``: isotropic (``M_i = I``). Shape (n, 2): per contact the axis angle (rad,
        from the x axis) and the ratio ``k_i > 0`` of the friction across the axis to the
        friction along it, ``M_i = R diag(1, k_i^2) R^T``. Shape (n, 2, 2): symmetric
        positive definite ``M_i`` (dimensionless; the force limit set is
        ``{F : F^T M_i^{-1} F <= f_i^2}``).
    n : int
    owner : str
        The caller's name, for error messages.

    Returns
    -------
    dmat : ndarray of shape (n, 2, 2), or (0, 2, 2) when isotropic
    limits : ndarray of shape (n, 2, 2) or None
    """
    if anisotropy is None:
        return _NO_LIMITS, None
    try:
        array = None if isinstance(anisotropy, (str, bytes)) else np.asarray(anisotropy, dtype=float)
    except (TypeError, ValueError):             # (not numbers, or a ragged list)
        array = None
    if array is None:
        raise ParameterTypeError(parameter_message(
            "anisotropy", owner, "be None or an array of numbers", anisotropy))
    if not np.all(np.isfinite(array)):
        raise ParameterError(parameter_message("anisotropy", owner, "be finite", anisotropy))
    if array.shape == (n, 2):
        angle, ratio = array[:, 0], array[:, 1]
        if np.any(ratio <= 0):
            raise ParameterError(parameter_message(
                "anisotropy", owner, "have a positive ratio (second column) for every contact",
                float(ratio[ratio <= 0][0])))
        cos, sin = np.cos(angle), np.sin(angle)
        rot = np.stack((np.column_stack((cos, -sin)), np.column_stack((sin, cos))), 1)   # R (n,2,2)
        dmat = rot * np.column_stack((np.ones(n), ratio))[:, None, :]                # R diag(1, k)
    elif array.shape == (n, 2, 2):
        if not np.allclose(array, np.swapaxes(array, 1, 2), rtol=1e-12, atol=0.0):
            raise ParameterError(parameter_message(
                "anisotropy", owner, "hold symmetric 2 x 2 matrices", "a non-symmetric matrix"))
        sym = 0.5 * (array + np.swapaxes(array, 1, 2))
        if np.any(np.linalg.eigvalsh(sym)[:, 0] <= 0):
            raise ParameterError(parameter_message(
                "anisotropy", owner, "hold positive definite 2 x 2 matrices",
                "a matrix with an eigenvalue <= 0"))
        dmat = np.linalg.cholesky(sym)
    else:
        raise ParameterError(parameter_message(
            "anisotropy", owner, f"have shape ({n}, 2) (angle, ratio) or ({n}, 2, 2) (matrices)",
            f"an array of shape {array.shape}"))
    dmat = np.ascontiguousarray(dmat)
    limits = dmat @ np.swapaxes(dmat, 1, 2)
    dmat.setflags(write=False)
    limits.setflags(write=False)
    return dmat, limits


def _as_twists(V: Any, omega: Any, owner: str) -> tuple[np.ndarray, np.ndarray]:
    """Broadcast body velocities (..., 2) and angular velocities (...) to one batch shape."""
    arrays = []
    for name, value, unit in (("V", V, "m/s"), ("omega", omega, "rad/s")):
        try:
            real = not (value is None or isinstance(value, (str, bytes)) or np.iscomplexobj(value))
            array = np.asarray(value, dtype=float) if real else None
        except (TypeError, ValueError):           # (a ragged list: numpy's ValueError)
            array = None
        if array is None:
            raise ParameterTypeError(parameter_message(name, owner, f"be real numbers ({unit})", value))
        arrays.append(array)
        if not np.all(np.isfinite(arrays[-1])):
            raise ParameterError(parameter_message(name, owner, "be finite", "a NaN or inf entry"))
    vel, rate = arrays
    if vel.ndim == 0 or vel.shape[-1] != 2:
        raise ParameterError(parameter_message(
            "V", owner, "have a last axis of length 2 (vx, vy)", f"an array of shape {vel.shape}"))
    try:
        shape = np.broadcast_shapes(vel.shape[:-1], rate.shape)
    except ValueError:
        raise ParameterError(parameter_message(
            "omega", owner, f"broadcast against V's batch shape {vel.shape[:-1]}",
            f"an array of shape {rate.shape}")) from None
    return np.broadcast_to(vel, shape + (2,)), np.broadcast_to(rate, shape)


@dataclass(frozen=True)
class LineReduction:
    """A planar contact set whose contacts and motion lie on one line, as a 1-D set.

    Attributes
    ----------
    contacts : ContactSet
        Speeds ``u_i = v_i . e`` (m/s) and magnitudes ``f_i |D_i^T e|`` (N) along the line.
    origin : ndarray of shape (2,), m
        A point of the line of the positions.
    direction : ndarray of shape (2,)
        Its unit direction ``e`` (first non-zero component positive).
    """

    contacts: ContactSet
    origin: np.ndarray
    direction: np.ndarray


@dataclass(frozen=True, eq=False)
class WrenchSet:
    """The set of net wrenches at one twist: the sliding contacts' wrench plus the friction
    discs (or ellipses) of the contacts that do not slip.

    Attributes
    ----------
    force : ndarray of shape (2,), N
        Net force of the sliding contacts (the centre of the set; :meth:`PlanarContactSet.wrench`).
    torque : float, N m
        Their net torque about the reference point.
    stuck : ndarray of shape (k,), int
        Indices of the contacts with zero slip.
    positions : ndarray of shape (k, 2), m
    forces : ndarray of shape (k,), N
    dmat : ndarray of shape (k, 2, 2) or (0, 2, 2)
        The stuck contacts' positions, magnitudes and limit factors.
    """

    force: np.ndarray
    torque: float
    stuck: np.ndarray
    positions: np.ndarray
    forces: np.ndarray
    dmat: np.ndarray

    def support(self, direction: Any) -> np.ndarray:
        """Support function ``max d . w`` over the set's wrenches ``w = (Fx, Fy, tau)``.

        Parameters
        ----------
        direction : array_like of shape (..., 3)
            ``d = (a_x, a_y, b)``, weights of the force (1/N) and torque (1/(N m)) components.

        Returns
        -------
        ndarray of shape (...)
            ``d . w_centre + sum_k f_k |D_k^T (a + b J r_k)|`` (docs/planar.md section 1).
        """
        d = np.asarray(direction, dtype=float)
        if d.ndim == 0 or d.shape[-1] != 3:
            raise ParameterError(parameter_message(
                "direction", "WrenchSet.support", "have a last axis of length 3", f"shape {d.shape}"))
        centre = d[..., 0] * self.force[0] + d[..., 1] * self.force[1] + d[..., 2] * self.torque
        if self.stuck.size == 0:
            return centre
        r = self.positions
        ax = d[..., 0, None] - d[..., 2, None] * r[:, 1]       # a + b J r_k, (..., k)
        ay = d[..., 1, None] + d[..., 2, None] * r[:, 0]
        if self.dmat.shape[0]:
            zx = self.dmat[:, 0, 0] * ax + self.dmat[:, 1, 0] * ay
            zy = self.dmat[:, 0, 1] * ax + self.dmat[:, 1, 1] * ay
        else:
            zx, zy = ax, ay
        return centre + np.sum(self.forces * np.hypot(zx, zy), axis=-1)

    def bounds(self, direction: Any) -> tuple[float, float]:
        """``(min, max)`` of ``d . w`` over the set, for one ``d`` of shape (3,).

        With ``d = (1, 0, 0)`` and every contact on the x axis this is
        :meth:`toolkit.ContactSet.force_bounds` of the 1-D set.
        """
        return float(-self.support(np.negative(direction))), float(self.support(direction))


@dataclass(frozen=True, eq=False)
class PlanarContactSet:
    """Active contacts in the plane: positions, velocities, friction magnitudes, limit surfaces.

    Parameters
    ----------
    positions : array_like of shape (n, 2), m
        Contact points relative to the body's reference point (the point whose velocity is
        ``V``, about which torques are taken; the centre of mass in a simulation).
    velocities : array_like of shape (n, 2), m/s
        ``v_i``: the body velocity at ``r_i`` at which contact ``i`` does not slip (a foot
        that sweeps backwards at ``u`` relative to the body has ``v_i = +u``; a passive
        contact on fixed ground has ``v_i = 0``).
    forces : array_like of shape (n,), N, optional
        Friction magnitudes ``f_i = mu_i N_i >= 0`` (along the axis when anisotropic), with a
        positive sum; a zero is a lifted contact. Default 1 N each.
    anisotropy : None or array_like of shape (n, 2) or (n, 2, 2)
        Elliptical limit surfaces, see :func:`limit_factors`: ``(angle, ratio)`` per contact
        (ratio = friction across the axis / along it) or SPD matrices ``M_i``.

    Notes
    -----
    Ties: a contact whose slip is exactly zero contributes nothing to :meth:`wrench` (the
    centre of its set-valued force, as ``sign(0) = 0`` in :meth:`toolkit.ContactSet.force`);
    :meth:`wrench_set` returns the whole set. Net force components below
    :attr:`tie_tolerance` (and torques below ``tie_tolerance`` times the largest ``|r_i|``)
    are exactly 0, so contacts that cancel give an exact zero, as in the 1-D set.
    """

    positions: np.ndarray
    velocities: np.ndarray
    forces: np.ndarray
    limits: np.ndarray | None = None
    _dmat: np.ndarray = field(init=False, repr=False)
    _total: float = field(init=False, repr=False)

    def __init__(self, positions: Any, velocities: Any, forces: Any = None,
                 anisotropy: Any = None) -> None:
        owner = "PlanarContactSet"
        pos = _as_points(positions, "positions", owner)
        n = pos.shape[0]
        vel = _as_points(velocities, "velocities", owner, n)
        if forces is None:
            mag = np.ones(n)
            mag.setflags(write=False)
        else:
            mag = as_float_array(forces, "forces", owner)
            check_nonnegative(mag, "forces", owner)
            if mag.shape != (n,):
                raise ParameterError(parameter_message(
                    "forces", owner, f"have one magnitude per contact ({n})",
                    f"an array of length {mag.size}"))
        with np.errstate(over="ignore"):
            total = float(np.sum(mag))
        if not np.isfinite(total):
            raise ParameterError(parameter_message(
                "forces", owner, "have a finite sum (F_tot overflows)", f"max {mag.max()}"))
        if not total > 0:
            raise ParameterError(parameter_message(
                "forces", owner, "have a positive sum (some contact must touch)",
                mag.tolist() if n <= 8 else "all zeros"))
        dmat, limits = limit_factors(anisotropy, n, owner)
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "velocities", vel)
        object.__setattr__(self, "forces", mag)
        object.__setattr__(self, "limits", limits)
        object.__setattr__(self, "_dmat", dmat)
        object.__setattr__(self, "_total", total)

    @classmethod
    def _trusted(cls, positions: np.ndarray, velocities: np.ndarray, forces: np.ndarray,
                 dmat: np.ndarray, limits: np.ndarray | None) -> PlanarContactSet:
        """A set from arrays already checked (read-only, shapes right): no re-validation."""
        new = object.__new__(cls)
        for name, value in (("positions", positions), ("velocities", velocities),
                            ("forces", forces), ("limits", limits), ("_dmat", dmat)):
            object.__setattr__(new, name, value)
        object.__setattr__(new, "_total", float(np.sum(forces)))
        return new

    @classmethod
    def from_friction(cls, positions: Any, velocities: Any, mu: Any, normal_loads: Any,
                      anisotropy: Any = None) -> PlanarContactSet:
        """Build from friction coefficients and normal loads, ``f_i = mu_i N_i``.

        Parameters
        ----------
        positions, velocities : array_like of shape (n, 2), m and m/s
        mu : float or array_like of shape (n,), ``>= 0``
        normal_loads : float or array_like of shape (n,), N, ``>= 0``
        anisotropy : see the class.
        """
        owner = "PlanarContactSet.from_friction"
        pos = _as_points(positions, "positions", owner)
        n = pos.shape[0]
        parts = []
        for name, value in (("mu", mu), ("normal_loads", normal_loads)):
            array = as_float_array(value, name, owner)
            check_nonnegative(array, name, owner)
            if array.size not in (1, n):
                raise ParameterError(parameter_message(
                    name, owner, f"be a scalar or have one entry per contact ({n})",
                    f"an array of length {array.size}"))
            parts.append(array)
        return cls(pos, velocities, np.broadcast_to(parts[0] * parts[1], (n,)), anisotropy)

    @classmethod
    def on_line(cls, contacts: ContactSet, positions: Any = None, direction: Any = (1.0, 0.0),
                origin: Any = (0.0, 0.0)) -> PlanarContactSet:
        """Embed a 1-D :class:`toolkit.ContactSet` in the plane, on the line ``origin + s e``.

        Parameters
        ----------
        contacts : ContactSet
            Speeds ``v_i`` (m/s) along ``e`` and magnitudes ``f_i`` (N).
        positions : array_like of shape (n,), m, optional
            Coordinate ``s_i`` of each contact along the line (default 0 for every contact:
            give at least two distinct ones to fix the rotation).
        direction : array_like of shape (2,)
            ``e``, normalized here.
        origin : array_like of shape (2,), m
        """
        owner = "PlanarContactSet.on_line"
        if not isinstance(contacts, ContactSet):
            raise ParameterTypeError(parameter_message("contacts", owner, "be a ContactSet", contacts))
        e = as_float_array(direction, "direction", owner)
        p = as_float_array(origin, "origin", owner)
        if e.shape != (2,) or not np.hypot(*e) > 0:
            raise ParameterError(parameter_message("direction", owner, "be a non-zero 2-vector", e.tolist()))
        if p.shape != (2,):
            raise ParameterError(parameter_message("origin", owner, "be a 2-vector", p.tolist()))
        e = e / np.hypot(*e)
        s = np.zeros(contacts.n) if positions is None else as_float_array(positions, "positions", owner)
        if s.shape != (contacts.n,):
            raise ParameterError(parameter_message(
                "positions", owner, f"have one coordinate per contact ({contacts.n})",
                f"an array of length {s.size}"))
        return cls(p + s[:, None] * e, contacts.speeds[:, None] * e, contacts.forces)

    # -- properties ------------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of contacts (lifted ones included)."""
        return int(self.forces.size)

    def __len__(self) -> int:
        return self.n

    @property
    def total_force(self) -> float:
        """``F_tot = sum f_i``, N: the largest net force (reached when every contact slides
        the same way, isotropic)."""
        return self._total

    @property
    def isotropic(self) -> bool:
        """True when every limit surface is a disc (no ``anisotropy``)."""
        return self.limits is None

    @property
    def limit_factors(self) -> np.ndarray:
        """``D_i`` with ``M_i = D_i D_i^T``, shape (n, 2, 2) (``(0, 2, 2)`` when isotropic)."""
        return self._dmat

    @property
    def tie_tolerance(self) -> float:
        """Net force components below this (N) are reported as exactly 0:
        ``4 (n + 1) eps F_tot``, a bound on the rounding of the sum (as
        :attr:`toolkit.ContactSet.tie_tolerance`)."""
        return tie_tolerance(self.n, self._total)

    @property
    def arm(self) -> float:
        """``max |r_i|``, m (0 when every contact is at the reference point)."""
        return float(np.max(np.hypot(self.positions[:, 0], self.positions[:, 1])))

    def __repr__(self) -> str:
        kind = "isotropic" if self.isotropic else "anisotropic"
        return (f"PlanarContactSet(n={self.n}, total_force={self._total:.6g} N, {kind}, "
                f"max |r| = {self.arm:.6g} m)")

    # -- variants --------------------------------------------------------------------------
    def with_velocities(self, velocities: Any) -> PlanarContactSet:
        """The same contacts with new velocities (m/s, shape (n, 2))."""
        vel = _as_points(velocities, "velocities", "PlanarContactSet.with_velocities", self.n)
        return self._trusted(self.positions, vel, self.forces, self._dmat, self.limits)

    def with_forces(self, forces: Any) -> PlanarContactSet:
        """The same contacts with new magnitudes (N, shape (n,), >= 0, positive sum)."""
        return PlanarContactSet(self.positions, self.velocities, forces, self.limits)

    def subset(self, index: Any) -> PlanarContactSet:
        """The contacts selected by ``index`` (a boolean mask or indices)."""
        index = np.asarray(index)
        idx = np.arange(self.n)[index if index.size else index.astype(int)]   # ([] is float)
        if idx.size == 0 or not np.sum(self.forces[idx]) > 0:
            raise ParameterError(parameter_message(
                "index", "PlanarContactSet.subset", "select contacts with a positive total force",
                idx.tolist()))
        pick = [np.ascontiguousarray(a[idx]) for a in (self.positions, self.velocities, self.forces)]
        dmat = np.ascontiguousarray(self._dmat[idx]) if self._dmat.shape[0] else self._dmat
        limits = None if self.limits is None else np.ascontiguousarray(self.limits[idx])
        for array in (*pick, dmat) + (() if limits is None else (limits,)):
            array.setflags(write=False)
        return self._trusted(*pick, dmat, limits)

    def transformed(self, angle: float = 0.0, shift: Any = (0.0, 0.0)) -> PlanarContactSet:
        """The same contacts seen from another frame: positions ``R (r_i - shift)``,
        velocities ``R v_i``, limit matrices ``R M_i R^T``, with ``R`` the rotation by
        ``angle`` (rad).

        ``angle`` = the body's heading expresses a body-frame set in the world frame;
        ``shift`` (m, in the current frame) is the new reference point, about which the new
        set's torques are taken.
        """
        angle = as_float(angle, "angle", "PlanarContactSet.transformed")
        p = as_float_array(shift, "shift", "PlanarContactSet.transformed")
        if p.shape != (2,):
            raise ParameterError(parameter_message("shift", "PlanarContactSet.transformed",
                                                   "be a 2-vector", p.tolist()))
        c, s = np.cos(angle), np.sin(angle)
        rot = np.array([[c, -s], [s, c]])
        pos = (self.positions - p) @ rot.T
        vel = self.velocities @ rot.T
        dmat = rot @ self._dmat                                  # ((0, 2, 2) stays empty)
        limits = None if self.limits is None else dmat @ np.swapaxes(dmat, 1, 2)
        for array in (pos, vel, dmat) + (() if limits is None else (limits,)):
            array.setflags(write=False)
        return self._trusted(pos, vel, self.forces, dmat, limits)

    # -- evaluation ------------------------------------------------------------------------
    def slips(self, V: Any, omega: Any = 0.0) -> np.ndarray:
        """Slip ``s_i = v_i - V - omega J r_i`` of every contact, m/s.

        Parameters
        ----------
        V : array_like of shape (..., 2), m/s
        omega : array_like of shape (...), rad/s

        Returns
        -------
        ndarray of shape (..., n, 2)
        """
        vel, rate = _as_twists(V, omega, "PlanarContactSet.slips")
        r = self.positions
        sx = self.velocities[:, 0] - vel[..., 0, None] + rate[..., None] * r[:, 1]
        sy = self.velocities[:, 1] - vel[..., 1, None] - rate[..., None] * r[:, 0]
        return np.stack((sx, sy), axis=-1)

    def _snap(self, force: np.ndarray, torque: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        tol = self.tie_tolerance
        force[np.abs(force) <= tol] = 0.0
        torque[np.abs(torque) <= tol * self.arm] = 0.0
        return force, torque

    def wrench(self, V: Any, omega: Any = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Net force and torque of the contacts on the body at twists ``(V, omega)``.

        Parameters
        ----------
        V : array_like of shape (..., 2), m/s
            Body velocities at the reference point.
        omega : array_like of shape (...), rad/s
            Angular velocities (counter-clockwise positive); broadcast against ``V``.

        Returns
        -------
        force : ndarray of shape (..., 2), N
        torque : ndarray of shape (...), N m
            About the reference point. A contact with exactly zero slip contributes 0 (the
            centre of its set-valued force; :meth:`wrench_set` gives the set). ``O(n)`` per
            twist, no ``n x M`` array (a compiled kernel).
        """
        vel, rate = _as_twists(V, omega, "PlanarContactSet.wrench")
        shape = rate.shape
        flat_v = np.ascontiguousarray(vel.reshape(rate.size, 2))
        flat_w = np.ascontiguousarray(rate.ravel())
        force = np.empty((flat_w.size, 2))
        torque = np.empty(flat_w.size)
        kernels("planar", self.n * flat_w.size).wrench(
            self.positions, self.velocities, self.forces, self._dmat, flat_v, flat_w, force, torque)
        force, torque = self._snap(force, torque)
        return force.reshape(shape + (2,)), torque.reshape(shape)

    def dissipation(self, V: Any, omega: Any = 0.0) -> np.ndarray:
        """The dissipation potential ``Phi = sum f_i sqrt(s_i^T M_i s_i)`` at twists, W.

        Convex in ``(V, omega)``; the net wrench is minus its gradient wherever no contact
        sticks (docs/planar.md section 1). Shapes as :meth:`wrench`; returns shape (...).
        """
        vel, rate = _as_twists(V, omega, "PlanarContactSet.dissipation")
        shape = rate.shape
        out = np.empty(rate.size)
        kernels("planar", self.n * rate.size).dissipation(
            self.positions, self.velocities, self.forces, self._dmat,
            np.ascontiguousarray(vel.reshape(rate.size, 2)), np.ascontiguousarray(rate.ravel()), out)
        return out.reshape(shape)

    def stuck(self, V: Any, omega: Any = 0.0) -> np.ndarray:
        """Which contacts have exactly zero slip at each twist: bool of shape (..., n)."""
        s = self.slips(V, omega)
        return (s[..., 0] == 0.0) & (s[..., 1] == 0.0) & (self.forces > 0)

    def wrench_set(self, V: Any, omega: float = 0.0) -> WrenchSet:
        """The set-valued net wrench at one twist (``V`` of shape (2,), ``omega`` a float):
        the sliding contacts' wrench plus every stuck contact's friction disc or ellipse."""
        vel, rate = _as_twists(V, omega, "PlanarContactSet.wrench_set")
        if vel.shape != (2,):
            raise ParameterError(parameter_message(
                "V", "PlanarContactSet.wrench_set", "be one velocity of shape (2,)",
                f"an array of shape {vel.shape}"))
        force, torque = self.wrench(vel, rate)
        idx = np.flatnonzero(self.stuck(vel, rate))
        dmat = self._dmat[idx] if self._dmat.shape[0] else self._dmat
        return WrenchSet(force, float(torque), idx, self.positions[idx], self.forces[idx], dmat)

    def resistance(self, V: Any, omega: Any = 0.0) -> np.ndarray:
        """The local resistance matrix ``R = -d(F, tau)/d(V, omega)`` (the Hessian of the
        dissipation potential) at twists where no contact sticks.

        Returns
        -------
        ndarray of shape (..., 3, 3)
            Rows/columns ``(Vx, Vy, omega)``: N s/m, N s, N m s. Symmetric positive
            semi-definite. ``inf`` everywhere at a twist where some contact has zero slip
            (the map is not differentiable there: stiction resists any change).
        """
        vel, rate = _as_twists(V, omega, "PlanarContactSet.resistance")
        s = self.slips(vel, rate)
        r = self.positions
        # A_i maps the twist to the body velocity at r_i: [[1, 0, -r_y], [0, 1, r_x]].
        A = np.zeros((self.n, 2, 3))
        A[:, 0, 0] = A[:, 1, 1] = 1.0
        A[:, 0, 2] = -r[:, 1]
        A[:, 1, 2] = r[:, 0]
        if self._dmat.shape[0]:
            z = np.einsum("nji,...nj->...ni", self._dmat, s)
            BA = np.einsum("nji,njk->nik", self._dmat, A)          # D^T A
        else:
            z, BA = s, A
        rho = np.hypot(z[..., 0], z[..., 1])
        active = self.forces > 0
        # A slip at the rounding of the velocities it is computed from is a stick.
        size = (np.abs(self.velocities).max(axis=1) + np.abs(vel).max(axis=-1)[..., None]
                + np.abs(rate)[..., None] * np.abs(self.positions).max(axis=1))
        stuck = np.any((rho <= 64 * _EPS * size) & active, axis=-1)
        # Only sliding contacts (f_i > 0, s_i != 0) resist: f_i / rho_i (I - u_i u_i^T).
        slide = active & (rho > 0)
        rho = np.where(slide, rho, 1.0)
        u = z / rho[..., None]
        scale = np.where(slide, self.forces / rho, 0.0)
        proj = np.eye(2) - u[..., :, None] * u[..., None, :]        # (..., n, 2, 2)
        out = np.einsum("...n,nai,...nab,nbj->...ij", scale, BA, proj, BA)
        out[stuck] = np.inf
        return out

    # -- reductions and solvers --------------------------------------------------------------
    def line_reduction(self) -> LineReduction | None:
        """The 1-D set when every contact lies on one line, every velocity is parallel to it
        and each limit surface has the line as an axis (else None).

        Used by :meth:`equilibrium` and the simulation for the exact reduction to the 1-D
        toolkit (docs/planar.md section 5). Contacts all at one point are on every line: the
        line is then the one of the velocities (if they are parallel).
        """
        scale_r = max(self.arm, float(np.max(np.abs(self.positions))))   # (0: every test below is 0 > 0)
        scale_v = float(np.max(np.abs(self.velocities)))
        tol_r = 16 * _EPS * scale_r
        tol_v = 16 * _EPS * scale_v
        centre = self.positions[0]
        rel = self.positions - centre
        spread = np.hypot(rel[:, 0], rel[:, 1])
        if np.max(spread) > tol_r:
            e = rel[int(np.argmax(spread))] / np.max(spread)
        else:
            speeds = np.hypot(self.velocities[:, 0], self.velocities[:, 1])
            if np.max(speeds) == 0.0:
                e = np.array([1.0, 0.0])
            else:
                e = self.velocities[int(np.argmax(speeds))] / np.max(speeds)
        e = _canonical(e)
        if np.max(np.abs(rel[:, 0] * e[1] - rel[:, 1] * e[0])) > tol_r:
            return None
        if np.max(np.abs(self.velocities[:, 0] * e[1] - self.velocities[:, 1] * e[0])) > tol_v:
            return None
        weights = self.line_weights(e)
        if weights is None:
            return None
        speeds = self.velocities @ e
        origin = centre - (centre @ e) * e
        return LineReduction(ContactSet(speeds, weights), origin, e)

    def line_weights(self, e: np.ndarray) -> np.ndarray | None:
        """Friction magnitudes along the unit direction ``e``, ``f_i |D_i^T e|`` (N), when
        ``e`` is an axis of every limit surface (so a slip along ``e`` gets a force along
        it); None otherwise."""
        if not self._dmat.shape[0]:
            return self.forces
        Me = self.limits @ e
        if np.max(np.abs(Me[:, 0] * e[1] - Me[:, 1] * e[0])) > 16 * _EPS * np.max(np.abs(Me)):
            return None
        z = np.einsum("nji,j->ni", self._dmat, e)
        return self.forces * np.hypot(z[:, 0], z[:, 1])

    def equilibrium(self, translation_only: bool = False, *, method: str = "auto",
                    tol: float = 1e-10) -> Any:
        """The twist (or velocity) at which the contacts balance: the minimizer of the
        dissipation potential, certified by a duality gap.

        See :func:`toolkit.planar.equilibrium.solve_equilibrium` for ``method`` and ``tol``
        and :class:`toolkit.planar.equilibrium.PlanarEquilibrium` for the result
        (``velocity`` (2,), ``omega``, ``gap``, ``status``, ...).
        """
        return solve_equilibrium(self, translation_only=translation_only, method=method, tol=tol)


def geometric_median(points: Any, weights: Any = None, *, method: str = "auto",
                     tol: float = 1e-10) -> PlanarEquilibrium:
    """The weighted geometric median (Fermat-Weber point) of planar points, certified.

    ``points`` (n, 2) play the contact velocities of a translation-only
    :class:`PlanarContactSet` with ``weights`` (n,) its magnitudes: the result's
    ``velocity`` is the median, ``gap`` its certificate (see :func:`solve_equilibrium`).
    """
    P = _as_points(points, "points", "geometric_median")
    contacts = PlanarContactSet(np.zeros_like(P), P, weights)
    return solve_equilibrium(contacts, translation_only=True, method=method, tol=tol)


def wrench_batch(positions: Any, velocities: Any, forces: Any, V: Any, omega: Any,
                 anisotropy: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Net force and torque of many contact sets, each at its own twists.

    Parameters
    ----------
    positions, velocities : array_like of shape (S, n, 2), m and m/s
    forces : array_like of shape (S, n), N
    V : array_like of shape (S, ..., 2), m/s
    omega : array_like of shape (S, ...), rad/s
    anisotropy : None or array_like of shape (S, n, 2) or (S, n, 2, 2)

    Returns
    -------
    force : ndarray of shape (S, ..., 2), N
    torque : ndarray of shape (S, ...), N m
        Set ``k`` at its twists, exactly as ``PlanarContactSet(...[k]).wrench(V[k], omega[k])``.
    """
    pos = np.asarray(positions)           # (each set's arrays are checked by PlanarContactSet)
    vel = np.asarray(velocities)
    mag = np.asarray(forces)
    if pos.ndim != 3:
        raise ParameterError(parameter_message(
            "positions", "wrench_batch", "have shape (S, n, 2)", f"an array of shape {pos.shape}"))
    S = pos.shape[0]
    Vs = np.asarray(V)                    # (and each set's twists by its wrench)
    ws = np.asarray(omega)
    if Vs.shape[:1] != (S,) or ws.shape[:1] != (S,):
        raise ParameterError(parameter_message(
            "V", "wrench_batch", f"have a first axis of length S = {S} (as 'omega')",
            f"shapes {Vs.shape} and {ws.shape}"))
    forces_out, torques_out = [], []
    for k in range(S):
        aniso = None if anisotropy is None else np.asarray(anisotropy)[k]
        contacts = PlanarContactSet(pos[k], vel[k], mag[k], aniso)
        f, t = contacts.wrench(Vs[k], ws[k])
        forces_out.append(f)
        torques_out.append(t)
    return np.stack(forces_out), np.stack(torques_out)
