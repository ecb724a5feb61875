"""What the model-based estimators know, and the known input they compute from the wheels.

:class:`EstimatorModel` is the plant as an estimator knows it (friction magnitudes, mass,
sensors, motor lag, drag, speed limits, wander); its :meth:`~EstimatorModel.increment` is the
known input over one sample period: the simulator's exact flow
(:func:`toolkit.simulation.advance`) from the estimated speed, with the contacts moving from
the wheel-measured speeds (:mod:`toolkit.estimation.contact_speeds`) towards the command by
the motor law, linearized for the filter, and the process noise of what the filter does not
know of it. Derivations: docs/estimation.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from ..laws import quantization_variance
from ..errors import as_float, as_float_array, as_int, check_nonnegative
from ..errors import ParameterError, ParameterTypeError, parameter_message
from .._compiled import core as _core
from .._compiled import kernels
from ..model.contacts import ContactSet, weighted_median
from ..model.friction import contact_forces
from ..model.motors import MotorPiece, Motors, lag_memory, unsaturated_response
from ..model.plant import Plant
from ..model.sensors import Sensors

__all__ = ["EstimatorModel"]

#: The kernels' event codes by :class:`~toolkit.simulation.Event` kind.
_KIND_CODES = {"cross": _core.CROSS, "stick": _core.STICK, "release": _core.RELEASE}


class Period(NamedTuple):
    """One sample period of the exact flow as the estimators linearize it."""

    #: Body speed at the end, m/s.
    V: float
    #: Body displacement over the period, m.
    displacement: float
    #: The contact the body ends stuck on (-1: none).
    stuck: int
    #: Events, rows ``(t, kind, contact, V)`` (s, the kernels' codes, -1 for none, m/s).
    events: np.ndarray


#: Relative margin (of ``max(1, |V|, |dV|)``, m/s) by which a body must fall short of the next
#: contact speed for the between-contacts shortcut: far above the rounding of ``F h / m`` and
#: of the speeds' differences (1e-16 relative), far below any speed the filter resolves.
QUIET_MARGIN = 1e-12


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
    contact_drift : float, m/s per sqrt(s)
        Random-walk intensity of a settled contact's speed (motor speed wander the wheel
        windows do not resolve), ``>= 0``; default 0: a settled motor holds its speed, as the
        motor law (``toolkit.model.motors``) says. A body stuck on a contact follows it:
        its speed then wanders as much.
    speed_limits : tuple of 2 floats, m/s
        The motors' speed limits (``Motors.speed_limits``): commands beyond them are clipped
        by the motor law (:meth:`~toolkit.model.Motors.clip`), as the plant clips them.
    """

    forces: np.ndarray
    mass: float
    sensors: Sensors
    motor_lag: float = 0.0
    damping: float = 0.0
    friction_uncertainty: float = 0.0
    max_window: int = 25
    contact_drift: float = 0.0
    speed_limits: tuple[float, float] = (-math.inf, math.inf)
    _motors: Motors = field(init=False, repr=False)
    _settle: int = field(init=False, repr=False)
    _friction_var: float = field(init=False, repr=False)
    _held_noise: np.ndarray = field(init=False, repr=False)
    _reach: float = field(init=False, repr=False)
    _follow: float = field(init=False, repr=False)
    _plants: tuple | None = field(init=False, repr=False)
    _friction_noise: np.ndarray = field(init=False, repr=False)
    _between: Any = field(init=False, repr=False)
    _read_noise: float = field(init=False, repr=False)
    _period_moments: tuple = field(init=False, repr=False)

    def __post_init__(self) -> None:
        owner = "EstimatorModel"
        forces = as_float_array(self.forces, "forces", owner)
        check_nonnegative(forces, "forces", owner)
        object.__setattr__(self, "forces", forces)
        object.__setattr__(self, "mass", as_float(self.mass, "mass", owner, low=0.0, low_open=True))
        if not isinstance(self.sensors, Sensors):
            raise ParameterTypeError(parameter_message("sensors", owner, "be a Sensors", self.sensors))
        if self.sensors.n_wheels != forces.size:
            raise ParameterError(parameter_message(
                "sensors", owner, f"have n_wheels = len(forces) = {forces.size}", self.sensors.n_wheels))
        for name in ("motor_lag", "damping", "friction_uncertainty", "contact_drift"):
            object.__setattr__(self, name, as_float(getattr(self, name), name, owner, low=0.0))
        object.__setattr__(self, "max_window", as_int(self.max_window, "max_window", owner, low=1))
        self._derive(None)

    def adjusted(self, forces: Any, motor_lag: float, contact_drift: float) -> EstimatorModel:
        """This model with the friction magnitudes ``forces`` (N, shape (n,)), the motor lag
        (s) and the contacts' drift (m/s per sqrt(s)) replaced, each checked as the
        constructor checks it; equal to constructing it anew, but the parts that depend on
        none of the changed values are shared (an adaptive filter rebuilds its model at its
        estimates every few samples)."""
        owner = "EstimatorModel.adjusted"
        if forces is self.forces and motor_lag == self.motor_lag:
            # The wander alone: only the held contacts' noise depends on it.
            new = object.__new__(EstimatorModel)
            new.__dict__.update(self.__dict__)
            object.__setattr__(new, "contact_drift", as_float(contact_drift, "contact_drift", owner, low=0.0))
            new._wander()
            return new
        forces = as_float_array(forces, "forces", owner)
        check_nonnegative(forces, "forces", owner)
        if forces.size != self.n:
            raise ParameterError(parameter_message("forces", owner, f"have length n = {self.n}", forces.size))
        new = object.__new__(EstimatorModel)
        new.__dict__.update(self.__dict__)
        object.__setattr__(new, "forces", forces)
        object.__setattr__(new, "motor_lag", as_float(motor_lag, "motor_lag", owner, low=0.0))
        object.__setattr__(new, "contact_drift", as_float(contact_drift, "contact_drift", owner, low=0.0))
        new._derive(self)
        return new

    def _derive(self, previous: EstimatorModel | None) -> None:
        """The derived fields from the checked ones; the motors and the plants of
        ``previous`` (a model of the same sensors, mass, drag and speed limits) are shared
        where its lag, or its lag and magnitudes, are this one's."""
        forces = self.forces
        # 4 lags for the motors plus one sample for the gearbox play, in whole samples.
        object.__setattr__(self, "_settle", 1 + math.ceil(4.0 * self.motor_lag * self.sensors.rate))
        object.__setattr__(self, "_friction_var", self.friction_uncertainty**2 * float(np.dot(forces, forces))
                           if self.friction_uncertainty > 0.0 else 0.0)
        # Largest speed change over a period: the whole friction, one way.
        object.__setattr__(self, "_reach", float(forces.sum()) * self.sensors.period / self.mass)
        # A settled contact's speed as a random walk of intensity contact_drift: over a
        # period the speed of a body that follows it changes by the white-noise
        # acceleration model's drift^2 [[h^3 / 3, h^2 / 2], [h^2 / 2, h]].
        h = self.sensors.period
        if previous is None:
            # What depends on the period and the sensors alone (shared by every adjusted model).
            g = np.array([0.5 * h * h, h])
            object.__setattr__(self, "_period_moments", (
                np.array([[h**3 / 3.0, h * h / 2.0], [h * h / 2.0, h]]), np.outer(g, g)))
            object.__setattr__(self, "_read_noise", self.sensors.read_noise_variance)
        if previous is None or previous.contact_drift != self.contact_drift:
            self._wander()
        # Largest move of the equilibrium set's edges over a period that a body on it
        # follows: the smallest step of the staircase, 2 min f_i > 0, for the period.
        smallest = float(np.min(forces, where=forces > 0, initial=math.inf))
        object.__setattr__(self, "_follow", 2.0 * smallest * h / self.mass if smallest < math.inf else 0.0)
        # The plant whose exact flow is the known input: held contacts (ideal motors take
        # the command at once) and, with a lag, the same contacts behind lagging motors;
        # both clip commands to the speed limits. Built at the first flow (:meth:`_plant`):
        # held periods run the engine without them (:meth:`period`).
        same_lag = previous is not None and previous.motor_lag == self.motor_lag
        motors = previous._motors if same_lag else Motors(lag=self.motor_lag, speed_limits=self.speed_limits)
        object.__setattr__(self, "speed_limits", motors.speed_limits)
        object.__setattr__(self, "_motors", motors)
        same = same_lag and previous._plants is not None and bool((previous.forces == forces).all())
        object.__setattr__(self, "_plants", previous._plants if same else None)   # (one length: n)
        # The friction spread's force error, held over the period: (sigma_F / m)^2 g g^T with
        # g = (h^2 / 2, h).
        if previous is None or previous._friction_var != self._friction_var:
            spread = self._period_moments[1] * (self._friction_var / self.mass**2)
            spread.setflags(write=False)
            object.__setattr__(self, "_friction_noise", spread)
        # The between-contacts shortcut: for unequal magnitudes (an adaptive filter's model at
        # its estimates), where bodies creep across bands the nominal equal ones hold exactly.
        object.__setattr__(self, "_between", self._quiet_between if forces.max() > forces.min() else None)

    def _wander(self) -> None:
        """The held contacts' noise from ``contact_drift`` (the white-noise acceleration model)."""
        held = self.contact_drift**2 * self._period_moments[0]
        held.setflags(write=False)
        object.__setattr__(self, "_held_noise", held)

    def _plant(self, held: bool) -> Plant:
        """The plant of :meth:`flow`: held contacts, or contacts behind the lagging motors
        (built at the first flow)."""
        plants = self._plants
        if plants is None:
            contacts = ContactSet(np.zeros(self.n), self.forces)
            motors = self._motors
            ideal = Plant(contacts, self.mass, damping=self.damping,
                          motors=Motors(lag=0.0, speed_limits=motors.speed_limits))
            plants = (ideal, Plant(contacts, self.mass, damping=self.damping, motors=motors)
                      if self.motor_lag > 0 else ideal)
            object.__setattr__(self, "_plants", plants)
        return plants[0 if held else 1]

    @property
    def n(self) -> int:
        """Number of contacts."""
        return int(self.forces.size)

    @property
    def settle(self) -> int:
        """Samples after a command change before the wheel differences are trusted."""
        return self._settle

    def reading_variance(self, speed: Any) -> Any:
        """Variance of one wheel reading, m^2: the quantization's ``q^2 / 12``, the declared
        read noise's (:attr:`Sensors.read_noise_variance` counts^2) and the jitter's ``(v
        sigma_t)^2`` for a contact at ``speed`` (m/s)."""
        sensors = self.sensors
        q = sensors.wheel.distance_per_count
        return quantization_variance(q) + q * q * self._read_noise + (speed * sensors.jitter) ** 2

    def clip(self, commands: Any) -> np.ndarray:
        """Commands clipped to the motors' speed limits (the motor law's clip), m/s."""
        return self._motors.clip(np.asarray(commands, dtype=float))

    # -- the known input --------------------------------------------------------------------
    def period_track(self, speeds: np.ndarray, commands: np.ndarray, steady: np.ndarray) -> np.ndarray:
        """The track of each sample period: contact speeds at its start and their target.

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
        ndarray of shape (k, 2, n), m/s
            Row 0 the start speeds, row 1 the target (the command, or the start speeds when
            steady). Without a motor lag the contacts take the command at once: both rows
            are the target.
        """
        target = np.where(np.asarray(steady, dtype=bool)[:, None], speeds, self.clip(commands))
        start = speeds if self.motor_lag > 0 else target
        return np.stack((start, target), axis=1)

    def end_speeds(self, track: np.ndarray) -> np.ndarray:
        """Contact speeds at the end of the period(s) of ``track`` (the motor law), m/s."""
        return unsaturated_response(track[..., 0, :], track[..., 1, :], self.sensors.period,
                                    self.motor_lag, math.inf)

    def increment(self, V: float, track: np.ndarray, contact_std: float, speed_std: float,
                  steady: bool, bounds: Any = None, force: float = 0.0, gains: np.ndarray | None = None
                  ) -> tuple[float, float, np.ndarray, tuple[float, float] | None, float | None, bool]:
        """Known input over one sample period from body speed ``V`` (m/s).

        Parameters
        ----------
        V : float, m/s
            Body speed estimate at the start of the period.
        track : ndarray of shape (2, n), m/s
            The period's start speeds and target (:meth:`period_track`).
        contact_std, speed_std : float, m/s
            Std of the contact-speed estimates and of ``V``.
        steady : bool
            Contacts steady over the period.
        bounds : sequence of 6 floats, optional
            :meth:`bounds_row` of ``track`` and ``force`` (computed when needed and not given).
        force : float, N
            Outside force held over the period (known exactly).
        gains : ndarray of shape (2, n + 1), optional
            Filled, when given, with the first-order sensitivity of ``(X+, V+)`` to relative
            errors ``e_i`` of the friction magnitudes (``f_i (1 + e_i)``, columns ``0 .. n -
            1``) and to an error of the drag (N s/m, column ``n``) (:meth:`force_gains`).

        Returns
        -------
        dx, dV : float
            Position (m) and speed (m/s) increments of the flow from ``V``: ``x+ = x + h V
            + dx``, ``V+ = V + dV``.
        Q : ndarray of shape (2, 2)
            Process noise of ``(X, V)`` over the period (docs/estimation.md).
        slopes : tuple of 2 floats or None
            ``(dX+/dV, dV+/dV)`` of the flow; ``None`` for ``(h, 1)`` (no event, no drag).
        arrival : float or None, (m/s)^2
            When the body reaches the equilibrium set within the period and sticks there,
            ``V+`` is a contact speed (``dV+/dV = 0``) that errs by the contact estimate:
            ``contact_std^2``. ``None`` otherwise.
        on_set : bool
            The body ends the period on the equilibrium set (stuck, coasting in a zero
            band, carried along, or arrived).

        Notes
        -----
        Without drag: a body on the equilibrium set with steady contacts stays on it (``dV =
        0``, the settled contacts' noise); a body farther from every contact speed of the
        period than both ``w`` (below) and the period's largest speed change ``(F_tot + |F|)
        h / m`` feels the whole friction one way (``dV = (+-F_tot + F) h / m``, ``dx = dV h /
        2``, no crossing); with unequal magnitudes and held contacts, one that does not reach
        the next contact speed in its direction within the period feels its region's constant
        force (:meth:`_quiet_between`). With moving contacts (a command change) a body
        within ``w = 2 sqrt(speed_std^2 + contact_std^2)`` of the set at the start of the
        period whose edges move by at most ``2 min f_i h / m`` over the period (the speed the
        smallest stiction step can give it, docs/physics.md section 4) stays inside it, or follows
        the contact at its edge when it is on that contact (:meth:`_carried`). Otherwise the
        exact flow (:meth:`flow`) and its linearization.
        """
        if self.damping == 0.0:
            b = bounds if bounds is not None else self.bounds_row(track, force)
            smin, smax, lo_eq, hi_eq, lo0, hi0 = b
            w = 2.0 * math.sqrt(speed_std * speed_std + contact_std * contact_std)
            if steady and lo_eq <= V <= hi_eq:
                if gains is not None:
                    self._coast_gains(V, track[0], lo_eq < V < hi_eq, gains)
                return 0.0, 0.0, self._held_noise, None, None, True
            if (not steady and V - w <= hi0 and V + w >= lo0
                    and max(abs(lo_eq - lo0), abs(hi_eq - hi0)) <= self._follow):
                out = self._carried(V, track, b, contact_std, force)
                if gains is not None:
                    if out[3] is None and out[4] is None:     # inside the set, or on its edge contact
                        self._coast_gains(V, track[0], lo_eq < V < hi_eq and lo0 < V < hi0, gains)
                    else:
                        self.force_gains(V, track, force, gains, out)
                return out
            # Every contact speed of the period out of reach: the whole friction one way.
            push = force * self.sensors.period / self.mass if force != 0.0 else 0.0
            reach = max(w, self._reach + abs(push))
            if smin - V > reach or V - smax > reach:
                dV = push + (self._reach if smin - V > reach else -self._reach)
                if gains is not None:
                    self._coast_gains(V, track[0], True, gains)
                return 0.5 * dV * self.sensors.period, dV, self._friction_noise, None, None, False
            if steady and self._between is not None:
                quiet = self._between(V, track[0], force)
                if quiet is not None:
                    if gains is not None:
                        self._coast_gains(V, track[0], True, gains)
                    return 0.5 * quiet * self.sensors.period, quiet, self._friction_noise, None, None, False
        step = self.period(V, track, force)
        if gains is None:
            return self._linearized(V, track, force, step, contact_std)
        response, signs = np.empty(2), np.empty(self.n)
        out = self._linearized(V, track, force, step, contact_std, response, signs)
        self.force_gains(V, track, force, gains, out, step, response, signs)
        return out

    def _quiet_between(self, V: float, speeds: np.ndarray, force: float) -> float | None:
        """A body between two held contact speeds that does not reach the next one in its
        direction within the period (the region's net force, the friction law's, carries it
        less far, by more than the rounding :data:`QUIET_MARGIN`): ``dV = F h / m`` with ``F``
        the region's constant force (as the whole-friction shortcut, for any region), to
        rounding what the exact flow gives (no event: the flow's slopes and gains are the
        free body's). None otherwise (the flow decides), and where a speed lies beyond the
        speed limits (the flow clips it; an estimate of a motor at its limit may overshoot)."""
        below, above = -math.inf, math.inf
        low, high = self.speed_limits
        for v in speeds.tolist():
            if v < V:
                below = max(below, v)
            elif v > V:
                above = min(above, v)
            else:
                return None                          # on a contact speed: stick or pass
            if not low <= v <= high:
                return None
        dV = (float(contact_forces(speeds - V, self.forces).sum()) + force) * self.sensors.period / self.mass
        margin = QUIET_MARGIN * max(1.0, abs(V), abs(dV))
        ok = above - V > dV + margin if dV >= 0.0 else V - below > margin - dV
        return dV if ok else None

    def _coast_gains(self, V: float, speeds: np.ndarray, free: bool, gains: np.ndarray) -> None:
        """:meth:`increment`'s ``gains`` of a period without events: a body that slides
        (``free``) feels each force error ``f_i e_i sign(v_i - V)`` and ``-dc V`` for the
        whole period (``dV = dF h / m``, ``dx = dF h^2 / (2 m)``); a stuck one none."""
        if not free:
            gains[:] = 0.0
            return
        h, m, n = self.sensors.period, self.mass, self.n
        gv = h / m
        gains[1, :n] = self.forces * np.sign(speeds - V) * gv
        gains[1, n] = -V * gv
        gains[0] = gains[1] * (0.5 * h)

    def force_gains(self, V: float, track: np.ndarray, force: float, gains: np.ndarray,
                    out: tuple | None = None, step: Any = None, response: np.ndarray | None = None,
                    signs: np.ndarray | None = None) -> np.ndarray:
        """First-order sensitivity of the period's end ``(X+, V+)`` to the force errors, into
        ``gains`` (2, n + 1): columns ``i < n`` a relative error ``e_i`` of ``f_i``, column
        ``n`` an error of the drag (N s/m).

        The end state's response ``g_F`` to an extra outside force held over the period is
        the exact flow's, linearized along its events (:meth:`_linearized`'s ``response``,
        given or computed here: crossings, sticking and release are the simulator's; a body
        that ends stuck feels none); each force error acts through it with the contact's sign
        relative to the body averaged over the period (``signs``: they flip at the step's
        crossings), ``f_i s_i``, and the drag's ``-V`` averaged over the start and end speeds.
        """
        n = self.n
        if step is not None and not len(step.events) and self.damping == 0.0:
            # No event in the period: the signs hold throughout and the response to a force
            # is the free body's (or none, stuck all along): the closed form.
            self._coast_gains(V, track[0], step.stuck < 0, gains)
            return gains
        if step is None:
            step = self.period(V, track, force)
        if out is None or response is None or signs is None:
            response, signs = np.empty(2), np.empty(n)
            out = self._linearized(V, track, force, step, 0.0, response, signs)
        g_x, g_v = float(response[0]), float(response[1])
        gains[0, :n] = self.forces * signs * g_x
        gains[1, :n] = self.forces * signs * g_v
        V_mean = V + 0.5 * out[1]
        gains[0, n] = -V_mean * g_x
        gains[1, n] = -V_mean * g_v
        return gains

    def flow(self, V: float, track: np.ndarray, force: float = 0.0) -> Any:
        """The plant's exact flow over one period from body speed ``V`` (m/s): the
        :class:`~toolkit.simulation.ExactStep` of :func:`~toolkit.simulation.advance` with
        the contacts at ``track[0]`` moving towards ``track[1]`` (held when equal) and the
        outside force ``force`` (N)."""
        from ..simulation import ExactState, advance

        start, target = track[0], track[1]
        held = bool((start == target).all())           # (the rows of one track: one shape)
        plant = self._plant(held)
        state = ExactState(0.0, float(V), start)
        step = advance(plant, state, target, self.sensors.period, external=float(force))
        if not step.success:
            raise RuntimeError(f"the estimator's flow failed over one period: {step.message}")
        return step

    def period(self, V: float, track: np.ndarray, force: float = 0.0) -> Period:
        """:meth:`flow` as the linearization reads it (a ``Period``). Held contacts run the
        exact engine directly at this model's magnitudes, no plant built
        (:func:`toolkit._compiled.core.batch_scene`: the staircase, then the very loop of
        :func:`~toolkit.simulation.advance`, the same doubles); moving ones take :meth:`flow`."""
        start, target = track[0], track[1]
        if self.motor_lag > 0.0 and not bool((start == target).all()):
            step = self.flow(V, track, force)
            ev = np.array([(e.time, _KIND_CODES.get(e.kind, -1), -1 if e.contact is None else e.contact, e.speed)
                           for e in step.events]) if step.events else np.empty((0, 4))
            stuck = step.state.stuck
            return Period(step.state.V, step.body_displacement, -1 if stuck is None else stuck, ev)
        low, high = self.speed_limits
        slowest, fastest = float(target.min()), float(target.max())
        if not (math.isfinite(slowest) and math.isfinite(fastest) and math.isfinite(V) and math.isfinite(force)):
            # (as advance refuses them: the engine would carry NaN, or clip an infinite speed)
            name, value = (("track", track) if not (math.isfinite(slowest) and math.isfinite(fastest))
                           else ("V", V) if not math.isfinite(V) else ("force", force))
            raise ParameterError(parameter_message(name, "EstimatorModel.period", "be finite", value))
        u = target if low <= slowest and fastest <= high else self.clip(target)
        n = self.n
        rows = 4 * n + 16                     # a period has at most 2 n + 2 rounds of two rows each
        fstate, istate = np.zeros(_core.N_FSTATE), np.zeros(_core.N_ISTATE, dtype=np.int64)
        seg, ev = np.empty((rows, 7)), np.empty((rows, 4))
        K = kernels("core", 40 * n)
        V1, nev, _, code, _ = K.batch_scene(
            np.ascontiguousarray(u).reshape(1, n), self.forces.reshape(1, n), 0, self.mass, self.damping,
            float(force), float(V), self.sensors.period, -1.0, np.empty(n, dtype=np.int64),
            np.empty((3, n + 1)), np.empty(n, dtype=np.int64), fstate, istate, seg, ev)
        if code != _core.DONE:
            raise RuntimeError(f"the estimator's flow failed over one period (kernel code {code})")
        body = K.displacement(seg, int(istate[_core.I_NSEG]), 0.0, self.sensors.period)
        return Period(float(V1), float(body), int(istate[_core.I_STUCK]), ev[:nev])

    def _linearized(self, V: float, track: np.ndarray, force: float, step: Period, contact_std: float,
                    response: np.ndarray | None = None, signs: np.ndarray | None = None
                    ) -> tuple[float, float, np.ndarray, tuple[float, float] | None, float | None, bool]:
        """Increments, process noise and slopes of one exact step (docs/estimation.md).

        Walks the events of ``step`` (:meth:`period`) in order
        (:func:`toolkit._compiled.core.linearize_step`),
        keeping the net force of the current segment, ``dV/dV0`` (``J``) and, per contact,
        the gain of its start-speed error on ``(X, V)`` (a contact's error enters once per
        event it takes part in; the sum over its events is its gain, so ``Q = var_v sum_i g_i
        g_i^T``). A contact crossed while the body is stuck on another changes nothing until
        the body is released; a release recomputes the force from the contact law, the
        released contacts on the side they pull to.

        ``response`` (shape (2,)), when given, is filled with ``d(X+, V+)/dF`` (m/N, s/kg) of
        an extra outside force ``F`` held over the period: each free stretch of length ``dt``
        adds ``expm1_ratio(k, dt) / m`` to ``dV/dF`` (decaying it by the drag's ``exp(-k
        dt)``, ``k = c / m``) and the integral to ``dX/dF``; a crossing scales it as it
        scales ``J`` (the crossing time moves, the acceleration changes there); sticking
        zeroes it (the stiction absorbs the force); a release restarts it from 0 (the body
        leaves the contact's speed). ``signs`` (shape (n,)), when given, is filled with each
        contact's sign relative to the body averaged over the period (it flips at the step's
        crossings of that contact).
        """
        h, m = self.sensors.period, self.mass
        dV = step.V - V
        dx = step.displacement - V * h
        on_set = step.stuck >= 0
        if not len(step.events) and self.damping == 0.0:
            if response is not None:        # free all period, or stuck all along: none
                response[:] = (0.0, 0.0) if on_set else (0.5 * h * h / m, h / m)
            if signs is not None:
                signs[:] = np.sign(track[0] - V)
            return dx, dV, self._friction_noise, None, None, on_set
        out, average = self._walk(V, track, force, step, contact_std * contact_std)
        Q = np.array([[out[2], out[3]], [out[3], out[4]]])
        if on_set:
            Q += self._held_noise
        if response is not None:
            response[:] = out[6:8]
        if signs is not None:
            signs[:] = average
        return dx, dV, Q, (float(out[0]), float(out[1])), None if math.isnan(out[5]) else float(out[5]), on_set

    def _walk(self, V: float, track: np.ndarray, force: float, step: Period, var_v: float
              ) -> tuple[np.ndarray, np.ndarray]:
        """:func:`toolkit._compiled.core.linearize_step` over ``step``'s events: its ``out``
        (slopes, ``Q`` without the held noise, arrival, force response) and the contacts'
        average signs."""
        start, target = track[0], track[1]
        n = self.n
        ev = step.events
        lagging = self.motor_lag > 0 and not np.array_equal(start, target)
        noise = self._friction_noise
        out, average = np.empty(8), np.empty(n)
        kernels("core", 20 * n * (len(ev) + 1)).linearize_step(
            ev, len(ev), float(V), start, target, lagging, self.motor_lag, self.forces, self.mass,
            self.damping, self.sensors.period, float(force), var_v,
            np.array([noise[0, 0], noise[0, 1], noise[1, 1]]), np.empty((5, n)), np.empty((7, n)),
            np.empty((3, n), dtype=bool), np.empty(n, dtype=np.int64), average, out)
        return out, average

    def _carried(self, V: float, track: np.ndarray, b: Any, contact_std: float, force: float
                 ) -> tuple[float, float, np.ndarray, tuple[float, float] | None, float | None, bool]:
        """A body on a slowly moving equilibrium set stays on it (see :meth:`increment`).

        Inside the set at the start and at the end of the period it keeps its speed. On the
        contact at an edge (``V = v_j(0)`` to rounding) it follows that contact:
        ``V+ - V = v_j(h) - v_j(0)`` and
        ``X+ - X - h V = int (v_j - v_j(0))``, the motor law's closed forms
        (:class:`~toolkit.model.motors.MotorPiece`), errs as ``v_j(0)``'s estimate moves
        them (``dv_j(h) / dv_j(0) = exp(-h / tau)``). Otherwise the exact flow.
        """
        lo_eq, hi_eq, lo0, hi0 = b[2], b[3], b[4], b[5]
        if lo_eq <= V <= hi_eq and lo0 <= V <= hi0:
            return 0.0, 0.0, self._held_noise, None, None, True
        start, target = track[0], track[1]
        h, tau = self.sensors.period, self.motor_lag
        edge = lo_eq if V < lo_eq else hi_eq
        end = self.end_speeds(track)
        # Exact only for a body on the edge contact itself (to rounding): one a little off
        # it would stick on it within the period (dV+/dV = 0), which the flow gives.
        candidates = np.flatnonzero((end == edge) & (np.abs(start - V) <= 1e-12 * max(1.0, abs(V))))
        if candidates.size != 1 or tau == 0.0:
            return self._linearized(V, track, force, self.period(V, track, force), contact_std)
        j = int(candidates[0])
        piece = MotorPiece.build(0.0, start[j:j + 1], target[j:j + 1], tau, math.inf)
        v0 = float(start[j])
        dV = float(end[j]) - v0
        dx = float(piece.displacement(h)[0]) - v0 * h
        decay, area = lag_memory(h, tau)
        gv, gx = decay - 1.0, area - h                    # d(dV)/dv_j(0), d(dx)/dv_j(0)
        var_v = contact_std * contact_std
        Q = self._held_noise + var_v * np.array([[gx * gx, gx * gv], [gx * gv, gv * gv]])
        return dx, dV, Q, None, None, True

    def bounds(self, track: np.ndarray, force: Any = None) -> np.ndarray:
        """Per sample, what decides the input without the flow (vectorized).

        Parameters
        ----------
        track : ndarray of shape (k, 2, n), m/s
            :meth:`period_track`.
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
        first, last = track[:, 0, :], self.end_speeds(track)
        end = self._edges(last, F)
        # Held rows (start = end) share the end's edges; only moving rows need their own.
        moving = np.flatnonzero(np.any(first != last, axis=1))
        lo0, hi0 = end[0].copy(), end[1].copy()
        if moving.size:
            lo0[moving], hi0[moving] = self._edges(first[moving], None if F is None else F[moving])
        return np.column_stack((np.minimum(first, last).min(axis=1), np.maximum(first, last).max(axis=1),
                                *end, lo0, hi0))

    def _edges(self, speeds: np.ndarray, force: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        # The weighted median (toolkit.model.weighted_median), the outside force as a
        # contact of magnitude |F| at sign(F) inf.
        return weighted_median(speeds, self.forces, force)

    def bounds_row(self, track: np.ndarray, force: float = 0.0) -> list[float]:
        """:meth:`bounds` of one sample, ``track`` of shape (2, n), with the period's
        outside force ``force`` (N) (the same numbers), as 6 floats."""
        start = track[0]
        # A held track (start = target; the bytes compared: cheap, and any equal pair they
        # miss, such as -0.0 and 0.0, ends where it starts under the motor law anyway).
        end = start if track[1] is start or track[1].tobytes() == start.tobytes() else self.end_speeds(track)
        out = np.empty(6)
        # One kernel call: the extremes and the edges, the one weighted median
        # (toolkit.model.weighted_median's kernel) without that function's checks.
        kernels("core", 6 * self.n).period_bounds(start, end, self.forces, float(force), out)
        return out.tolist()
