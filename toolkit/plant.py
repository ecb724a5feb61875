"""The plant: a body of mass ``m`` driven by active contacts, their motors and outside forces.

The body obeys the differential inclusion (PHYSICS.md section 2)

    m dV/dt in sum_i f_i Sign(v_i(t) - V) + F_ext(t) - c V

where ``v_i(t)`` are the contact speeds. With ideal motors the contact speeds equal the
(clipped) commands; with a :class:`Motors` model they follow the commands through a
first-order lag and/or a rate limit, and a compliant motor makes each contact force the
saturated linear function ``f_i clip((v_i - V) / (k f_i), -1, 1)`` of slip.

Everything here is data plus pure helpers that every simulation method shares
(:mod:`toolkit.simulation`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._validation import as_float, as_float_array, check_option
from .contacts import ContactSet
from .errors import ParameterError, ParameterTypeError, parameter_message

__all__ = ["PiecewiseConstant", "Motors", "Plant", "FRICTION_MODELS"]

#: Friction laws accepted by :meth:`Plant.contact_forces`.
FRICTION_MODELS = ("sign", "tanh", "stribeck")

#: Smoothed Stribeck law: peak (breakaway) force over the Coulomb force ...
STRIBECK_PEAK = 1.5
#: ... and Stribeck speed in units of the smoothing width ``epsilon``.
STRIBECK_SPEED = 3.0


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


@dataclass(frozen=True)
class Motors:
    """A motor model shared by all contacts.

    Parameters
    ----------
    lag : float, s
        First-order time constant ``tau``: ``dv/dt = (u - v) / tau``; ``0`` = no lag.
    rate_limit : float, m/s^2
        Bound on ``|dv/dt|`` (``inf`` = none). With ``lag = 0`` a finite rate limit makes
        the speed ramp to each new command at exactly this rate.
    speed_limits : tuple of float, m/s
        ``(low, high)``: commands are clipped to this range (``low <= high``).
    compliance : float, (m/s)/N
        Slope ``k`` of the motor's torque-speed line: the contact's actual speed droops by
        ``k`` times its contact force, so the contact force becomes the saturated linear
        function ``f_i clip((v_i - V) / (k f_i), -1, 1)``; ``0`` = stiff motor (Coulomb law).
    """

    lag: float = 0.0
    rate_limit: float = float("inf")
    speed_limits: tuple[float, float] = (float("-inf"), float("inf"))
    compliance: float = 0.0

    def __post_init__(self) -> None:
        owner = "Motors"
        object.__setattr__(self, "lag", as_float(self.lag, "lag", owner, low=0.0))
        if self.lag > 0 and not math.isfinite(1.0 / self.lag):
            raise ParameterError(parameter_message(
                "lag", owner, "be 0 or have a finite rate 1 / lag", self.lag))
        object.__setattr__(self, "rate_limit", as_float(
            self.rate_limit, "rate_limit", owner, low=0.0, low_open=True, finite=False))
        object.__setattr__(self, "compliance", as_float(
            self.compliance, "compliance", owner, low=0.0))
        limits = self.speed_limits
        if isinstance(limits, (str, bytes)) or not hasattr(limits, "__len__") or len(limits) != 2:
            raise ParameterTypeError(parameter_message(
                "speed_limits", owner, "be a pair (low, high) of speeds", limits))
        low = as_float(limits[0], "speed_limits", owner, finite=False)
        high = as_float(limits[1], "speed_limits", owner, finite=False)
        if not low <= high or low == float("inf") or high == float("-inf"):
            raise ParameterError(parameter_message(
                "speed_limits", owner, "satisfy low <= high with low < inf and high > -inf",
                limits))
        object.__setattr__(self, "speed_limits", (low, high))

    @property
    def dynamic(self) -> bool:
        """True when contact speeds lag behind the commands (a lag or a finite rate limit)."""
        return self.lag > 0 or np.isfinite(self.rate_limit)


def _nonneg_float(value: Any, name: str) -> float:
    return as_float(value, name, "Plant", low=0.0)


@dataclass(frozen=True, eq=False)
class Plant:
    """A body on active contacts: what every simulation method integrates.

    Parameters
    ----------
    contacts : ContactSet
        The friction magnitudes ``f_i`` (N) and the commanded contact speeds at ``t = 0``
        (m/s). When ``commands`` is given it overrides these speeds.
    mass : float, kg
        Moving inertia ``m > 0`` (for the carousel ``I / L^2``).
    damping : float, N s/m
        Bearing drag ``c >= 0``; the body feels ``-c V``.
    external_force : float or PiecewiseConstant (scalar), N
        Outside force ``F_ext(t)``.
    motors : Motors or None
        ``None`` = ideal motors: contact speeds equal the clipped commands at every instant.
    commands : PiecewiseConstant (vector of width n) or None
        Commanded contact speeds over time, m/s; ``None`` = constant ``contacts.speeds``.

    Notes
    -----
    Motors start settled: the contact speeds at ``t = 0`` are :meth:`command` ``(0)``.
    """

    contacts: ContactSet
    mass: float
    damping: float = 0.0
    external_force: float | PiecewiseConstant = 0.0
    motors: Motors | None = None
    commands: PiecewiseConstant | None = None
    _limits: tuple[float, float] = field(init=False, repr=False)
    _derived: dict[str, dict[Any, Any]] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.contacts, ContactSet):
            raise ParameterTypeError(parameter_message(
                "contacts", "Plant", "be a ContactSet", self.contacts))
        object.__setattr__(self, "mass", as_float(self.mass, "mass", "Plant", low=0.0, low_open=True))
        object.__setattr__(self, "damping", _nonneg_float(self.damping, "damping"))
        ext = self.external_force
        if isinstance(ext, PiecewiseConstant):
            if ext.width is not None:
                raise ParameterError(parameter_message(
                    "external_force", "Plant", "be a scalar signal (values of shape (k + 1,))",
                    f"values of shape {ext.values.shape}"))
        else:
            object.__setattr__(self, "external_force", as_float(ext, "external_force", "Plant"))
        if self.motors is not None and not isinstance(self.motors, Motors):
            raise ParameterTypeError(parameter_message(
                "motors", "Plant", "be a Motors instance or None", self.motors))
        if self.commands is not None:
            if not isinstance(self.commands, PiecewiseConstant):
                raise ParameterTypeError(parameter_message(
                    "commands", "Plant", "be a PiecewiseConstant or None", self.commands))
            if self.commands.width != self.contacts.n:
                raise ParameterError(parameter_message(
                    "commands", "Plant",
                    f"have values of shape (k + 1, {self.contacts.n}) (one column per contact)",
                    f"values of shape {self.commands.values.shape}"))
        limits = self.motors.speed_limits if self.motors is not None else (-np.inf, np.inf)
        object.__setattr__(self, "_limits", limits)
        self._check_scales()
        object.__setattr__(self, "_derived", {})

    def _check_scales(self) -> None:
        """Refuse parameters whose rates overflow or whose compliance is below rounding.

        Every method divides by the mass and by ``k f_i``: ``(F_tot + max|F_ext|) / m`` (the
        largest acceleration, m/s^2), ``c / m`` (the drag rate, 1/s) and ``1 / (k f_i)``
        must be finite. A compliance with ``k f_i <= 4 eps max|v_j|`` is below the speeds'
        rounding: its linear band is not resolved (use ``compliance=0``).
        """
        ext = self.external_force
        push = float(np.max(np.abs(ext.values))) if isinstance(ext, PiecewiseConstant) else abs(ext)
        accel = (self.contacts.total_force + push) / self.mass
        if not math.isfinite(accel):
            raise ParameterError(parameter_message(
                "mass", "Plant", f"keep the largest acceleration (F_tot + max|F_ext|) / m finite "
                f"(F_tot = {self.contacts.total_force:g} N, max|F_ext| = {push:g} N)", self.mass))
        if not math.isfinite(self.damping / self.mass):
            raise ParameterError(parameter_message(
                "damping", "Plant", f"keep the drag rate c / m finite (m = {self.mass:g} kg)",
                self.damping))
        k = self.compliance
        if k > 0:
            f = self.contacts.forces[self.contacts.forces > 0]
            speeds = self.contacts.speeds if self.commands is None else self.commands.values
            scale = float(np.max(np.abs(np.clip(speeds, *self._limits)), initial=0.0))
            floor = 4.0 * float(np.finfo(float).eps) * scale
            with np.errstate(over="ignore", divide="ignore"):
                resolved = np.all(k * f > floor) and np.all(np.isfinite(1.0 / (k * f)))
            if not resolved:
                raise ParameterError(parameter_message(
                    "motors", "Plant", f"have a compliance k with k f_i above the speeds' "
                    f"rounding 4 eps max|v| = {floor:.3g} m/s and 1 / (k f_i) finite for every "
                    f"contact (smallest f_i = {float(np.min(f)):g} N); use compliance=0 for a "
                    f"stiff motor", k))
            lag = self.motors.lag
            if lag > 0 and self.commands is not None:
                # The lagging motors pull the compliant force at up to n 2 max|v| / (tau k)
                # N/s, summed in the event functions: keep it (with 4 bits to spare) finite.
                with np.errstate(over="ignore"):
                    pull = 16.0 * self.n * (2.0 * scale / lag) / k
                if not math.isfinite(pull):
                    raise ParameterError(parameter_message(
                        "motors", "Plant", f"have a lag tau with 16 n 2 max|v| / (tau k) finite "
                        f"(n = {self.n}, max|v| = {scale:g} m/s, k = {k:g} (m/s)/N); use lag=0 "
                        f"for instantaneous motors", lag))

    def derived(self, name: str) -> dict[Any, Any]:
        """A named cache of quantities derived from this (immutable) plant.

        Solvers store what depends only on the plant here (e.g. the sorted force landscape
        of each command), so repeated simulations of one plant skip recomputing it. The
        plant's own fields never change; only this private cache grows.
        """
        cache = self._derived.get(name)
        if cache is None:
            cache = self._derived[name] = {}
        return cache

    def clear_derived(self) -> None:
        """Empty the caches of :meth:`derived`: the next run pays what a new plant would
        (benchmarks time runs from scratch this way)."""
        self._derived.clear()

    # -- properties ---------------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of contacts."""
        return self.contacts.n

    @property
    def compliance(self) -> float:
        """Motor compliance ``k`` ((m/s)/N), 0 for stiff or ideal motors."""
        return 0.0 if self.motors is None else self.motors.compliance

    @property
    def dynamic_motors(self) -> bool:
        """True when contact speeds are states (a motor lag or a finite rate limit)."""
        return self.motors is not None and self.motors.dynamic

    def switching_times(self) -> np.ndarray:
        """All times (s) at which the commands or the external force switch, ascending."""
        parts = [np.empty(0)]
        if self.commands is not None:
            parts.append(self.commands.times)
        if isinstance(self.external_force, PiecewiseConstant):
            parts.append(self.external_force.times)
        return np.unique(np.concatenate(parts))

    # -- helpers shared by every method ---------------------------------------------------
    def command(self, t: float) -> np.ndarray:
        """Commanded contact speeds at time ``t`` (s), clipped to the motor speed limits.

        Returns
        -------
        ndarray of shape (n,), m/s
        """
        raw = self.contacts.speeds if self.commands is None else self.commands(t)
        return raw if self.motors is None else np.clip(raw, *self._limits)

    def initial_speeds(self) -> np.ndarray:
        """Contact speeds at ``t = 0`` (motors start settled on ``command(0)``), m/s, shape (n,)."""
        return self.command(0.0)

    def final_command(self) -> np.ndarray:
        """The last commanded speeds (after every switch), clipped, m/s, shape (n,)."""
        raw = self.contacts.speeds if self.commands is None else self.commands.values[-1]
        return np.clip(raw, *self._limits)

    def external(self, t: float) -> float:
        """External force ``F_ext(t)``, N."""
        ext = self.external_force
        return ext(t) if isinstance(ext, PiecewiseConstant) else float(ext)

    def motor_rate(self, t: float, speeds: Any) -> np.ndarray:
        """``dv_i/dt`` of the motor model at time ``t`` for contact speeds ``speeds``.

        Parameters
        ----------
        t : float, s
        speeds : array_like of shape (n,), m/s

        Returns
        -------
        ndarray of shape (n,), m/s^2
            ``clip((u - v) / tau, -r, r)`` with a lag ``tau > 0``; ``r sign(u - v)`` with only
            a rate limit ``r``; zeros for ideal motors (their speeds jump with the commands).
        """
        v = np.asarray(speeds, dtype=float)
        motors = self.motors
        if motors is None or not motors.dynamic:
            return np.zeros_like(v)
        gap = self.command(t) - v
        if motors.lag > 0:
            return np.clip(gap / motors.lag, -motors.rate_limit, motors.rate_limit)
        return motors.rate_limit * np.sign(gap)

    def contact_forces(self, V: float, speeds: Any, *, friction: str = "sign",
                       epsilon: float = 0.0) -> np.ndarray:
        """Force of each contact on the body at body speed ``V``.

        Parameters
        ----------
        V : float, m/s
            Body speed.
        speeds : array_like of shape (n,), m/s
            Contact speeds ``v_i``.
        friction : {"sign", "tanh", "stribeck"}
            ``"sign"``: Coulomb ``f_i sign(v_i - V)`` with ``sign(0) = 0`` at a tie (the
            set-valued force there is ``[-f_i, f_i]``; the exact method resolves it).
            ``"tanh"``: ``f_i tanh(s / epsilon)`` with slip ``s = v_i - V``.
            ``"stribeck"``: ``f_i tanh(s / epsilon) (1 + (P - 1) exp(-(s / (S epsilon))^2))``
            with peak ratio ``P = STRIBECK_PEAK`` and Stribeck speed ``S epsilon``
            (``S = STRIBECK_SPEED``): a breakaway hump above the Coulomb level.
        epsilon : float, m/s
            Smoothing width, ``> 0`` for ``"tanh"`` and ``"stribeck"``.

        Returns
        -------
        ndarray of shape (n,), N

        Notes
        -----
        With motor compliance ``k > 0`` every friction option gives the saturated linear law
        ``f_i clip(s / (k f_i), -1, 1)``: it is already Lipschitz, there is nothing to smooth.
        """
        check_option(friction, "friction", "Plant.contact_forces", FRICTION_MODELS)
        slip = np.asarray(speeds, dtype=float) - V
        f = self.contacts.forces
        k = self.compliance
        if k > 0:
            scale = k * f
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = np.where(scale > 0, slip / np.where(scale > 0, scale, 1.0), 0.0)
            return f * np.clip(ratio, -1.0, 1.0)
        if friction == "sign":
            return f * np.sign(slip)
        eps = as_float(epsilon, "epsilon", "Plant.contact_forces", low=0.0, low_open=True)
        with np.errstate(over="ignore"):     # slip / eps = +-inf: tanh = +-1, exp(-inf) = 0
            smooth = np.tanh(slip / eps)
            if friction == "tanh":
                return f * smooth
            hump = np.exp(-(slip / (STRIBECK_SPEED * eps)) ** 2)
        return f * smooth * (1.0 + (STRIBECK_PEAK - 1.0) * hump)

    def net_force(self, t: float, V: float, speeds: Any, *, friction: str = "sign",
                  epsilon: float = 0.0) -> float:
        """Net force on the body, ``sum_i contact_forces + F_ext(t) - c V``, N."""
        contact = self.contact_forces(V, speeds, friction=friction, epsilon=epsilon)
        return float(np.sum(contact) + self.external(t) - self.damping * V)

    def equilibrium(self) -> tuple[float, float]:
        """Equilibrium set of the final constant commands, without external force or drag.

        Returns
        -------
        (lo, hi) : tuple of float, m/s
            The weighted median set of :meth:`final_command` (``lo == hi`` for a point,
            ``lo < hi`` for a zero-force band). With motor compliance ``k > 0`` the zero set
            of the continuous piecewise-linear force ``sum f_i clip((v_i - V)/(k f_i), -1, 1)``.
        """
        speeds = self.final_command()
        if self.compliance == 0:
            return self.contacts.with_speeds(speeds).equilibrium()
        return _compliant_zero_set(speeds, self.contacts.forces, self.compliance)


