"""Continuous contact regions: discs, annuli, thin rings and loaded curves.

A region spreads a friction magnitude (N) over an area or a curve; its force and torque are
integrals of the planar Coulomb law over the region. Each region gives a quadrature
(:class:`Quadrature`: one node per cell at the cell's load centroid, carrying the cell's
load) whose wrench comes with a computed, rigorous bound on its error for every twist
(docs/planar.md section 3), and the uniform disc, annulus and thin ring also have closed
forms (elliptic integrals; Farkas et al., PRL 90, 248302 (2003)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ParameterError, as_float, as_float_array, as_int, parameter_message
from .contacts import PlanarContactSet, _as_twists

__all__ = ["Quadrature", "RegionWrench", "DiscRegion", "RingRegion", "CurveRegion",
           "disc_force_torque", "ring_force_torque", "terminal_ratio"]


@dataclass(frozen=True)
class RegionWrench:
    """Force and torque of a region by quadrature, with bounds on their errors.

    Attributes
    ----------
    force : ndarray of shape (..., 2), N
    torque : ndarray of shape (...), N m
    force_bound : ndarray of shape (...), N
        ``|force - exact force| <= force_bound`` (Euclidean norm).
    torque_bound : ndarray of shape (...), N m
    """

    force: np.ndarray
    torque: np.ndarray
    force_bound: np.ndarray
    torque_bound: np.ndarray


@dataclass(frozen=True, eq=False)
class Quadrature:
    """A region cut into cells: one contact per cell at its load centroid.

    Attributes
    ----------
    contacts : PlanarContactSet
        Nodes (m), node velocities (m/s) and cell loads (N) as contact magnitudes.
    radius : ndarray of shape (n,), m
        ``delta_j``: the largest distance from node ``j`` to a point of its cell.
    lipschitz : ndarray of shape (n,), 1/s
        A bound on how fast the contact velocity changes with position inside cell ``j``.
    """

    contacts: PlanarContactSet
    radius: np.ndarray
    lipschitz: np.ndarray

    @property
    def n(self) -> int:
        """Number of nodes."""
        return self.contacts.n

    def wrench(self, V: Any, omega: Any = 0.0) -> RegionWrench:
        """Force and torque at twists ``(V, omega)`` (shapes as
        :meth:`PlanarContactSet.wrench`) with their error bounds."""
        force, torque = self.contacts.wrench(V, omega)
        fb, tb = self.error_bound(V, omega)
        return RegionWrench(force, torque, fb, tb)

    def error_bound(self, V: Any, omega: Any = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Bounds on the quadrature's force (N) and torque (N m) errors at twists.

        For a cell of load ``W_j``, node ``r_j`` (its load centroid) and radius ``delta_j``,
        the slip inside the cell is within ``e_j = (L_j + |omega|) delta_j`` of the node's
        (and ``e_z = s_max e_j`` in the limit surface's norm, ``s_max`` the largest
        singular value of its factor ``D_j``). First order: the unit force differs by at
        most ``dev1 = s_max min(2, 2 e_z / |z_j|)``. Second order, where ``|z_j| > e_z``:
        the slip is affine in the cell and the node is its centroid, so the linear term
        integrates to zero and ``dev2 = s_max e_z^2 / (sqrt(3) (|z_j| - e_z)^2)`` bounds the
        rest (``|D^2 (z / |z|)| <= 2 / (sqrt(3) |z|^2)``). The force error is at most
        ``sum W_j min(dev1, dev2)``; the torque error at most ``sum W_j min((|r_j| +
        delta_j) dev1, delta_j s_max^2 e_j / |z_j| + (|r_j| + delta_j) dev2)``
        (docs/planar.md section 3).
        """
        c = self.contacts
        vel, rate = _as_twists(V, omega, "Quadrature.error_bound")
        s = c.slips(vel, rate)
        dmat = c.limit_factors
        if dmat.shape[0]:
            sv = np.linalg.svd(dmat, compute_uv=False)
            smax = sv[:, 0]
            z = np.einsum("nji,...nj->...ni", dmat, s)
        else:
            smax = np.ones(c.n)
            z = s
        zn = np.hypot(z[..., 0], z[..., 1])
        e = (self.lipschitz + np.abs(rate)[..., None]) * self.radius
        ez = smax * e
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            dev1 = smax * np.minimum(2.0, np.where(ez == 0, 0.0, 2.0 * ez / zn))
            far = zn > ez
            dev2 = np.where(far, smax * ez * ez / (np.sqrt(3.0) * np.where(far, zn - ez, 1.0) ** 2), np.inf)
            lin = np.where(far, self.radius * smax * smax * e / np.where(far, zn, 1.0), np.inf)
        arm = np.hypot(c.positions[:, 0], c.positions[:, 1]) + self.radius
        force = np.sum(c.forces * np.minimum(dev1, dev2), axis=-1)
        torque = np.sum(c.forces * np.minimum(arm * dev1, lin + arm * dev2), axis=-1)
        return force, torque

    @staticmethod
    def concatenate(parts: list[Quadrature]) -> Quadrature:
        """One quadrature of several regions on one body (their nodes together)."""
        if not parts:
            raise ParameterError(parameter_message("parts", "Quadrature.concatenate",
                                                   "hold at least one quadrature", parts))
        sets = [p.contacts for p in parts]
        aniso = any(not s.isotropic for s in sets)
        limits = None
        if aniso:
            limits = np.concatenate([np.broadcast_to(np.eye(2), (s.n, 2, 2)) if s.isotropic
                                     else s.limits for s in sets])
        contacts = PlanarContactSet(np.concatenate([s.positions for s in sets]),
                                    np.concatenate([s.velocities for s in sets]),
                                    np.concatenate([s.forces for s in sets]), limits)
        return Quadrature(contacts, _frozen(np.concatenate([p.radius for p in parts])),
                          _frozen(np.concatenate([p.lipschitz for p in parts])))


