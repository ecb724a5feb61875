"""Gaits: legs (or body elements) whose positions, velocities and loads change through a cycle.

A :class:`Gait` samples one period of a contact schedule in the body frame (linear between
samples); :func:`force_twist_map`, :func:`quasi_static_cycle`, :func:`dynamic_cycles`,
:func:`averaged_model` and :func:`compare_averaged` analyse it (docs/planar.md section 6);
:func:`tripod_gait` and :func:`serpenoid` build a hexapod's and a snake's."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ParameterError, as_float, as_float_array, as_int, parameter_message
from .contacts import PlanarContactSet
from .equilibrium import PlanarEquilibrium, solve_equilibrium

__all__ = ["Gait", "CycleMotion", "AveragedModel", "GaitComparison", "tripod_gait", "serpenoid",
           "force_twist_map", "quasi_static_cycle", "dynamic_cycles", "averaged_model",
           "compare_averaged", "se2_step"]


@dataclass(frozen=True, eq=False)
class Gait:
    """A periodic contact schedule sampled over one period (body frame).

    Parameters
    ----------
    period : float, s
    times : array_like of shape (K,), s
        Increasing sample times in ``[0, period)``; the schedule wraps around (linear from the
        last sample to the first one plus a period).
    positions : array_like of shape (K, n, 2), m
        Contact points relative to the centre of mass.
    velocities : array_like of shape (K, n, 2), m/s
        Contact velocities ``v_i(t)`` (the body velocity at ``r_i`` at which leg ``i`` does not slip).
    loads : array_like of shape (K, n), N
        Friction magnitudes ``f_i(t) = mu_i N_i(t) >= 0``; 0 while a leg is in the air. Their
        sum must be positive at every sample.
    anisotropy : None or array_like of shape (n, 2) or (K, n, 2)
        ``(angle, ratio)`` per contact, constant or per sample (angles are interpolated the
        short way modulo pi, an ellipse's axis having no sign).
    """

    period: float
    times: Any
    positions: Any
    velocities: Any
    loads: Any
    anisotropy: Any = None

    def __post_init__(self) -> None:
        owner = "Gait"
        T = as_float(self.period, "period", owner, low=0.0, low_open=True)
        t = as_float_array(self.times, "times", owner)
        K = t.size
        if np.any(np.diff(t) <= 0) or t[0] < 0 or t[-1] >= T:
            raise ParameterError(parameter_message("times", owner, f"increase within [0, period = {T:g})",
                                                   t.tolist() if K <= 8 else f"[{t.min():g} .. {t.max():g}]"))
        pos = as_float_array(self.positions, "positions", owner, ndim=3)
        n = pos.shape[1]
        vel = as_float_array(self.velocities, "velocities", owner, ndim=3)
        load = as_float_array(self.loads, "loads", owner, ndim=2)
        for name, array, shape in (("positions", pos, (K, n, 2)), ("velocities", vel, (K, n, 2)),
                                   ("loads", load, (K, n))):
            if array.shape != shape:
                raise ParameterError(parameter_message(name, owner, f"have shape {shape}",
                                                       f"an array of shape {array.shape}"))
        if np.any(load < 0) or not np.all(load.sum(axis=1) > 0):
            raise ParameterError(parameter_message("loads", owner, "be >= 0 with a positive sum at "
                                                   "every sample", "a negative load or a sample with none"))
        aniso = None
        if self.anisotropy is not None:
            a = as_float_array(self.anisotropy, "anisotropy", owner, ndim=np.ndim(self.anisotropy))
            if a.shape == (n, 2):
                a = np.broadcast_to(a, (K, n, 2))
            if a.shape != (K, n, 2) or np.any(a[..., 1] <= 0):
                raise ParameterError(parameter_message(
                    "anisotropy", owner, f"have shape ({n}, 2) or ({K}, {n}, 2) with positive ratios",
                    f"an array of shape {a.shape}"))
            angle = np.unwrap(a[..., 0], period=np.pi, axis=0)
            aniso = np.stack((angle, a[..., 1]), axis=-1)
            aniso.setflags(write=False)
        object.__setattr__(self, "period", T)
        for name, value in (("times", t), ("positions", pos), ("velocities", vel), ("loads", load)):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "anisotropy", aniso)

    @property
    def n(self) -> int:
        """Number of legs (contacts)."""
        return int(self.loads.shape[1])

    def _weights(self, t: float) -> tuple[int, int, float]:
        phase = float(t) % self.period
        k = int(np.searchsorted(self.times, phase, side="right")) - 1
        if k < 0:                                    # before the first sample: wrap back
            k = self.times.size - 1
            t0, t1 = self.times[k] - self.period, self.times[0]
        else:
            t0 = self.times[k]
            t1 = self.times[k + 1] if k + 1 < self.times.size else self.times[0] + self.period
        j = (k + 1) % self.times.size
        return k, j, (phase - t0) / (t1 - t0) if phase > t0 else 0.0

    def contacts_at(self, t: float) -> PlanarContactSet:
        """The contacts at time ``t`` (s, any real: the gait repeats), linear between samples."""
        k, j, a = self._weights(t)
        mix = (lambda x: x[k]) if a == 0.0 else (lambda x: (1 - a) * x[k] + a * x[j])
        aniso = None
        if self.anisotropy is not None:
            ang = self.anisotropy[:, :, 0]
            wrap = 0.0 if j != 0 or k == 0 else np.pi * np.round((ang[k] - ang[0]) / np.pi)
            start, end = ang[k], ang[j] + wrap
            aniso = np.stack(((1 - a) * start + a * end, mix(self.anisotropy[:, :, 1])), axis=-1)
        return PlanarContactSet(mix(self.positions), mix(self.velocities), mix(self.loads), aniso)


def se2_step(V: np.ndarray, omega: float, h: float) -> np.ndarray:
    """Pose change ``(dx, dy, dtheta)`` in the starting body frame of moving for ``h`` seconds
    at the constant body twist ``(V, omega)`` (the exponential map of SE(2))."""
    a = omega * h
    if abs(a) < 1e-8:
        c1, c2 = h * (1 - a * a / 6), h * a / 2 * (1 - a * a / 12)
    else:
        c1, c2 = math.sin(a) / omega, (1 - math.cos(a)) / omega
    return np.array([c1 * V[0] - c2 * V[1], c2 * V[0] + c1 * V[1], a])


def _compose(pose: np.ndarray, step: np.ndarray) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.array([pose[0] + c * step[0] - s * step[1], pose[1] + s * step[0] + c * step[1],
                     pose[2] + step[2]])


@dataclass(frozen=True)
class CycleMotion:
    """Net motion over one gait cycle, in the body frame at the cycle's start.

    Attributes
    ----------
    displacement : ndarray of shape (2,), m
    rotation : float, rad
    error : float
        Estimated error of ``displacement`` (m; Richardson: the change from half the samples
        or twice the step, over 3 for the second-order quadrature or 1 for Moreau-Jean).
    rotation_error : float, rad
    method : str
        ``"quasi-static"`` or ``"dynamic"``.
    times : ndarray of shape (S,), s
    twists : ndarray of shape (S, 3)
        Body-frame twists ``(Vx, Vy, omega)`` at ``times``.
    max_gap : float
        Largest equilibrium gap (W) or Moreau-Jean step gap (J) met.
    wall_time : float, s
    """

    displacement: np.ndarray
    rotation: float
    error: float
    rotation_error: float
    method: str
    times: np.ndarray
    twists: np.ndarray
    max_gap: float
    wall_time: float

    @property
    def mean_twist(self) -> np.ndarray:
        """The time average of ``twists`` (trapezoid over the cycle), shape (3,)."""
        t, x = self.times, self.twists
        return np.trapezoid(x, t, axis=0) / (t[-1] - t[0])


def force_twist_map(gait: Gait, times: Any, V: Any, omega: Any) -> tuple[np.ndarray, np.ndarray]:
    """The contacts' force and torque at body twists through the cycle.

    Parameters
    ----------
    gait : Gait
    times : array_like of shape (K,), s
    V : array_like of shape (..., 2), m/s
    omega : array_like of shape (...), rad/s

    Returns
    -------
    force : ndarray of shape (K, ..., 2), N
    torque : ndarray of shape (K, ...), N m
    """
    t = as_float_array(times, "times", "force_twist_map")
    out = [gait.contacts_at(tk).wrench(V, omega) for tk in t]
    return np.stack([f for f, _ in out]), np.stack([tq for _, tq in out])


def _integrate(times: np.ndarray, twists: np.ndarray) -> np.ndarray:
    """Pose after the twists (body frame, linear between samples), by the midpoint
    exponential map on each interval (second order)."""
    pose = np.zeros(3)
    for k in range(times.size - 1):
        h = times[k + 1] - times[k]
        mid = 0.5 * (twists[k] + twists[k + 1])
        pose = _compose(pose, se2_step(mid[:2], mid[2], h))
    return pose


def quasi_static_cycle(gait: Gait, samples: int = 256, *, tol: float = 1e-10) -> CycleMotion:
    """Net motion over one cycle of a body that sits at its instantaneous equilibrium twist.

    The body-frame equilibrium twist (:func:`~toolkit.planar.equilibrium.solve_equilibrium`,
    certified) at ``samples + 1`` uniform times over the period, integrated on SE(2) by the
    midpoint rule; the same with half the samples gives the Richardson error estimate.
    Where the equilibrium is a segment (all contacts on one line) its midpoint is used.
    """
    samples = as_int(samples, "samples", "quasi_static_cycle", low=4)
    started = time.perf_counter()
    t = np.linspace(0.0, gait.period, samples + 1)
    twists = np.empty((t.size, 3))
    gaps = []
    for k, tk in enumerate(t):
        eq = solve_equilibrium(gait.contacts_at(tk), tol=tol)
        if not eq.certified:
            raise ParameterError(parameter_message(
                "gait", "quasi_static_cycle", "have a certified equilibrium at every sample",
                f"{eq.status.name} at t = {tk:g} s ({eq.message})"))
        twists[k] = eq.twist
        gaps.append(eq.gap)
    fine = _integrate(t, twists)
    coarse = _integrate(t[::2], twists[::2])
    error = float(np.hypot(*(fine[:2] - coarse[:2]))) / 3
    return CycleMotion(fine[:2], float(fine[2]), error, abs(fine[2] - coarse[2]) / 3,
                       "quasi-static", t, twists, float(max(gaps)), time.perf_counter() - started)


def dynamic_cycles(gait: Gait, mass: float, inertia: float, *, cycles: int = 4,
                   steps_per_cycle: int = 400) -> CycleMotion:
    """Net motion over the last of ``cycles`` cycles of a body with mass and inertia, started
    at rest, by the certified Moreau-Jean simulation (body-frame result); the same run with
    half the steps gives the error estimate (first order)."""
    from .simulation import PlanarPlant, simulate_planar

    cycles = as_int(cycles, "cycles", "dynamic_cycles", low=1)
    steps = as_int(steps_per_cycle, "steps_per_cycle", "dynamic_cycles", low=8)
    started = time.perf_counter()
    plant = PlanarPlant(gait, mass, inertia)
    results = []
    for per in (steps, steps // 2):
        h = gait.period / per
        times = np.linspace(0.0, cycles * gait.period, cycles * per + 1)
        run = simulate_planar(plant, cycles * gait.period, method="moreau", step=h, t_eval=times)
        last = slice((cycles - 1) * per, cycles * per + 1)
        start = np.array([run.position[last][0, 0], run.position[last][0, 1], run.heading[last][0]])
        end = np.array([run.position[-1, 0], run.position[-1, 1], run.heading[-1]])
        c, s = math.cos(start[2]), math.sin(start[2])
        d = end[:2] - start[:2]
        body = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])
        th = run.heading[last]
        Vw = run.velocity[last]
        Vb = np.stack((np.cos(th) * Vw[:, 0] + np.sin(th) * Vw[:, 1],
                       -np.sin(th) * Vw[:, 0] + np.cos(th) * Vw[:, 1]), axis=1)
        results.append((body, end[2] - start[2], run.t[last] - run.t[last][0],
                        np.c_[Vb, run.omega[last]], run.max_gap))
    (body, rot, t, tw, gap), (body2, rot2, _, _, _) = results
    return CycleMotion(body, float(rot), float(np.hypot(*(body - body2))), abs(rot - rot2), "dynamic",
                       t, tw, float(gap), time.perf_counter() - started)


@dataclass(frozen=True)
class AveragedModel:
    """The resistive-force (cycle-averaged) approximation of a gait.

    Attributes
    ----------
    contacts : PlanarContactSet
        Every sample's loaded contacts with magnitudes ``f_i(t_k) w_k / T`` (``w_k`` the
        trapezoid weights): its dissipation is the cycle average, its wrench the averaged
        force-twist map.
    equilibrium : PlanarEquilibrium
        The twist at which the averaged map balances.
    resistance : ndarray of shape (3, 3)
        ``-d(averaged wrench)/d(twist)`` at that twist (``inf`` when a sample's contact sticks
        there: the averaged map is not differentiable).
    displacement : ndarray of shape (2,), m
    rotation : float, rad
        The motion over one period at the constant averaged twist (the exponential map).
    """

    contacts: PlanarContactSet
    equilibrium: PlanarEquilibrium
    resistance: np.ndarray
    displacement: np.ndarray
    rotation: float


def averaged_model(gait: Gait, samples: int = 256) -> AveragedModel:
    """The cycle-averaged force-twist map, its equilibrium and resistance (docs/planar.md
    section 6). The average is over ``samples`` uniform times (periodic trapezoid rule)."""
    samples = as_int(samples, "samples", "averaged_model", low=4)
    t = np.arange(samples) * gait.period / samples
    sets = [gait.contacts_at(tk) for tk in t]
    aniso = any(not s.isotropic for s in sets)
    big = PlanarContactSet(np.concatenate([s.positions for s in sets]),
                           np.concatenate([s.velocities for s in sets]),
                           np.concatenate([s.forces for s in sets]) / samples,
                           np.concatenate([np.broadcast_to(np.eye(2), (s.n, 2, 2)) if s.isotropic
                                           else s.limits for s in sets]) if aniso else None)
    keep = big.forces > 0
    big = big.subset(keep)
    eq = solve_equilibrium(big)
    resistance = big.resistance(eq.velocity, eq.omega)
    step = se2_step(eq.velocity, eq.omega, gait.period)
    return AveragedModel(big, eq, resistance, step[:2], float(step[2]))


@dataclass(frozen=True)
class GaitComparison:
    """A cycle's net motion against the averaged model's prediction.

    Attributes
    ----------
    cycle : CycleMotion
    averaged : AveragedModel
    error : float, m
        ``|averaged displacement - cycle displacement|``.
    relative_error : float
        ``error / |cycle displacement|``.
    rotation_error : float, rad
    """

    cycle: CycleMotion
    averaged: AveragedModel
    error: float
    relative_error: float
    rotation_error: float


def compare_averaged(gait: Gait, cycle: CycleMotion | None = None, samples: int = 256) -> GaitComparison:
    """The averaged model's error against a cycle (default the quasi-static one)."""
    cycle = quasi_static_cycle(gait, samples) if cycle is None else cycle
    avg = averaged_model(gait, samples)
    err = float(np.hypot(*(avg.displacement - cycle.displacement)))
    norm = float(np.hypot(*cycle.displacement))
    return GaitComparison(cycle, avg, err, err / norm if norm > 0 else math.inf,
                          abs(avg.rotation - cycle.rotation))


