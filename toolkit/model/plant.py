"""The plant: a body of mass ``m`` driven by active contacts, their motors and outside forces.

The body obeys the differential inclusion (docs/physics.md section 2)

    m dV/dt in sum_i f_i Sign(v_i(t) - V) + F_ext(t) - c V

where ``v_i(t)`` are the contact speeds. With ideal motors the contact speeds equal the
(clipped) commands; with a :class:`~toolkit.model.motors.Motors` model they follow the
commands through the motor law (:func:`~toolkit.model.motors.motor_rate`), and a compliant
motor makes each contact force the saturated linear law of :mod:`toolkit.model.friction`.

A :class:`Plant` is parameters plus its right-hand side :meth:`Plant.rhs`; it holds no solver
state (solvers keep their caches to themselves).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import as_float
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ._xp import ops
from .contacts import ContactSet
from .friction import compliant_zero_set, contact_forces
from .motors import Motors, motor_rate
from .signals import PiecewiseConstant

__all__ = ["Plant"]


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
    def backlash(self) -> float:
        """Drive backlash ``b`` (m at the contact), 0 for ideal motors or no play."""
        return 0.0 if self.motors is None else self.motors.backlash

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
        """``dv_i/dt`` of the motor law (:func:`~toolkit.model.motors.motor_rate`) at time
        ``t`` (s) for contact speeds ``speeds`` (m/s, shape (n,)); m/s^2, shape (n,)."""
        v = np.asarray(speeds, dtype=float)
        if not self.dynamic_motors:
            return np.zeros_like(v)
        return motor_rate(self.motors, self.command(t), v)

    def contact_forces(self, V: Any, speeds: Any, *, friction: str = "sign",
                       epsilon: float = 0.0) -> np.ndarray:
        """Force of each contact on the body at body speed ``V``.

        Parameters
        ----------
        V : float or ndarray of shape (M, 1), m/s
            Body speed.
        speeds : array_like of shape (n,), m/s
            Contact speeds ``v_i``.
        friction : {"sign", "tanh", "stribeck"}
            The law of :func:`toolkit.model.friction.contact_forces` (``"sign"``: Coulomb
            with ``sign(0) = 0`` at a tie, the midpoint of the set-valued force; the exact
            method resolves the set itself).
        epsilon : float, m/s
            Smoothing width, ``> 0`` for ``"tanh"`` and ``"stribeck"``.

        Returns
        -------
        ndarray of shape (n,) (or (M, n)), N

        Notes
        -----
        With motor compliance ``k > 0`` every friction option gives the saturated linear law
        ``f_i clip(s / (k f_i), -1, 1)``: it is already Lipschitz, there is nothing to smooth.
        """
        slip = np.asarray(speeds, dtype=float) - V
        return contact_forces(slip, self.contacts.forces, law=friction, epsilon=epsilon,
                              compliance=self.compliance, owner="Plant.contact_forces")

    def net_force(self, t: float, V: float, speeds: Any, *, friction: str = "sign",
                  epsilon: float = 0.0) -> float:
        """Net force on the body, ``sum_i contact_forces + F_ext(t) - c V``, N."""
        contact = self.contact_forces(V, speeds, friction=friction, epsilon=epsilon)
        return float(np.sum(contact) + self.external(t) - self.damping * V)

    def rhs(self, t: float, x: Any, u: Any = None, *, external: Any = None,
            friction: str = "sign", epsilon: float = 0.0, xp: Any = np) -> Any:
        """The right-hand side ``dx/dt`` of the plant: one definition for every solver.

        Parameters
        ----------
        t : float, s
        x : array_like of shape (d,), or a casadi column
            State ``[V]`` (ideal or stiff motors without dynamics) or ``[V, v_1 .. v_n]``
            (m/s) when :attr:`dynamic_motors`.
        u : array_like of shape (n,), m/s, optional
            Commanded contact speeds (clipped to the motor speed limits here); ``None``:
            the plant's own :meth:`command` ``(t)``.
        external : float, N, optional
            ``F_ext``; ``None``: the plant's own :meth:`external` ``(t)``.
        friction, epsilon
            The friction law and its smoothing width (``"sign"`` returns the midpoint of
            the set-valued force at a tie, as :meth:`contact_forces` does).
        xp : module
            ``numpy`` (numbers) or ``casadi`` (``x``, ``u``, ``external`` symbolic).

        Returns
        -------
        ndarray of shape (d,) (or a casadi column), ``[dV/dt, dv_1/dt ..]`` in m/s^2
        """
        o = ops(xp)
        if not o.symbolic:                  # array_like state and command: lists too
            x = np.asarray(x, dtype=float)
            u = None if u is None else np.asarray(u, dtype=float)
        if u is None:
            command = self.command(t)
        else:
            command = u if self.motors is None else self.motors.clip(u, xp)
        ext = self.external(t) if external is None else external
        V = x[0]
        speeds = x[1:] if self.dynamic_motors else command
        slip = speeds - V
        contact = contact_forces(slip, self.contacts.forces, law=friction, epsilon=epsilon,
                                 compliance=self.compliance, xp=xp, owner="Plant.rhs")
        dV = (o.sum(contact) + ext - self.damping * V) / self.mass
        if not self.dynamic_motors:
            return dV if o.symbolic else np.atleast_1d(dV)
        return o.concat(dV, motor_rate(self.motors, command, speeds, xp))

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
        return compliant_zero_set(speeds, self.contacts.forces, self.compliance)