def _frozen(array: np.ndarray) -> np.ndarray:
    array = np.ascontiguousarray(array, dtype=float)
    array.setflags(write=False)
    return array


def _point(value: Any, name: str, owner: str) -> np.ndarray:
    array = as_float_array(value, name, owner)
    if array.shape != (2,):
        raise ParameterError(parameter_message(name, owner, "be a 2-vector", array.tolist()))
    return array


# -- closed forms ----------------------------------------------------------------------------
def _series_coefficients(terms: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients of ``F`` and ``k T`` of a uniform disc in powers of ``m = 1 / k^2`` (the
    closed forms below expanded with ``K(m) = pi/2 sum a_n m^n``, ``E(m) = pi/2 sum a_n m^n /
    (1 - 2n)``, ``a_n = ((2n)! / (4^n n!^2))^2``): for ``k >= 2`` the closed forms lose
    ``k^4`` to cancellation (1e-11 at k = 88), the series (40 terms: below 1e-24 there) none."""
    n = np.arange(terms + 2)
    a = np.cumprod(np.concatenate(([1.0], ((2 * n[1:] - 1) / (2 * n[1:])) ** 2)))
    b = a / (1 - 2 * n)
    j = n[:terms]
    force = (2.0 / 3.0) * (a[j + 1] * 2 * (j + 1) / (1 - 2 * (j + 1)) + a[j] * (2 - 2 * j) / (1 - 2 * j))
    torque = (2.0 / 9.0) * (2 * (a[j + 2] - b[j + 2]) + (4 * b[j + 1] - 5 * a[j + 1]) + 3 * a[j])
    return force, torque


_FORCE_SERIES, _TORQUE_SERIES = _series_coefficients()


def _disc_shape(eps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``F(eps)``, ``T(eps)`` of a uniform disc: force / (mu N) and torque / (mu N R) at the
    ratio ``eps = |W| / (R |omega|)`` (docs/planar.md section 3)."""
    from scipy.special import ellipe, ellipk

    eps = np.asarray(eps, dtype=float)
    F = np.empty(eps.shape)
    T = np.empty(eps.shape)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        low = eps < 1.0
        e = np.where(low, eps, 0.5)
        m = e * e
        K, E = ellipk(m), ellipe(m)
        F_low = np.where(e > 0, 4 / (3 * np.pi) * ((1 + m) * E - (1 - m) * K) / np.where(e > 0, e, 1.0), 0.0)
        T_low = 4 / (9 * np.pi) * ((4 - 2 * m) * E - (1 - m) * K)
        k = np.where(low, 2.0, eps)
        mi = np.where(np.isfinite(k), 1.0 / (k * k), 0.0)
        Ki, Ei = ellipk(mi), ellipe(mi)
        F_high = np.where(np.isfinite(k), 4 / (3 * np.pi) * ((k * k + 1) * Ei - (k * k - 1) * Ki), 1.0)
        T_high = np.where(np.isfinite(k),
                          4 / (9 * np.pi) * ((4 - 2 * k * k) * k * Ei + (k * k - 1) * (2 * k * k - 3) / k * Ki),
                          0.0)
        far = ~low & (eps >= 2.0)
        mf = np.where(far & np.isfinite(eps), 1.0 / np.where(far, eps, 2.0) ** 2, 0.0)
        F_far = np.polynomial.polynomial.polyval(mf, _FORCE_SERIES)
        T_far = np.where(np.isfinite(eps), np.polynomial.polynomial.polyval(mf, _TORQUE_SERIES)
                         * np.sqrt(mf), 0.0)
    F[...] = np.where(low, F_low, np.where(far, F_far, F_high))
    T[...] = np.where(low, T_low, np.where(far, T_far, T_high))
    one = eps == 1.0
    F[one] = 8 / (3 * np.pi)
    T[one] = 8 / (9 * np.pi)
    return F, T


def _ring_shape(eps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``F(eps)``, ``T(eps)`` of a thin uniform ring: force / (mu N), torque / (mu N R), from
    the mean distance ``Psi(rho) = (2/pi) (1 + rho) E(m)``, ``m = 4 rho / (1 + rho)^2``:
    ``F = Psi'``, ``T = Psi - rho Psi'``.

    ``K`` diverges at ``rho = 1`` (``m = 1``), where ``m`` itself rounds to 1 within 1e-8 of
    it: ``K`` is taken at the complementary parameter ``1 - m = ((1 - rho) / (1 + rho))^2``
    (``scipy.special.ellipkm1``), computed without cancellation and at least 3e-33 for any
    double ``rho != 1``, so the term ``(1 - rho) K ~ (1 - rho) ln(4 / |1 - rho|)`` is
    accurate to rounding up to ``rho = 1``, where it vanishes (and is set to 0).
    """
    from scipy.special import ellipe, ellipkm1

    rho = np.asarray(eps, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        fin = np.isfinite(rho)
        r = np.where(fin, rho, 1.0)
        gap = 1 - r
        E = ellipe(np.minimum(4 * r / (1 + r) ** 2, 1.0))
        K = ellipkm1((gap / (1 + r)) ** 2)                # at 1 - m, without cancellation
        psi = 2 / np.pi * (1 + r) * E
        # Psi' = (2/pi) [E + (E - K)(1 - rho) / (2 rho)]; (1 - rho) K -> 0 at rho = 1.
        dk = np.where(gap == 0.0, 0.0, (E - K) * gap / np.where(r > 0, 2 * r, 1.0))
        dpsi = 2 / np.pi * (E + dk)
        dpsi = np.where(r > 0, dpsi, 0.0)
        F = np.where(fin, dpsi, 1.0)
        T = np.where(fin, psi - r * dpsi, 0.0)
    return F, T


def _annulus_shape(eta: float):
    """The shape functions ``(F, T)`` of a uniform annulus of inner radius ``eta R``
    (:func:`_disc_shape` for ``eta = 0``): the disc's minus its hole's, at one pressure."""
    if eta == 0:
        return _disc_shape

    def shape(eps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        area = 1 - eta * eta
        Fo, To = _disc_shape(eps)
        Fi, Ti = _disc_shape(np.asarray(eps) / eta)
        return (Fo - eta * eta * Fi) / area, (To - eta ** 3 * Ti) / area
    return shape


def _axisymmetric(shape, V: Any, omega: Any, centre: np.ndarray, radius: float, force: float,
                  velocity: np.ndarray, owner: str) -> tuple[np.ndarray, np.ndarray]:
    vel, rate = _as_twists(V, omega, owner)
    # Relative motion of the body over the region, at the region's centre.
    Wx = vel[..., 0] - velocity[0] - rate * centre[1]
    Wy = vel[..., 1] - velocity[1] + rate * centre[0]
    speed = np.hypot(Wx, Wy)
    with np.errstate(divide="ignore", invalid="ignore"):
        eps = np.where(rate != 0, speed / (radius * np.abs(rate)), np.inf)
    F, T = shape(eps)
    with np.errstate(divide="ignore", invalid="ignore"):
        ux = np.where(speed > 0, Wx / speed, 0.0)
        uy = np.where(speed > 0, Wy / speed, 0.0)
    fx, fy = -force * F * ux, -force * F * uy
    tc = -np.sign(rate) * force * radius * T
    torque = tc + centre[0] * fy - centre[1] * fx
    return np.stack((fx, fy), axis=-1), torque


def disc_force_torque(V: Any, omega: Any, *, radius: float, force: float,
                      centre: Any = (0.0, 0.0), velocity: Any = (0.0, 0.0),
                      inner_radius: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Exact force and torque of a uniformly loaded disc (or annulus) at twists.

    Parameters
    ----------
    V : array_like of shape (..., 2), m/s
    omega : array_like of shape (...), rad/s
    radius : float, m
    force : float, N
        Total friction magnitude ``mu N``.
    centre : array_like of shape (2,), m
        Disc centre relative to the reference point (torques are about the reference point).
    velocity : array_like of shape (2,), m/s
        The ground velocity of the region (0 for a passive disc).
    inner_radius : float, m
        ``> 0``: an annulus, the uniform disc of ``radius`` minus that of ``inner_radius``.

    Returns
    -------
    force : ndarray of shape (..., 2), N
    torque : ndarray of shape (...), N m
        At a twist where the region does not slip at all (``W = 0``, ``omega = 0``) the
        force is set-valued; 0 is returned.
    """
    owner = "disc_force_torque"
    R = as_float(radius, "radius", owner, low=0.0, low_open=True)
    Ftot = as_float(force, "force", owner, low=0.0)
    r0 = as_float(inner_radius, "inner_radius", owner, low=0.0)
    if not r0 < R:
        raise ParameterError(parameter_message("inner_radius", owner, f"be < radius ({R:g})", r0))
    c = _point(centre, "centre", owner)
    u = _point(velocity, "velocity", owner)
    if r0 == 0.0:
        return _axisymmetric(_disc_shape, V, omega, c, R, Ftot, u, owner)
    # Annulus = disc(R) - disc(r0) at one pressure p = F / (pi (R^2 - r0^2)).
    area = R * R - r0 * r0
    fo, to = _axisymmetric(_disc_shape, V, omega, c, R, Ftot * R * R / area, u, owner)
    fi, ti = _axisymmetric(_disc_shape, V, omega, c, r0, Ftot * r0 * r0 / area, u, owner)
    return fo - fi, to - ti


def ring_force_torque(V: Any, omega: Any, *, radius: float, force: float,
                      centre: Any = (0.0, 0.0), velocity: Any = (0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Exact force and torque of a thin uniformly loaded ring at twists (as
    :func:`disc_force_torque`)."""
    owner = "ring_force_torque"
    R = as_float(radius, "radius", owner, low=0.0, low_open=True)
    Ftot = as_float(force, "force", owner, low=0.0)
    return _axisymmetric(_ring_shape, V, omega, _point(centre, "centre", owner), R, Ftot,
                         _point(velocity, "velocity", owner), owner)


def terminal_ratio(kind: str = "disc", *, inertia_ratio: float | None = None,
                   inner_ratio: float = 0.0) -> float:
    """The terminal ratio ``eps* = v / (R omega)`` of a passive axisymmetric body sliding and
    spinning to rest: the stable root of ``F(eps) = eps T(eps) m R^2 / I``.

    Parameters
    ----------
    kind : {"disc", "ring"}
        Uniform disc (or annulus with ``inner_ratio = R_in / R``) or thin ring.
    inertia_ratio : float, optional
        ``I / (m R^2)``; default the body's own (uniform disc 1/2, annulus
        ``(1 + inner_ratio^2) / 2``, ring 1).
    inner_ratio : float
        ``R_in / R`` in ``[0, 1)`` (discs only).

    Returns
    -------
    float
        From the closed forms by Brent's method to 1e-15 (docs/planar.md section 4).
    """
    from scipy.optimize import brentq

    eta = as_float(inner_ratio, "inner_ratio", "terminal_ratio", low=0.0)
    if kind == "ring":
        k = 1.0 if inertia_ratio is None else inertia_ratio
        shape = _ring_shape
    elif kind == "disc":
        if not eta < 1.0:
            raise ParameterError(parameter_message("inner_ratio", "terminal_ratio", "be < 1", eta))
        k = (1 + eta * eta) / 2 if inertia_ratio is None else inertia_ratio
        shape = _annulus_shape(eta)
    else:
        raise ParameterError(parameter_message("kind", "terminal_ratio", "be 'disc' or 'ring'", kind))
    k = as_float(k, "inertia_ratio", "terminal_ratio", low=0.0, low_open=True)

    def balance(e: float) -> float:
        F, T = shape(np.array(e))
        return float(F - e * T / k)

    return float(brentq(balance, 1e-6, 50.0, xtol=1e-15, rtol=4 * np.finfo(float).eps))


# -- regions ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class DiscRegion:
    """A flat disc (or annulus) in contact with uniform pressure.

    Parameters
    ----------
    radius : float, m
    force : float, N
        Total friction magnitude ``mu N`` of the region.
    centre : array_like of shape (2,), m
        Relative to the body's reference point.
    velocity : array_like of shape (2,), m/s
        The contact velocity of the whole region (0: passive on fixed ground).
    inner_radius : float, m
        ``0`` for a full disc, else an annulus ``inner_radius <= |r - centre| <= radius``.
    """

    radius: float
    force: float
    centre: Any = (0.0, 0.0)
    velocity: Any = (0.0, 0.0)
    inner_radius: float = 0.0

    def __post_init__(self) -> None:
        owner = "DiscRegion"
        R = as_float(self.radius, "radius", owner, low=0.0, low_open=True)
        object.__setattr__(self, "radius", R)
        object.__setattr__(self, "force", as_float(self.force, "force", owner, low=0.0, low_open=True))
        object.__setattr__(self, "centre", _point(self.centre, "centre", owner))
        object.__setattr__(self, "velocity", _point(self.velocity, "velocity", owner))
        r0 = as_float(self.inner_radius, "inner_radius", owner, low=0.0)
        if not r0 < R:
            raise ParameterError(parameter_message("inner_radius", owner, f"be < radius ({R:g})", r0))
        object.__setattr__(self, "inner_radius", r0)

    def quadrature(self, rings: int = 24) -> Quadrature:
        """Polar cells: ``rings`` rings of equal width, each cut into sectors about as long
        as the ring is wide; one node per cell at its centroid."""
        rings = as_int(rings, "rings", "DiscRegion.quadrature", low=1)
        R, r0 = self.radius, self.inner_radius
        width = (R - r0) / rings
        pos, load, rad = [], [], []
        area = math.pi * (R * R - r0 * r0)
        for k in range(rings):
            a, b = r0 + k * width, r0 + (k + 1) * width
            m = max(3, int(round(2 * math.pi * 0.5 * (a + b) / width)))
            delta = 2 * math.pi / m
            mid = (np.arange(m) + 0.5) * delta
            rc = (2.0 / 3.0) * (b ** 3 - a ** 3) / (b * b - a * a) * math.sin(delta / 2) / (delta / 2)
            nodes = rc * np.stack((np.cos(mid), np.sin(mid)), axis=1)
            corners = np.array([[a * math.cos(-delta / 2), a * math.sin(-delta / 2)],
                                [a * math.cos(delta / 2), a * math.sin(delta / 2)],
                                [b * math.cos(-delta / 2), b * math.sin(-delta / 2)],
                                [b * math.cos(delta / 2), b * math.sin(delta / 2)]])
            radius = float(np.max(np.hypot(corners[:, 0] - rc, corners[:, 1])))
            pos.append(nodes)
            load.append(np.full(m, self.force * 0.5 * delta * (b * b - a * a) / area))
            rad.append(np.full(m, radius))
        positions = np.concatenate(pos) + self.centre
        n = positions.shape[0]
        contacts = PlanarContactSet(positions, np.broadcast_to(self.velocity, (n, 2)), np.concatenate(load))
        return Quadrature(contacts, _frozen(np.concatenate(rad)), _frozen(np.zeros(n)))

    def force_torque(self, V: Any, omega: Any = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Exact force (N) and torque (N m) by :func:`disc_force_torque`."""
        return disc_force_torque(V, omega, radius=self.radius, force=self.force, centre=self.centre,
                                 velocity=self.velocity, inner_radius=self.inner_radius)

    @property
    def inertia_ratio(self) -> float:
        """``I / (m R^2)`` of a uniform disc or annulus of this shape: ``(1 + (R_in/R)^2) / 2``."""
        return 0.5 * (1 + (self.inner_radius / self.radius) ** 2)


@dataclass(frozen=True)
class RingRegion:
    """A thin ring (a circle) in contact with uniform load.

    Parameters as :class:`DiscRegion` without ``inner_radius``.
    """

    radius: float
    force: float
    centre: Any = (0.0, 0.0)
    velocity: Any = (0.0, 0.0)

    def __post_init__(self) -> None:
        owner = "RingRegion"
        object.__setattr__(self, "radius", as_float(self.radius, "radius", owner, low=0.0, low_open=True))
        object.__setattr__(self, "force", as_float(self.force, "force", owner, low=0.0, low_open=True))
        object.__setattr__(self, "centre", _point(self.centre, "centre", owner))
        object.__setattr__(self, "velocity", _point(self.velocity, "velocity", owner))

    def quadrature(self, arcs: int = 256) -> Quadrature:
        """``arcs`` equal arcs, one node each at the arc's centroid ``R sin(d/2) / (d/2)``."""
        arcs = as_int(arcs, "arcs", "RingRegion.quadrature", low=3)
        delta = 2 * math.pi / arcs
        mid = (np.arange(arcs) + 0.5) * delta
        rc = self.radius * math.sin(delta / 2) / (delta / 2)
        positions = rc * np.stack((np.cos(mid), np.sin(mid)), axis=1) + self.centre
        end = np.array([self.radius * math.cos(delta / 2), self.radius * math.sin(delta / 2)])
        radius = max(float(np.hypot(end[0] - rc, end[1])), self.radius - rc)
        contacts = PlanarContactSet(positions, np.broadcast_to(self.velocity, (arcs, 2)),
                                    np.full(arcs, self.force / arcs))
        return Quadrature(contacts, _frozen(np.full(arcs, radius)), _frozen(np.zeros(arcs)))

    def force_torque(self, V: Any, omega: Any = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Exact force (N) and torque (N m) by :func:`ring_force_torque`."""
        return ring_force_torque(V, omega, radius=self.radius, force=self.force, centre=self.centre,
                                 velocity=self.velocity)

    @property
    def inertia_ratio(self) -> float:
        """``I / (m R^2) = 1`` for a thin ring."""
        return 1.0


@dataclass(frozen=True)
class CurveRegion:
    """A loaded polyline in contact (a snake's body, a leg's edge).

    Parameters
    ----------
    points : array_like of shape (k, 2), m
        Vertices, relative to the body's reference point (``k >= 2``).
    density : float or array_like of shape (k,), N/m
        Friction magnitude per unit length at each vertex, linear along each segment
        (``>= 0``, not all zero).
    velocities : array_like of shape (k, 2), m/s, optional
        Contact velocity at each vertex, linear along each segment (default 0: passive).
    ratio : float or array_like of shape (k - 1,), optional
        Anisotropy per segment: friction across the segment over friction along it (a snake's
        scales: > 1). Default 1 (isotropic).
    closed : bool
        Join the last vertex to the first.
    """

    points: Any
    density: Any
    velocities: Any = None
    ratio: Any = 1.0
    closed: bool = False

    def __post_init__(self) -> None:
        owner = "CurveRegion"
        pts = as_float_array(self.points, "points", owner, ndim=2)
        if pts.shape[1] != 2 or pts.shape[0] < 2:
            raise ParameterError(parameter_message("points", owner, "have shape (k, 2) with k >= 2",
                                                   f"an array of shape {pts.shape}"))
        k = pts.shape[0]
        dens = np.broadcast_to(as_float_array(self.density, "density", owner), (k,)).copy()
        if np.any(dens < 0) or not dens.sum() > 0:
            raise ParameterError(parameter_message("density", owner, "be >= 0 and not all zero",
                                                   dens.tolist()))
        vel = np.zeros((k, 2)) if self.velocities is None else as_float_array(
            self.velocities, "velocities", owner, ndim=2)
        if vel.shape != (k, 2):
            raise ParameterError(parameter_message("velocities", owner, f"have shape ({k}, 2)",
                                                   f"an array of shape {vel.shape}"))
        segments = k if self.closed else k - 1
        ratio = np.broadcast_to(as_float_array(self.ratio, "ratio", owner), (segments,)).copy()
        if np.any(ratio <= 0):
            raise ParameterError(parameter_message("ratio", owner, "be > 0", ratio.tolist()))
        for name, value in (("points", pts), ("density", dens), ("velocities", vel), ("ratio", ratio)):
            value = np.ascontiguousarray(value)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "closed", bool(self.closed))

    @property
    def length(self) -> float:
        """Total length, m."""
        P = self.points
        Q = np.roll(P, -1, axis=0) if self.closed else P[1:]
        return float(np.sum(np.hypot(*(Q - P[:len(Q)]).T)))

    @property
    def total_force(self) -> float:
        """Total friction magnitude ``int density ds``, N."""
        P = self.points
        idx = np.arange(P.shape[0] if self.closed else P.shape[0] - 1)
        nxt = (idx + 1) % P.shape[0]
        lengths = np.hypot(*(P[nxt] - P[idx]).T)
        return float(np.sum(lengths * 0.5 * (self.density[idx] + self.density[nxt])))

    def quadrature(self, cell: float | None = None) -> Quadrature:
        """Cells of length at most ``cell`` (m; default 1/200 of the length) along each
        segment; one node per cell at its load centroid (exact for the linear density)."""
        h = self.length / 200 if cell is None else as_float(cell, "cell", "CurveRegion.quadrature",
                                                           low=0.0, low_open=True)
        P, p, v = self.points, self.density, self.velocities
        k = P.shape[0]
        segs = k if self.closed else k - 1
        pos, vel, load, rad, lip, angle, ratio = [], [], [], [], [], [], []
        for s in range(segs):
            a, b = s, (s + 1) % k
            d = P[b] - P[a]
            length = float(np.hypot(*d))
            if length == 0:
                continue
            m = max(1, int(math.ceil(length / h)))
            t0 = np.arange(m) / m
            t1 = (np.arange(m) + 1) / m
            p0, dp = p[a], p[b] - p[a]
            w = length * (p0 * (t1 - t0) + dp * 0.5 * (t1 ** 2 - t0 ** 2))
            first = length * (p0 * 0.5 * (t1 ** 2 - t0 ** 2) + dp * (t1 ** 3 - t0 ** 3) / 3)
            with np.errstate(invalid="ignore", divide="ignore"):
                tc = np.where(w > 0, first / np.where(w > 0, w, 1.0), 0.5 * (t0 + t1))
            pos.append(P[a] + tc[:, None] * d)
            vel.append(v[a] + tc[:, None] * (v[b] - v[a]))
            load.append(w)
            rad.append(np.maximum(tc - t0, t1 - tc) * length)
            lip.append(np.full(m, float(np.hypot(*(v[b] - v[a]))) / length))
            angle.append(np.full(m, math.atan2(d[1], d[0])))
            ratio.append(np.full(m, self.ratio[s]))
        ratio_all = np.concatenate(ratio)
        aniso = None if np.all(ratio_all == 1.0) else np.stack((np.concatenate(angle), ratio_all), axis=1)
        contacts = PlanarContactSet(np.concatenate(pos), np.concatenate(vel), np.concatenate(load), aniso)
        return Quadrature(contacts, _frozen(np.concatenate(rad)), _frozen(np.concatenate(lip)))