# -- constructors ---------------------------------------------------------------------------
def tripod_gait(*, period: float = 1.0, duty: float = 0.6, speed: float = 0.1,
                turn: float = 0.0, length: float = 0.2, width: float = 0.12, mu: float = 0.5,
                weight: float = 9.81, load_shift: float = 0.0, samples: int = 240) -> Gait:
    """A hexapod's alternating tripod gait.

    Legs at ``(+-length/2 | 0, +-width/2)`` (front, middle, rear; left ``y > 0``), tripods
    {front-left, middle-right, rear-left} and the other three, half a period apart. A
    stance leg sweeps backwards at ``speed (1 -+ turn)`` (left / right) relative to the body,
    from ``+stride/2`` to ``-stride/2`` ahead of its hip (``stride = speed * duty * period``);
    its contact velocity is ``(speed (1 -+ turn), 0)``. Each tripod carries the weight share
    ``p_A / (p_A + p_B)`` with ``p = sin(pi tau / (duty period))`` over its stance (so loads
    go to zero at touchdown and lift-off and the total is ``weight`` at every instant);
    ``load_shift`` moves load from the rear legs to the front ones (fraction of a leg's share).

    Parameters
    ----------
    period : float, s
    duty : float
        Stance fraction of the period, ``0.5 < duty < 1`` (the tripods overlap).
    speed : float, m/s
    turn : float
        Differential sweep ``(-1, 1)``: left legs slower than right ones for ``turn > 0``.
    length, width : float, m
    mu : float
        Friction coefficient (``f = mu N``).
    weight : float, N
    load_shift : float
        In ``(-1, 1)``.
    samples : int
        Samples over the period.
    """
    owner = "tripod_gait"
    T = as_float(period, "period", owner, low=0.0, low_open=True)
    beta = as_float(duty, "duty", owner, low=0.5, low_open=True, high=1.0)
    if beta == 1.0:
        raise ParameterError(parameter_message("duty", owner, "be < 1 (legs must swing)", beta))
    u = as_float(speed, "speed", owner)
    k = as_float(turn, "turn", owner, low=-1.0, high=1.0)
    shift = as_float(load_shift, "load_shift", owner, low=-1.0, high=1.0)
    K = as_int(samples, "samples", owner, low=8)
    L, W = as_float(length, "length", owner, low=0.0), as_float(width, "width", owner, low=0.0)
    f_total = as_float(mu, "mu", owner, low=0.0, low_open=True) * as_float(weight, "weight", owner, low=0.0, low_open=True)
    hips = np.array([[L / 2, W / 2], [0.0, W / 2], [-L / 2, W / 2],
                     [L / 2, -W / 2], [0.0, -W / 2], [-L / 2, -W / 2]])
    tripod = np.array([0, 1, 0, 1, 0, 1])               # FL, ML, RL, FR, MR, RR
    side_speed = np.where(hips[:, 1] > 0, u * (1 - k), u * (1 + k))
    share = np.array([1 + shift, 1.0, 1 - shift] * 2)
    t = np.arange(K) * T / K
    stance = beta * T
    pos = np.empty((K, 6, 2))
    vel = np.zeros((K, 6, 2))
    load = np.zeros((K, 6))
    for i in range(6):
        tau = (t - tripod[i] * T / 2) % T                # time since touchdown
        on = tau < stance
        p = np.where(on, np.sin(np.pi * np.minimum(tau, stance) / stance), 0.0)
        stride = side_speed[i] * stance
        x = np.where(on, stride / 2 - side_speed[i] * tau, 0.0)
        pos[:, i] = hips[i] + np.c_[x, np.zeros(K)]
        vel[:, i, 0] = np.where(on, side_speed[i], 0.0)
        load[:, i] = p
    # Weight shares: each tripod's p over the sum of both, split over its legs by 'share'.
    pa = load[:, tripod == 0][:, 0]
    pb = load[:, tripod == 1][:, 0]
    total = pa + pb
    frac = np.where(tripod == 0, pa[:, None], pb[:, None]) / total[:, None]
    load = f_total * frac * share / 3.0
    return Gait(T, t, pos, vel, load)


