"""What the model-based estimators know, and the known input they compute from the wheels.

The active-contact force is the known input of the Kalman filters: it is computed from the
contact speeds the wheel encoders measure, through the model's own contact law
(:func:`toolkit.model.friction.contact_forces`), never re-derived here.

An outside force ``F`` (N) that a controller applies over the period (a test rig's,
:class:`~toolkit.controllers.ForceDrive`; held like the command) is the other known input.
For the contact law it is one more contact, of magnitude ``|F|``, at a speed the body cannot
reach within the period (``sign(F) inf`` for the equilibrium set; in the exact coast a
finite speed beyond every contact speed by more than the period's largest speed change
``(F_tot + |F|) h / m``): ``|F| sign(v - V) = F`` for every ``V`` on the path. So the
equilibrium set (``{V : -F in F_c(V)}``, the weighted quantile ``(F_tot + F) / (2 F_tot)``
of the contact speeds; none when ``|F| > F_tot``: the body accelerates throughout), the
stiction rule at a contact speed and the exact coast all take it through the same law
(:class:`~toolkit.model.ContactSet`, :func:`~toolkit.model.friction.contact_forces`), and
between crossings the closed-form increments simply gain ``F / m``: ``dV = (F_c + F) h /
m``, ``dx = dV h / 2``. It is known exactly (the controller's own output): it adds no
process noise.

Contact speeds from the wheels (:func:`contact_speed_estimates`, vectorized over a record;
a loop uses :class:`ContactSpeedTracker`, the same formulas one row at a time): a straight
line fitted by least squares to the counts of a window that starts ``settle`` samples after
the last command change
(the motor lag and the gearbox play have then been taken up: 4 lags = 30 ms, and 0.8 mm
of play at 0.1 m/s is 8 ms) and spans at most ``max_window`` samples. Within the window
the contact runs at one speed ``v`` and reading ``i`` is ``x_0 + v t_i`` plus its
quantization error, ``q^2 / 12`` each (the sensor model's white approximation, as for the
central encoder): the least-squares slope ``sum (t_i - tbar) c_i q / S``, ``S = sum (t_i -
tbar)^2``, is the minimum-variance linear unbiased estimate of ``v`` from all ``m``
readings, with variance ``(q^2 / 12) / S``. Two readings (``m = 2``) give the plain
difference and its ``q^2 / (6 T^2)``; ``m`` equally spaced readings ``(q^2 / 12) 12 / (h^2
m (m^2 - 1))``, ``m (m + 1) / 12`` times less (a 26-sample window: 56x; the two end
readings alone left the 24 readings between them unused). Inside the
transient after a change the contact speeds are the motor law from the speeds at the
change (that row's own estimate) towards the command. The first command is a change when
the motors had settled elsewhere before it (``initial``, the record's
``initial_commands``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import as_float, as_float_array, as_int, check_nonnegative
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..model.contacts import ContactSet
from ..model.friction import contact_forces
from ..model.motors import unsaturated_response
from ..model.sensors import Sensors

__all__ = ["EstimatorModel", "contact_speed_estimates", "ContactSpeedTracker"]


@dataclass(frozen=True, eq=False)
class EstimatorModel:
    """The plant as an estimator knows it (no truth, only parameters).

    Parameters
    ----------
    forces : array_like of shape (n,), N
        Nominal friction magnitudes ``f_i >= 0``.
    mass : float, kg
        Moving inertia ``m > 0``.
    sensors : Sensors
        The encoders (resolutions, backlash, rate, noise figures).
    motor_lag : float, s
        First-order lag of the motors, ``>= 0``.
    damping : float, N s/m
        Bearing drag ``c >= 0``.
    friction_uncertainty : float
        Relative std of each ``f_i`` (unequal, unknown friction), ``>= 0``; default 0:
        the friction is the nominal one (pass the plant's true spread when it has one).
    max_window : int
        Longest window of the wheel-speed differences, samples (``>= 1``).
    substeps : int
        Sub-intervals per sample over which the input force is averaged (``>= 1``).
    """

    forces: np.ndarray
    mass: float
    sensors: Sensors
    motor_lag: float = 0.0
    damping: float = 0.0
    friction_uncertainty: float = 0.0
    max_window: int = 25
    substeps: int = 8
    _settle: int = field(init=False, repr=False)
    _ds: float = field(init=False, repr=False)
    _rest: np.ndarray = field(init=False, repr=False)
    _friction_var: float = field(init=False, repr=False)
    _probe_offsets: np.ndarray = field(init=False, repr=False)
    _stuck_scale: float = field(init=False, repr=False)
    _reach: float = field(init=False, repr=False)
    _forces_list: list = field(init=False, repr=False)
    _follow: float = field(init=False, repr=False)

    def __post_init__(self) -> None:
        owner = "EstimatorModel"
        forces = as_float_array(self.forces, "forces", owner)
        check_nonnegative(forces, "forces", owner)
        object.__setattr__(self, "forces", forces)
        object.__setattr__(self, "_forces_list", forces.tolist())
        object.__setattr__(self, "mass", as_float(self.mass, "mass", owner, low=0.0, low_open=True))
        if not isinstance(self.sensors, Sensors):
            raise ParameterTypeError(parameter_message("sensors", owner, "be a Sensors", self.sensors))
        if self.sensors.n_wheels != forces.size:
            raise ParameterError(parameter_message(
                "sensors", owner, f"have n_wheels = len(forces) = {forces.size}", self.sensors.n_wheels))
        for name in ("motor_lag", "damping", "friction_uncertainty"):
            object.__setattr__(self, name, as_float(getattr(self, name), name, owner, low=0.0))
        object.__setattr__(self, "max_window", as_int(self.max_window, "max_window", owner, low=1))
        object.__setattr__(self, "substeps", as_int(self.substeps, "substeps", owner, low=1))
        # 4 lags for the motors plus one sample for the gearbox play, in whole samples.
        object.__setattr__(self, "_settle", 1 + math.ceil(4.0 * self.motor_lag * self.sensors.rate))
        M = self.substeps
        object.__setattr__(self, "_ds", self.sensors.period / M)
        object.__setattr__(self, "_rest", M - np.arange(M) - 0.5)
        object.__setattr__(self, "_friction_var", self.friction_uncertainty**2 * float(np.dot(forces, forces)))
        object.__setattr__(self, "_probe_offsets", np.zeros((M + 2, 1)))
        # Largest speed change over a period: the whole friction, one way.
        object.__setattr__(self, "_reach", float(forces.sum()) * self.sensors.period / self.mass)
        object.__setattr__(self, "_stuck_scale", (self.mass / self.sensors.period) ** 2 / self.max_window)
        # Largest move of the equilibrium set's edges over a period that a body on it
        # follows: the smallest step of the staircase, 2 min f_i > 0, for the period.
        positive = forces[forces > 0]
        object.__setattr__(self, "_follow", 2.0 * float(positive.min()) * self.sensors.period / self.mass
                           if positive.size else 0.0)

    @property
    def n(self) -> int:
        """Number of contacts."""
        return int(self.forces.size)

    @property
    def settle(self) -> int:
        """Samples after a command change before the wheel differences are trusted."""
        return self._settle

    # -- the known input --------------------------------------------------------------------
    def substep_speeds(self, speeds: np.ndarray, commands: np.ndarray, steady: np.ndarray) -> np.ndarray:
        """Contact speeds at the midpoints of the sub-intervals of each sample period.

        Parameters
        ----------
        speeds : ndarray of shape (k, n), m/s
            Estimated contact speeds at the samples.
        commands : ndarray of shape (k, n), m/s
            Commands sent at the samples.
        steady : ndarray of shape (k,), bool
            False within ``settle`` samples of a command change: the motors then move
            towards the command (motor law), else they hold the measured speeds.

        Returns
        -------
        ndarray of shape (k, substeps, n), m/s
        """
        h, M = self.sensors.period, self.substeps
        target = np.where(steady[:, None], speeds, commands)
        # The motor law solved (toolkit.model.motors), at the sub-interval midpoints.
        s = ((np.arange(M) + 0.5) * (h / M))[None, :, None]
        return unsaturated_response(speeds[:, None, :], target[:, None, :], s, self.motor_lag, math.inf)

    def increment(self, V: float, sub: np.ndarray, contact_std: float, speed_std: float,
                  steady: bool, bounds: Any = None, force: float = 0.0
                  ) -> tuple[float, float, float, float | None, bool]:
        """Known input over one sample period from body speed ``V`` (m/s).

        Parameters
        ----------
        V : float, m/s
            Body speed estimate at the start of the period.
        sub : ndarray of shape (substeps, n), m/s
            Contact speeds at the sub-interval midpoints (:meth:`substep_speeds`).
        contact_std, speed_std : float, m/s
            Std of the contact-speed estimates and of ``V``.
        steady : bool
            Contacts steady over the period.
        bounds : sequence of 6 floats, optional
            :meth:`bounds_row` of ``sub`` and ``force`` (computed when needed and not given).
        force : float, N
            Outside force held over the period (known exactly; see the module docstring).

        Returns
        -------
        dx, dV : float
            Position (m) and speed (m/s) increments due to the contact force and the
            outside force (``x+ = x + h V + dx``, ``V+ = V + dV``).
        force_var : float, N^2
            Variance of the mean force over the period.
        arrival_var : float or None, (m/s)^2
            When the body reaches the equilibrium set within the period and sticks there,
            ``V+`` is that set's edge, a contact speed: it no longer depends on ``V``
            (the filter's transition has ``dV+/dV = 0``) and errs by the contact-speed
            estimate, variance ``contact_std^2``. ``None`` otherwise.
        on_set : bool
            The body ends the period on the equilibrium set (stuck, coasting in a zero
            band, carried along, or arrived).

        Notes
        -----
        Set-valued force (PHYSICS.md section 2). Without drag and with steady contacts: a
        body on the equilibrium set (``lo_eq <= V <= hi_eq``) stays there, ``dV = 0``, and
        no friction uncertainty enters (a stuck or coasting body keeps its speed whatever
        the friction spread); the floor is the stuck-on contact's undetected speed change,
        variance ``contact_std^2 / max_window`` per period. Off the set, the motion is the
        exact piecewise-constant one, crossing by crossing (:meth:`_coast`), ending on the
        set's near edge when it gets there (an arrival). With moving contacts (a command
        change) a body within ``w`` of the set at the start of the period stays on it when
        the set's edges move by at most ``2 min f_i h / m`` over the period (the speed the
        smallest stiction step can give it: it is carried along, the stiction rule of
        PHYSICS.md section 2): ``V+ = clip(V, lo_eq, hi_eq)`` at the end, with the stuck
        floor. Otherwise, with drag or moving contacts, the
        force is averaged over the sub-intervals along the body's path, found by two passes
        (the path from the first pass's forces, then the forces along that path).

        Force variance: unequal friction, ``epsilon^2 sum f_i^2``, plus the contacts the
        path crosses or passes within ``w = 2 sigma`` of, ``sigma = sqrt(speed_std^2 +
        contact_std^2)`` the std of a slip ``v_i - V``: the crossing of contact ``i`` flips
        its force by ``2 f_i`` at a time known to ``sigma_t = sigma / r_i``, ``r_i`` the
        slip's rate of change over the period (body acceleration minus the contact's), at
        most ``h / sqrt(12)`` (a crossing anywhere in the period); the impulse error
        ``2 f_i sigma_t`` is a mean-force error ``2 f_i sigma_t / h``. Independent slips
        add their variances (:meth:`_crossing_var`).
        """
        f, m, c = self.forces, self.mass, self.damping
        M = sub.shape[0]
        sigma = math.sqrt(speed_std * speed_std + contact_std * contact_std)
        w = 2.0 * sigma
        last = sub[-1]
        if steady and c == 0.0:
            lo_eq, hi_eq = (bounds if bounds is not None else self.bounds_row(sub, force))[2:4]
            if V - w <= hi_eq and V + w >= lo_eq:
                # Stuck (or coasting in a zero band): V+ = V errs by the stuck-on contact's
                # own speed change over the period (motor drift, a bias of the wheel
                # estimate). The wheels would see a random walk that accumulates more than
                # their window estimate's variance ``contact_std^2`` over the
                # ``max_window`` periods of the window, so the floor is ``contact_std^2 /
                # max_window`` per period, an acceleration held over it.
                return 0.0, 0.0, self._stuck_scale * contact_std * contact_std, None, True
            # Contacts held over the period: the exact piecewise-constant motion, crossing
            # by crossing (a body crosses several contacts per period while braking).
            dx, dV, arrived = self._coast(V, last, force)
            var = self._friction_var + self._crossing_var(V, dV, sub, sigma, arrived)
            return dx, dV, var, (contact_std * contact_std if arrived else None), arrived
        if c == 0.0:
            edges = bounds if bounds is not None else self.bounds_row(sub, force)
            lo_eq, hi_eq, lo0, hi0 = edges[2:]
            if V - w <= hi0 and V + w >= lo0 and max(abs(lo_eq - lo0), abs(hi_eq - hi0)) <= self._follow:
                return self._carried(V, lo_eq, hi_eq, contact_std)
        # One call of the contact law: the sub-interval rows at V, then the window's edges.
        probe = np.concatenate((sub, last[None], last[None]))
        probe -= self._offsets(V, w, M)
        net = contact_forces(probe, f).sum(axis=1)
        if force != 0.0:
            net += force                    # the outside force: a contact out of reach
        hi, lo = net[M], net[M + 1]
        if steady and lo <= c * V <= hi:
            # Stuck with drag (the same floor as above).
            return 0.0, 0.0, self._stuck_scale * contact_std * contact_std, None, True
        dt_m = self._ds / m
        first = net[:M] - c * V
        travel = float(np.sum(first)) * dt_m
        gaps = np.abs(sub - V)
        if c == 0.0 and float(np.min(gaps)) > abs(travel):
            # No contact speed within reach of the path: the force is the same all along.
            second = first
        else:
            path = V + (np.cumsum(first) - 0.5 * first) * dt_m
            second = contact_forces(sub - path[:, None], f).sum(axis=1) + force - c * path
        dV = float(np.sum(second)) * dt_m
        # Double integral of piecewise-constant accelerations: each acts for the rest of the period.
        dx = float(np.dot(second, self._rest)) * self._ds * dt_m
        return dx, dV, self._friction_var + self._crossing_var(V, dV, sub, sigma), None, False

    def _carried(self, V: float, lo_eq: float, hi_eq: float, contact_std: float
                 ) -> tuple[float, float, float, None, bool]:
        """A body on a slowly moving equilibrium set stays on it (see :meth:`increment`)."""
        dV = min(max(V, lo_eq), hi_eq) - V
        return 0.5 * dV * self.sensors.period, dV, self._stuck_scale * contact_std * contact_std, None, True

    def _crossing_var(self, V: float, dV: float, sub: np.ndarray, sigma: float,
                      arrived: bool = False) -> float:
        """Variance (N^2) of the mean force from uncertain crossing times (see :meth:`increment`).

        Contact ``i`` counts when its speed range over the period (first and last rows of
        ``sub``: the motor law is monotone) comes within ``2 sigma`` of the body's
        ``[V, V + dV]``; its slip changes at ``r_i = |dv_i - dV| / h`` and its crossing time
        is known to ``min(sigma / r_i, h / sqrt(12))``.
        """
        h = self.sensors.period
        w = 2.0 * sigma
        a, b = (V, V + dV) if dV >= 0.0 else (V + dV, V)
        start, end = sub[0], sub[-1]
        low = np.minimum(start, end)
        high = np.maximum(start, end)
        near = (high >= a - w) & (low <= b + w)
        if arrived:
            # The contacts the body sticks on are not crossed: V+ is their speed.
            near &= end != V + dV
        if not near.any():
            return 0.0
        rate = np.abs((end - start)[near] - dV) / h
        cap = h / math.sqrt(12.0)
        with np.errstate(divide="ignore"):
            t_std = np.minimum(np.where(rate > 0.0, sigma / rate, cap), cap)
        impulse = 2.0 * self.forces[near] * t_std / h
        return float(np.dot(impulse, impulse))

    def bounds(self, sub: np.ndarray, force: Any = None) -> np.ndarray:
        """Per sample, what decides the input without the contact law (vectorized).

        Parameters
        ----------
        sub : ndarray of shape (k, substeps, n), m/s
            :meth:`substep_speeds`.
        force : array_like of shape (k,), N, optional
            Outside force of each period (``None``: none). The equilibrium set is then
            ``{V : -F in F_c(V)}`` (``+-inf`` edges when ``|F| > F_tot``).

        Returns
        -------
        ndarray of shape (k, 6), m/s
            Slowest and fastest contact speed over the period, the equilibrium set ``(lo,
            hi)`` of the speeds at its end and that of the speeds at its start (the
            weighted median, as :meth:`ContactSet.equilibrium
            <toolkit.model.ContactSet.equilibrium>`).
        """
        F = None if force is None else np.asarray(force, dtype=float)
        if F is not None and not F.any():
            F = None
        end = self._edges(sub[:, -1, :], F)
        start = self._edges(sub[:, 0, :], F)
        return np.column_stack((sub.min(axis=(1, 2)), sub.max(axis=(1, 2)), *end, *start))

    def _edges(self, speeds: np.ndarray, force: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        forces = np.broadcast_to(self.forces, speeds.shape)
        if force is not None:
            # The outside force as a contact of magnitude |F| at sign(F) inf (out of reach;
            # a zero force: a contact of no weight, which changes nothing).
            speeds = np.column_stack((speeds, np.where(force >= 0.0, np.inf, -np.inf)))
            forces = np.column_stack((forces, np.abs(force)))
        order = np.argsort(speeds, axis=1)
        s = np.take_along_axis(speeds, order, axis=1)
        W = np.cumsum(np.take_along_axis(forces, order, axis=1), axis=1)
        half = 0.5 * W[:, -1:]
        tol = 1e-12 * half
        j1 = np.argmax(W >= half - tol, axis=1)
        j2 = np.argmax(W > half + tol, axis=1)
        rows = np.arange(speeds.shape[0])
        return s[rows, j1], s[rows, j2]

    def bounds_row(self, sub: np.ndarray, force: float = 0.0) -> list[float]:
        """:meth:`bounds` of one sample, ``sub`` of shape (substeps, n), with the period's
        outside force ``force`` (N) (the same numbers)."""
        # Plain floats: ten contacts cost less than the numpy calls. The motor law is
        # monotone in time, so the extremes over the period lie on its first or last row.
        first, last = sub[0].tolist(), sub[-1].tolist()
        lo, hi = self._edges_row(last, force)
        lo0, hi0 = (lo, hi) if first == last else self._edges_row(first, force)
        return [min(min(first), min(last)), max(max(first), max(last)), lo, hi, lo0, hi0]

    def _edges_row(self, speeds: list, force: float = 0.0) -> tuple[float, float]:
        pairs = sorted(zip(speeds, self._forces_list))
        if force != 0.0:
            # The outside force as a contact of magnitude |F| at sign(F) inf (see _edges).
            pairs.append((math.copysign(math.inf, force), abs(force)))
            pairs.sort()
        total = 0.0
        for _, f in pairs:
            total += f
        half = 0.5 * total
        tol = 1e-12 * half
        acc, lo, hi = 0.0, None, None
        for s, f in pairs:
            acc += f
            if lo is None and acc >= half - tol:
                lo = s
            if acc > half + tol:
                hi = s
                break
        if hi is None:                  # every magnitude zero (bounds: the first speed)
            hi = pairs[0][0]
        return lo, hi

    def quick_increment(self, V: float, sub: np.ndarray, contact_std: float, speed_std: float,
                        steady: bool, bounds: Any, force: float = 0.0
                        ) -> tuple[float, float, float, float | None, bool]:
        """:meth:`increment`, without the contact law where :meth:`bounds` decide it.

        Without drag: stuck when ``V`` lies on the equilibrium set (the same rule as
        :meth:`increment`); the whole friction one way when every contact speed of the
        period lies beyond ``V`` by more than both ``w = 2 sqrt(speed_std^2 +
        contact_std^2)`` and the largest speed change of a period, ``(F_tot + |F|) h / m``
        (no crossing, no force spread: ``dV = (+-F_tot + F) h / m``, ``dx = dV h / 2``).
        Otherwise :meth:`increment`. ``bounds``: :meth:`bounds_row` with the same ``force``.
        """
        if self.damping == 0.0:
            smin, smax, lo_eq, hi_eq, lo0, hi0 = bounds
            w = 2.0 * math.sqrt(speed_std * speed_std + contact_std * contact_std)
            if steady and V - w <= hi_eq and V + w >= lo_eq:
                return 0.0, 0.0, self._stuck_scale * contact_std * contact_std, None, True
            if not steady and V - w <= hi0 and V + w >= lo0 and \
                    max(abs(lo_eq - lo0), abs(hi_eq - hi0)) <= self._follow:
                return self._carried(V, lo_eq, hi_eq, contact_std)
            if force == 0.0:
                reach, push = max(w, self._reach), 0.0
            else:
                push = force * self.sensors.period / self.mass
                reach = max(w, self._reach + abs(push))
            if smin - V > reach:
                dV = self._reach + push
            elif V - smax > reach:
                dV = push - self._reach
            else:
                return self.increment(V, sub, contact_std, speed_std, steady, bounds, force)
            return 0.5 * dV * self.sensors.period, dV, self._friction_var, None, False
        return self.increment(V, sub, contact_std, speed_std, steady, bounds, force)

    def _coast(self, V: float, speeds: np.ndarray, force: float = 0.0) -> tuple[float, float, bool]:
        """Exact motion over one period with the contact speeds held (no drag): ``(dx, dV,
        arrived)`` from ``V``; the force is constant between contact speeds, and the body
        sticks where it reaches the equilibrium set (:meth:`ContactSet.equilibrium`);
        ``arrived``: it got there from outside within the period. An outside force ``force``
        (N) is one more contact of magnitude ``|F|`` at a speed the body cannot reach within
        the period (see the module docstring)."""
        f, m, h = self.forces, self.mass, self.sensors.period
        if force != 0.0:
            # Beyond every contact speed and V by more than the period's largest speed change.
            far = float(np.max(np.abs(speeds))) + abs(V) + (float(f.sum()) + abs(force)) * h / m + 1.0
            speeds = np.append(speeds, math.copysign(far, force))
            f = np.append(f, abs(force))
        contacts = ContactSet(speeds, f)
        lo_eq, hi_eq = contacts.equilibrium()
        t, v, x = 0.0, V, 0.0
        arrived = False
        for _ in range(2 * speeds.size + 2):
            if lo_eq <= v <= hi_eq:
                arrived = v != V or not (lo_eq <= V <= hi_eq)
                break                           # stuck for the rest of the period
            d = 1.0 if v < lo_eq else -1.0      # the body moves towards the set
            # The force just past v in the direction of motion: the end of the set-valued
            # force at v that the contacts at v give once passed (lower moving up).
            lower, upper = contacts.force_bounds(v)
            F = float(lower if d > 0 else upper)
            a = F / m
            ahead = speeds[(speeds - v) * d > 0.0]
            s = float(ahead.min() if d > 0 else ahead.max())  # the set lies ahead: never empty
            dt = (s - v) / a
            if t + dt >= h:
                rest = h - t
                x += v * rest + 0.5 * a * rest * rest
                v += a * rest
                t = h
                break
            x += v * dt + 0.5 * a * dt * dt
            v, t = s, t + dt
        x += v * (h - t)
        return x - V * h, v - V, arrived

    def _offsets(self, V: float, w: float, M: int) -> np.ndarray:
        out = self._probe_offsets
        out[:M] = V
        out[M] = V - w
        out[M + 1] = V + w
        return out


def contact_speed_estimates(wheel_counts: Any, commands: Any, times: Any, model: EstimatorModel,
                            *, first: int = 0, initial: Any = None
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contact speeds at the samples from wheel counts and commands (vectorized).

    Parameters
    ----------
    wheel_counts : array_like of shape (k, n), counts
    commands : array_like of shape (k, n), m/s
    times : array_like of shape (k,), s
    model : EstimatorModel
    first : int
        Unused (kept for compatibility; a loop uses :class:`ContactSpeedTracker`, the same
        formulas one row at a time).
    initial : array_like of shape (n,), m/s, optional
        The command the motors had settled at before row 0
        (:attr:`EncoderRecord.initial_commands <toolkit.model.sensors.EncoderRecord>`). When
        row 0's command differs, row 0 is a command change (a motor transient follows, the
        wheel window starts ``settle`` rows later) from the speeds ``initial``; ``None``:
        the motors already run at row 0's command.

    Returns
    -------
    speeds : ndarray of shape (k, n), m/s
    variance : ndarray of shape (k,), (m/s)^2
        Per-contact variance: the least-squares slope's ``(q^2 / 12) / S`` with ``S = sum
        (t_i - tbar)^2`` over the window's readings (see the module docstring); in a transient the motor law's own uncertainty, taken
        as 10 % of the remaining gap, squared, plus one period's quantization ``q^2 / (6
        h^2)``.
    steady : ndarray of shape (k,), bool
        False within ``settle`` samples after a command change (the motors move).
    """
    w = np.asarray(wheel_counts, dtype=float)
    u = np.asarray(commands, dtype=float)
    t = np.asarray(times, dtype=float)
    k = t.size
    q = model.sensors.wheel.distance_per_count
    idx = np.arange(k)
    changed = np.zeros(k, dtype=bool)
    changed[1:] = np.any(u[1:] != u[:-1], axis=1)
    c0 = None if initial is None else np.asarray(initial, dtype=float)
    if c0 is not None and k:
        changed[0] = bool(np.any(u[0] != c0))
    # Last change strictly before row j (changes at j act after t_j), -inf-like when none.
    marks = np.where(changed, idx, -10**9 if first == 0 else -10**9)
    last_change = np.maximum.accumulate(np.concatenate(([-10**9], marks[:-1])))
    settle = model.settle
    start = np.maximum(last_change + settle, idx - model.max_window)
    start = np.clip(start, 0, idx)
    ok = start < idx
    speeds = np.zeros_like(w)
    variance = np.zeros(k)
    # The least-squares line of each window: readings start..j padded with zeros to
    # max_window + 1 columns and summed column by column (zeros add nothing exactly);
    # ContactSpeedTracker's row is the same formula (equal to rounding).
    rows = np.flatnonzero(ok)
    L = model.max_window + 1
    ar = np.arange(L)
    for chunk in np.array_split(rows, rows.size // 8192 + 1):
        if not chunk.size:
            continue
        s0, last = start[chunk], chunk - start[chunk]
        inside = ar <= last[:, None]
        J = np.minimum(s0[:, None] + ar, k - 1)
        t_rel = np.where(inside, t[J] - t[s0][:, None], 0.0)
        total = np.zeros(chunk.size)
        for i in range(L):
            total += t_rel[:, i]
        tt = np.where(inside, t_rel - (total / (last + 1))[:, None], 0.0)
        tt2 = tt * tt
        S = np.zeros(chunk.size)
        for i in range(L):
            S += tt2[:, i]
        w_s = w[s0]
        cov = np.zeros((chunk.size, w.shape[1]))
        for i in range(L):
            cov += (w[J[:, i]] - w_s) * tt[:, i, None]
        speeds[chunk] = cov * (q / S)[:, None]
        variance[chunk] = (q * q / 12.0) / S
    steady = (idx - last_change) >= settle
    steady &= ~changed
    transient = ~ok
    if transient.any():
        has_change = last_change >= 0
        # Row 0 with no history: the speeds the motors had settled at, else the commands.
        none = transient & ~has_change
        speeds = np.where(none[:, None], u if c0 is None else c0, speeds)
        variance = np.where(none, (q * model.sensors.rate) ** 2, variance)
        # Inside the transient after a change, the motor law (toolkit.model.motors)
        # u + (v0 - u) exp(-(t - t_change) / tau) from the speeds at the change: that row's
        # own estimate (the window's when settled; the law continued from the change before
        # when the commands change again inside a transient; the settled speeds at row 0).
        # Rows of one change are contiguous (last_change does not decrease): in order.
        floor = q * q / 6.0 / model.sensors.period**2
        rows = np.flatnonzero(transient & has_change)
        if rows.size:
            owners = last_change[rows]
            cuts = np.flatnonzero(np.diff(owners)) + 1
            for seg in np.split(rows, cuts):
                c = int(last_change[seg[0]])
                law = unsaturated_response(speeds[c], u[c], (t[seg] - t[c])[:, None], model.motor_lag, math.inf)
                speeds[seg] = law
                variance[seg] = (0.1 * np.abs(law - u[c])).max(axis=1) ** 2 + floor
    return speeds, variance, steady


class ContactSpeedTracker:
    """:func:`contact_speed_estimates` one row at a time, for a loop (O(n max_window) per sample).

    The same formulas on the same numbers as the vectorized function (a test checks they
    agree to rounding), keeping only what the next rows need: the last ``max_window + 1``
    times and wheel counts, the last command change and the speeds at it. :meth:`push` also
    returns the sample's input ingredients (:meth:`EstimatorModel.substep_speeds` and
    :meth:`EstimatorModel.bounds` of the row).

    Parameters
    ----------
    model : EstimatorModel
    initial : array_like of shape (n,), m/s, optional
        As in :func:`contact_speed_estimates`.
    """

    def __init__(self, model: EstimatorModel, initial: Any = None) -> None:
        self.model = model
        self._q = model.sensors.wheel.distance_per_count
        self._settle = model.settle
        self._keep = model.max_window + 1
        self._initial = None if initial is None else np.array(initial, dtype=float)
        self._prev: np.ndarray | None = self._initial
        # Times and counts of the last rows (row j at column j - _base), compacted when full.
        self._cap = 4 * self._keep
        self._tb = np.empty(self._cap)
        self._wb = np.empty((self._cap, model.n))
        self._base = 0
        self._j = -1
        self._last_change = -10**9
        self._change: tuple[float, np.ndarray, np.ndarray] | None = None  # (t, u, before)
        # Sub-interval midpoints of a period (as EstimatorModel.substep_speeds), a column.
        M = model.substeps
        self._s = ((np.arange(M) + 0.5) * (model.sensors.period / M))[:, None]
        self._lag = model.motor_lag
        self._law_floor = self._q * self._q / 6.0 / model.sensors.period**2

    def push(self, t: float, wheel_counts: Any, command: Any
             ) -> tuple[np.ndarray, float, bool, np.ndarray]:
        """Take row ``j`` (its time, wheel counts, and the command sent then).

        Returns
        -------
        speeds : ndarray of shape (n,), m/s
        variance : float, (m/s)^2
        steady : bool
        sub : ndarray of shape (substeps, n), m/s
            :meth:`EstimatorModel.substep_speeds` of the row.
        """
        model, q = self.model, self._q
        j = self._j = self._j + 1
        w = np.array(wheel_counts, dtype=float)
        u = command if type(command) is np.ndarray and command.dtype == np.float64 else \
            np.asarray(command, dtype=float)
        col = j - self._base
        if col == self._cap:                 # keep the last keep - 1 rows, then append
            kept = self._keep - 1
            self._tb[:kept] = self._tb[col - kept:col]
            self._wb[:kept] = self._wb[col - kept:col]
            self._base += col - kept
            col = kept
        self._tb[col] = t
        self._wb[col] = w
        prev = self._prev
        changed = prev is not None and bool((u != prev).any())
        self._prev = u
        lc = self._last_change
        start = min(max(lc + self._settle, j - model.max_window, 0), j)
        ok = start < j
        if ok:
            # The least-squares line through the window's readings (contact_speed_estimates'
            # formula; its sums in another order: equal to rounding).
            # Times and counts relative to the window's first reading: no cancellation of
            # large stamps or counts however long the run.
            a = start - self._base
            tb, wb = self._tb[a:col + 1], self._wb[a:col + 1]
            t_rel = tb - tb[0]
            tt = t_rel - t_rel.sum() / (j - start + 1)
            S = float(tt @ tt)
            speeds = (tt @ (wb - wb[0])) * (q / S)
            variance = (q * q / 12.0) / S
        elif lc >= 0:
            t_c, u_c, before = self._change  # type: ignore[misc]
            law = unsaturated_response(before, u_c, t - t_c, self._lag, math.inf)
            speeds = law
            variance = float(np.max(0.1 * np.abs(law - u_c))) ** 2 + self._law_floor
        else:
            speeds = u if self._initial is None else self._initial
            variance = (q * model.sensors.rate) ** 2
        steady = (j - lc) >= self._settle and not changed
        if changed:
            # The speeds at the change: this row's own estimate (contact_speed_estimates).
            before = speeds
            self._last_change = j
            self._change = (t, u, before)
        # EstimatorModel.substep_speeds for this row: the motor law from the speeds towards
        # the command (not steady) or the speeds held (steady).
        if steady:
            sub = np.broadcast_to(speeds, (model.substeps, speeds.size))
        else:
            sub = unsaturated_response(speeds, u, self._s, self._lag, math.inf)
        return speeds, float(variance), steady, sub