def compliant_breakpoints(speeds: np.ndarray, forces: np.ndarray, k: float) -> tuple[
        np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """The force-speed map ``F(V) = sum f_i clip((v_i - V)/(k f_i), -1, 1)`` of compliant
    contacts: continuous, piecewise linear, non-increasing.

    Parameters
    ----------
    speeds : ndarray of shape (n,), m/s
    forces : ndarray of shape (n,), N
    k : float, (m/s)/N
        Compliance, ``> 0`` (Plant makes sure ``k f_i`` is above the speeds' rounding).

    Returns
    -------
    x : ndarray of shape (K,), m/s
        Distinct saturation limits ``v_i +- k f_i`` of the contacts with ``f_i > 0``, ascending.
    at_x : ndarray of shape (K,), N
        ``F(x)``, snapped to 0 within ``4 (K + 1) eps F_tot``.
    first : ndarray of shape (K,), int
        The lowest index of the contacts saturating at each limit.
    slope : ndarray of shape (K + 1,), N s/m
        ``dF/dV`` inside interval ``j`` = ``(x[j-1], x[j])`` (0 below and above all limits).
    total : float, N
        ``F_tot`` of the contacts with ``f_i > 0``.
    """
    active = np.flatnonzero(forces > 0)
    v, fa = speeds[active], forces[active]
    points = np.concatenate((v - k * fa, v + k * fa))
    change = np.concatenate((np.full(v.size, -1.0 / k), np.full(v.size, 1.0 / k)))
    owner = np.concatenate((active, active))
    order = np.lexsort((owner, points))
    points, change, owner = points[order], change[order], owner[order]
    new = np.concatenate(([True], points[1:] != points[:-1]))
    group = np.cumsum(new) - 1
    x = points[new]
    change = np.bincount(group, weights=change, minlength=x.size)
    total = float(np.sum(fa))
    slope = np.concatenate(([0.0], np.cumsum(change)))           # slope inside interval j
    slope[-1] = 0.0                                                # exactly flat above all
    at_x = total + np.concatenate(([0.0], np.cumsum(slope[1:-1] * np.diff(x))))
    tol = 4.0 * (x.size + 1) * float(np.finfo(float).eps) * total
    at_x = np.where(np.abs(at_x) <= tol, 0.0, at_x)
    return x, at_x, owner[new], slope, total


def _compliant_zero_set(speeds: np.ndarray, forces: np.ndarray, k: float) -> tuple[float, float]:
    """Zero set of ``F(V) = sum f_i clip((v_i - V)/(k f_i), -1, 1)`` (continuous, non-increasing)."""
    x, values, _, _, _ = compliant_breakpoints(speeds, forces, k)
    zero = np.flatnonzero(values == 0.0)
    if zero.size:
        return float(x[zero[0]]), float(x[zero[-1]])
    j = int(np.flatnonzero(values < 0.0)[0])           # F(x[j-1]) > 0 > F(x[j])
    share = values[j - 1] / (values[j - 1] - values[j])
    point = float(x[j - 1] + share * (x[j] - x[j - 1]))
    return point, point