def serpenoid(*, period: float = 1.0, length: float = 0.5, amplitude: float = 0.8,
              waves: float = 1.0, elements: int = 60, mu: float = 0.3, weight: float = 9.81,
              ratio: float = 3.0, samples: int = 120) -> Gait:
    """A snake's lateral undulation (a serpenoid curve) with anisotropic friction.

    The tangent angle along the body is ``psi(s, t) = A sin(2 pi (waves s / length - t /
    period))``, ``s`` the arc length: a wave travelling tailwards. Each of ``elements`` equal
    segments carries ``mu weight / elements`` with an elliptical limit surface whose axis is
    the local tangent and whose ratio (across / along) is ``ratio``. The shape is expressed
    about its centroid, with the frame turned so that the head-to-tail axis stays along x
    (the body frame), and the contact velocities are minus the shape's rate of change in that
    frame (an element that does not move over the ground does not slip).
    """
    owner = "serpenoid"
    T = as_float(period, "period", owner, low=0.0, low_open=True)
    Ltot = as_float(length, "length", owner, low=0.0, low_open=True)
    A = as_float(amplitude, "amplitude", owner)
    m = as_int(elements, "elements", owner, low=3)
    K = as_int(samples, "samples", owner, low=8)
    k = as_float(ratio, "ratio", owner, low=0.0, low_open=True)
    f_total = as_float(mu, "mu", owner, low=0.0, low_open=True) * as_float(weight, "weight", owner, low=0.0, low_open=True)
    waves = as_float(waves, "waves", owner)
    ds = Ltot / m
    s_mid = (np.arange(m) + 0.5) * ds
    s_nodes = np.arange(m + 1) * ds

    def shape(tt: float) -> tuple[np.ndarray, np.ndarray]:
        psi = A * np.sin(2 * np.pi * (waves * s_nodes / Ltot - tt / T))
        # Nodes by integrating the tangent (trapezoid on the fine node grid, exact enough: the
        # body is defined by these nodes); element centres and tangents from the nodes.
        mid_psi = 0.5 * (psi[1:] + psi[:-1])
        steps = ds * np.c_[np.cos(mid_psi), np.sin(mid_psi)]
        nodes = np.vstack((np.zeros(2), np.cumsum(steps, axis=0)))
        centres = 0.5 * (nodes[1:] + nodes[:-1])
        # Body frame: origin at the centroid, x along head-to-tail (mean direction of the body).
        axis = nodes[-1] - nodes[0]
        turn = math.atan2(axis[1], axis[0])
        c, sn = math.cos(turn), math.sin(turn)
        rot = np.array([[c, sn], [-sn, c]])
        rel = (centres - centres.mean(axis=0)) @ rot.T
        return rel, mid_psi - turn

    t = np.arange(K) * T / K
    pos = np.empty((K, m, 2))
    angle = np.empty((K, m))
    for j, tt in enumerate(t):
        pos[j], angle[j] = shape(tt)
    # Shape velocity by a centred difference of the periodic samples (second order in T / K)
    # refined by sampling at +-h inside each interval.
    h = T / K * 1e-3
    vel = np.empty((K, m, 2))
    for j, tt in enumerate(t):
        vel[j] = -(shape(tt + h)[0] - shape(tt - h)[0]) / (2 * h)
    load = np.full((K, m), f_total / m)
    aniso = np.stack((angle, np.full((K, m), k)), axis=-1)
    return Gait(T, t, pos, vel, load, aniso)
