"""Simulation of a rigid body on planar contacts, through slip and stick.

``M dx/dt in W(x, t) + w_ext - C x`` for the twist ``x = (Vx, Vy, omega)``, with ``W`` the
set-valued wrench of contacts fixed in the body. Methods: ``"exact"`` where a closed form
exists (a line: the 1-D engine; a passive disc, annulus or ring: the reduced ODE,
docs/planar.md section 4), ``"moreau"`` (certified Moreau-Jean steps) and ``"smooth"`` (the
regularized law, a baseline that creeps). :func:`simulate_planar`, also reached through
:func:`toolkit.simulate` with a :class:`PlanarPlant`."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import (ParameterError, ParameterTypeError, as_float, as_float_array, check_option,
                      parameter_message)
from .._compiled import budget_clock
from ..simulation import Budget, BudgetExceeded, Meter, SimulationStatus
from ._socp import NormSum, solve_fast
from .contacts import PlanarContactSet
from .equilibrium import twist_problem
from .regions import CurveRegion, DiscRegion, Quadrature, RingRegion, _annulus_shape, _ring_shape

__all__ = ["PlanarPlant", "PlanarSimulationResult", "PLANAR_METHODS", "simulate_planar", "check_start", "check_method", "MAX_SPEED"]

#: Methods of :func:`simulate_planar`.
PLANAR_METHODS = ("exact", "moreau", "smooth")
_OPTIONS = {"exact": (), "moreau": ("step", "tol"), "smooth": ("epsilon", "solver", "rtol", "atol")}
_EPS = float(np.finfo(float).eps)
_REGIONS = (DiscRegion, RingRegion, CurveRegion)


@dataclass(frozen=True, eq=False)
class PlanarPlant:
    """A rigid body on planar contacts.

    Parameters
    ----------
    contacts : PlanarContactSet, Quadrature, DiscRegion, RingRegion, CurveRegion or a schedule
        The contacts in the body frame, positions relative to the centre of mass. A region
        is cut into cells by its ``quadrature(resolution)`` for the stepping methods. A
        schedule (e.g. :class:`toolkit.planar.gaits.Gait`) is any object with a method
        ``contacts_at(t) -> PlanarContactSet`` (time-varying legs).
    mass : float, kg
    inertia : float, kg m^2
        About the centre of mass.
    external_force : array_like of shape (2,), N
        Constant, in the world frame.
    external_torque : float, N m
    damping : float, N s/m
        Linear drag ``-c V``.
    angular_damping : float, N m s
        Rotational drag ``-c_r omega``.
    resolution : int or float, optional
        Passed to the region's ``quadrature`` (rings of a disc, arcs of a ring, cell length
        of a curve in m); default that method's default.
    """

    contacts: Any
    mass: float
    inertia: float
    external_force: Any = (0.0, 0.0)
    external_torque: float = 0.0
    damping: float = 0.0
    angular_damping: float = 0.0
    resolution: Any = None
    _quadrature: Any = field(init=False, repr=False, default=None)

    def __post_init__(self) -> None:
        owner = "PlanarPlant"
        c = self.contacts
        if not (isinstance(c, (PlanarContactSet, Quadrature) + _REGIONS) or
                callable(getattr(c, "contacts_at", None))):
            raise ParameterTypeError(parameter_message(
                "contacts", owner, "be a PlanarContactSet, a Quadrature, a region or an object "
                "with contacts_at(t)", c))
        object.__setattr__(self, "mass", as_float(self.mass, "mass", owner, low=0.0, low_open=True))
        object.__setattr__(self, "inertia", as_float(self.inertia, "inertia", owner, low=0.0, low_open=True))
        ext = as_float_array(self.external_force, "external_force", owner)
        if ext.shape != (2,):
            raise ParameterError(parameter_message("external_force", owner, "be a 2-vector (N)", ext.tolist()))
        object.__setattr__(self, "external_force", ext)
        object.__setattr__(self, "external_torque", as_float(self.external_torque, "external_torque", owner))
        object.__setattr__(self, "damping", as_float(self.damping, "damping", owner, low=0.0))
        object.__setattr__(self, "angular_damping",
                           as_float(self.angular_damping, "angular_damping", owner, low=0.0))
        if isinstance(c, _REGIONS):
            quad = c.quadrature() if self.resolution is None else c.quadrature(self.resolution)
            object.__setattr__(self, "_quadrature", quad)
        elif isinstance(c, Quadrature):
            object.__setattr__(self, "_quadrature", c)

    @property
    def time_varying(self) -> bool:
        """True for a schedule of contacts (a gait)."""
        return not isinstance(self.contacts, (PlanarContactSet, Quadrature) + _REGIONS)

    def simulate(self, t_end: float, **arguments: Any) -> PlanarSimulationResult:
        """:func:`simulate_planar` of this plant (what :func:`toolkit.simulate` calls)."""
        return simulate_planar(self, t_end, **arguments)

    def contacts_at(self, t: float) -> PlanarContactSet:
        """The contacts (body frame) at time ``t`` (s)."""
        if self._quadrature is not None:
            return self._quadrature.contacts
        if isinstance(self.contacts, PlanarContactSet):
            return self.contacts
        return self.contacts.contacts_at(t)

    @property
    def unforced(self) -> bool:
        """No external force or torque and no drag."""
        return (not np.any(self.external_force) and self.external_torque == 0.0
                and self.damping == 0.0 and self.angular_damping == 0.0)


@dataclass(frozen=True, eq=False)
class PlanarSimulationResult:
    """The outcome of :func:`simulate_planar`.

    Attributes
    ----------
    t : ndarray of shape (T,), s
    position : ndarray of shape (T, 2), m
        Centre of mass, world frame.
    heading : ndarray of shape (T,), rad
    velocity : ndarray of shape (T, 2), m/s
        Centre-of-mass velocity, world frame.
    omega : ndarray of shape (T,), rad/s
    status : SimulationStatus
    method, setting, message : str
    steps : int
        Time steps (``"moreau"``), right-hand-side evaluations (``"smooth"``) or ODE steps
        (``"exact"``).
    wall_time : float, s
    stop_time : float or None, s
        When a body with passive contacts and no outside force came to rest for good (the
        exact time for ``"exact"``; the first step at rest for ``"moreau"``), else None.
    max_gap : float, J
        Largest duality gap of a Moreau-Jean step's convex program (0 for the other methods).
    solve_error : float, m/s
        A bound on the solve error of every step's velocity, ``sqrt(2 gap / m)`` at its worst
        (0 for the other methods); the time-discretization error is not in it (see
        :func:`toolkit.planar.precision.precision_report`).
    terminal_ratio : float or None
        For ``"exact"`` on a passive axisymmetric region: the limit of ``|V| / (R |omega|)``
        as both vanish (the reduced ODE run to ``R |omega| = e^-80`` of its start), else None.
    """

    t: np.ndarray
    position: np.ndarray
    heading: np.ndarray
    velocity: np.ndarray
    omega: np.ndarray
    status: SimulationStatus
    method: str
    setting: str
    message: str
    steps: int
    wall_time: float
    stop_time: float | None = None
    max_gap: float = 0.0
    solve_error: float = 0.0
    terminal_ratio: float | None = None

    @property
    def success(self) -> bool:
        """True when the run reached ``t_end``."""
        return self.status is SimulationStatus.SUCCESS

    @property
    def speed(self) -> np.ndarray:
        """``|V|``, m/s, shape (T,)."""
        return np.hypot(self.velocity[:, 0], self.velocity[:, 1])

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able summary (no samples): method, setting, status, message, t_final,
        final velocity and omega, steps, wall_time, stop_time, max_gap, solve_error."""
        return {"method": self.method, "setting": self.setting, "status": self.status.name,
                "message": self.message, "t_final": float(self.t[-1]),
                "velocity_final": self.velocity[-1].tolist(), "omega_final": float(self.omega[-1]),
                "steps": self.steps, "wall_time": self.wall_time, "stop_time": self.stop_time,
                "max_gap": self.max_gap, "solve_error": self.solve_error,
                "terminal_ratio": self.terminal_ratio}


def _freeze(*arrays: np.ndarray) -> None:
    for a in arrays:
        a.setflags(write=False)


def _result(t, pos, heading, vel, omega, status, method, setting, message, steps, started,
            **extra) -> PlanarSimulationResult:
    arrays = [np.ascontiguousarray(a, dtype=float) for a in (t, pos, heading, vel, omega)]
    _freeze(*arrays)
    return PlanarSimulationResult(*arrays, status=status, method=method, setting=setting,
                                  message=message, steps=int(steps),
                                  wall_time=time.perf_counter() - started, **extra)


#: Largest body or rim speed a planar run starts from, m/s (squares and products stay finite).
MAX_SPEED = 1e100


def check_start(plant: PlanarPlant, v0: Any, omega0: Any) -> tuple[np.ndarray, float]:
    """The start twist of a run on ``plant``: ``v0`` (2,), m/s, and ``omega0``, rad/s, checked
    (finite; body and rim speeds at most :data:`MAX_SPEED`: the methods square speeds and
    multiply them by the magnitudes, which must stay finite)."""
    V, omega = _as_vector(v0, "v0"), as_float(omega0, "omega0", "simulate")
    if float(np.hypot(*V)) > MAX_SPEED:
        raise ParameterError(parameter_message("v0", "simulate", f"have a magnitude <= {MAX_SPEED:g} m/s "
                                               "(its squares must stay finite)", V.tolist()))
    arm = plant.contacts_at(0.0).arm
    if abs(omega) * max(arm, 1.0) > MAX_SPEED:
        raise ParameterError(parameter_message(
            "omega0", "simulate", f"give rim speeds <= {MAX_SPEED:g} m/s (|omega0| times the contacts' "
            f"largest distance {arm:g} m, at least 1 m)", omega))
    return V, omega


def _as_vector(value: Any, name: str) -> np.ndarray:
    if isinstance(value, (int, float)) and not isinstance(value, bool) and value == 0:
        return np.zeros(2)
    array = as_float_array(value, name, "simulate")
    if array.shape != (2,):
        raise ParameterError(parameter_message(name, "simulate", "be a 2-vector (planar plant)",
                                               array.tolist()))
    return array


def simulate_planar(plant: PlanarPlant, t_end: float, *, v0: Any = 0.0, omega0: float = 0.0,
                    position: Any = (0.0, 0.0), heading: float = 0.0, method: str = "exact",
                    t_eval: Any = None, budget: Budget | None = None,
                    **options: Any) -> PlanarSimulationResult:
    """Simulate a :class:`PlanarPlant` from rest or from a given twist to ``t_end``.

    Parameters
    ----------
    plant : PlanarPlant
    t_end : float, s
    v0 : array_like of shape (2,), m/s
        Initial centre-of-mass velocity (world frame); 0 for rest.
    omega0 : float, rad/s
    position : array_like of shape (2,), m
    heading : float, rad
    method : {"exact", "moreau", "smooth"}
        See the module docstring. ``"exact"`` refuses a plant without a closed form.
    t_eval : array_like of shape (T,), s, optional
        Increasing times in ``[0, t_end]`` to report (the stepping methods land on them);
        default: the method's own steps (at most ``budget.max_samples``, decimated beyond).
    budget : Budget, optional
        Wall time, steps and samples (default ``Budget()``).
    **options
        ``"moreau"``: ``step`` (s, default ``t_end / 1000``), ``tol`` (duality gap of a step
        relative to its kinetic and dissipation terms, default 1e-12). ``"smooth"``: ``epsilon`` (m/s, required), ``solver``
        (``"RK45"``, ``"Radau"``, ``"LSODA"``, ``"BDF"``; default ``"Radau"``), ``rtol``,
        ``atol``.

    Returns
    -------
    PlanarSimulationResult
    """
    owner = "simulate"
    if not isinstance(plant, PlanarPlant):
        raise ParameterTypeError(parameter_message("plant", owner, "be a PlanarPlant", plant))
    t_end = as_float(t_end, "t_end", owner, low=0.0, low_open=True)
    check_option(method, "method", owner, PLANAR_METHODS)
    for name in options:
        if name not in _OPTIONS[method]:
            accepted = list(_OPTIONS[method])
            rule = (f"only name the options {accepted} of method {method!r}" if accepted
                    else f"be empty: method {method!r} takes no options")
            raise ParameterError(parameter_message("options", owner, rule, name))
    budget = Budget() if budget is None else budget
    if not isinstance(budget, Budget):
        raise ParameterTypeError(parameter_message("budget", owner, "be a Budget", budget))
    V, omega = check_start(plant, v0, omega0)
    state = _State(V, omega, _as_vector(position, "position"), as_float(heading, "heading", owner))
    times = None
    if t_eval is not None:
        times = as_float_array(t_eval, "t_eval", owner)
        if np.any(np.diff(times) < 0) or times[0] < 0 or times[-1] > t_end:
            raise ParameterError(parameter_message(
                "t_eval", owner, f"be non-decreasing times within [0, t_end = {t_end:g}]",
                times.tolist() if times.size <= 8 else f"[{times.min():g} .. {times.max():g}]"))
    if method == "exact":
        return _exact(plant, t_end, state, times, budget)
    if method == "moreau":
        return _moreau(plant, t_end, state, times, budget, **options)
    return _smooth(plant, t_end, state, times, budget, **options)


@dataclass(frozen=True)
class _State:
    V: np.ndarray
    omega: float
    position: np.ndarray
    heading: float


# -- exact: the 1-D line ----------------------------------------------------------------------------
def _line_case(plant: PlanarPlant, s: _State):
    """The 1-D reduction when it applies (constant contacts on a line through the centre of
    mass, velocities along it, the motion and the outside force along it), else None."""
    if plant.time_varying or s.omega != 0.0 or plant.external_torque != 0.0:
        return None
    contacts = plant.contacts_at(0.0)
    red = contacts.line_reduction()
    if red is None:
        return None
    e = red.direction
    scale = max(contacts.arm, 1.0)
    if np.hypot(*red.origin) > 16 * _EPS * scale:
        return None                                      # the line misses the centre of mass
    world = np.array([math.cos(s.heading) * e[0] - math.sin(s.heading) * e[1],
                      math.sin(s.heading) * e[0] + math.cos(s.heading) * e[1]])
    for vec in (s.V, plant.external_force):
        if abs(vec[0] * world[1] - vec[1] * world[0]) > 16 * _EPS * max(np.max(np.abs(vec)), 1e-300):
            return None
    return red, world


def _exact(plant: PlanarPlant, t_end: float, s: _State, times: np.ndarray | None,
           budget: Budget) -> PlanarSimulationResult:
    line = _line_case(plant, s)
    if line is not None:
        return _exact_line(plant, t_end, s, times, budget, *line)
    if _axisymmetric(plant):
        return _exact_axisymmetric(plant, t_end, s, times, budget)
    raise _no_closed_form()


def _axisymmetric(plant: PlanarPlant) -> bool:
    """A passive uniform disc or ring centred on the centre of mass (the second closed form)."""
    c = plant.contacts
    return isinstance(c, (DiscRegion, RingRegion)) and plant.unforced and not np.any(c.centre)


def _no_closed_form() -> ParameterError:
    return ParameterError(parameter_message(
        "method", "simulate", "be 'exact' only for a plant with a closed form (contacts and "
        "motion on one line through the centre of mass, or a passive uniform disc or ring "
        "centred on it, without outside force or drag); use method='moreau' (time stepping "
        "with certified steps)", "exact"))


def check_method(plant: PlanarPlant, method: str, v0: Any = 0.0, omega0: float = 0.0,
                 heading: float = 0.0) -> None:
    """Refuse ``method`` for a run of ``plant`` from ``(v0, omega0)`` before any work, as
    :func:`simulate_planar` would (``"exact"`` needs one of the two closed forms)."""
    check_option(method, "method", "simulate", PLANAR_METHODS)
    if method == "exact":
        V, omega = check_start(plant, v0, omega0)
        state = _State(V, omega, np.zeros(2), as_float(heading, "heading", "simulate"))
        if _line_case(plant, state) is None and not _axisymmetric(plant):
            raise _no_closed_form()


def _exact_line(plant, t_end, s, times, budget, red, world) -> PlanarSimulationResult:
    from ..model import Plant
    from ..simulation import ExactState, advance, simulate

    started = time.perf_counter()
    meter = Meter(budget)                                # the clock over the whole run
    plant1 = Plant(red.contacts, mass=plant.mass, damping=plant.damping,
                   external_force=float(plant.external_force @ world))
    v0 = float(s.V @ world)
    run = simulate(plant1, t_end, v0=v0, method="exact", t_eval=times, budget=budget)
    # Exact displacements between the samples (closed forms of the same engine), within the
    # wall-clock budget (the run counted the steps).
    status, message = run.status, run.message
    x = np.zeros(run.t.size)
    state = ExactState.initial(plant1, v0)
    command = red.contacts.speeds
    external = float(plant.external_force @ world)
    n = run.t.size
    try:
        for k in range(1, n):
            meter.check_clock()
            if run.t[k] > state.t:
                step = advance(plant1, state, command, float(run.t[k]), external=external,
                               budget=budget)
                if step.status is not SimulationStatus.SUCCESS:
                    raise BudgetExceeded(step.status, step.message)
                x[k] = x[k - 1] + step.body_displacement
                state = step.state
            else:
                x[k] = x[k - 1]
    except BudgetExceeded as stopped:
        n = k
        status, message = stopped.status, (f"{stopped.status.value} ({stopped.detail}, while "
                                           f"integrating the displacements to t = {run.t[k]:.6g} s)")
    pos = s.position + x[:n, None] * world
    vel = run.V[:n, None] * world
    return _result(run.t[:n], pos, np.full(n, s.heading), vel, np.zeros(n), status, "exact",
                   "1-D line: exact event-driven engine", "contacts and motion on one line: "
                   + message, run.n_steps, started)


# -- exact: the axisymmetric passive region ------------------------------------------------------
def _exact_axisymmetric(plant: PlanarPlant, t_end: float, s: _State, times: np.ndarray | None,
                        budget: Budget) -> PlanarSimulationResult:
    from scipy.integrate import solve_ivp

    started = time.perf_counter()
    region = plant.contacts
    R = region.radius
    shape = _ring_shape if isinstance(region, RingRegion) else _annulus_shape(region.inner_radius / R)
    a = region.force / plant.mass                         # m/s^2
    b = region.force * R * R / plant.inertia             # m/s^2 (rim)
    W0 = s.V - region.velocity
    v0 = float(np.hypot(*W0))
    w0 = R * abs(s.omega)
    direction = W0 / v0 if v0 > 0 else np.array([1.0, 0.0])
    spin = 1.0 if s.omega >= 0 else -1.0
    T0 = float(shape(np.array(0.0))[1])
    steps = 0
    if v0 == 0.0 and w0 == 0.0:
        stop = 0.0
        tau_t = None
    elif w0 == 0.0:
        stop = v0 / a
        tau_t = None
    elif v0 == 0.0:
        stop = w0 / (b * T0)
        tau_t = None
    else:
        # dtau = dt / w: d eps/dtau = -a F + b eps T, d ln w/dtau = -b T, dt/dtau = w,
        # ds/dtau = eps w^2, dphi/dtau = w^2 / R (docs/planar.md section 4).
        # Every evaluation is counted against the budget (steps: evaluations; and the clock):
        # a spent budget ends the run with its status at the simulated time last evaluated.
        meter = Meter(budget, counts="evaluations")
        reached = [0.0]

        def rhs(tau, y):
            meter.evaluation()
            reached[0] = max(reached[0], min(float(y[2]), t_end))
            eps, lw = y[0], y[1]
            F, T = shape(np.array(eps))
            w = w0 * math.exp(lw)
            return [-a * F + b * eps * T, -b * T, w, eps * w * w, w * w / R]

        def low(tau, y):
            return y[1] + 80.0                           # w = w0 e^-80: far below rounding
        low.terminal = True

        def late(tau, y):
            return y[2] - t_end                          # t(tau) reaches t_end: still moving
        late.terminal = True
        try:
            sol = solve_ivp(rhs, (0.0, 1e9), [v0 / w0, 0.0, 0.0, 0.0, 0.0], method="DOP853",
                            rtol=1e-13, atol=1e-15, dense_output=True, events=(low, late))
        except BudgetExceeded as stopped:
            return _result([0.0], s.position[None, :], [s.heading], s.V[None, :], [s.omega],
                           stopped.status, "exact", "reduced ODE, DOP853 rtol=1e-13",
                           f"{stopped.status.value} ({stopped.detail}; the reduced ODE had reached "
                           f"t = {reached[0]:.6g} s of {t_end:g} s; only the start is reported)",
                           min(meter.evaluations, budget.max_steps), started)
        steps = int(sol.nfev)
        tau_end = float(sol.t[-1])
        y_end = sol.y[:, -1]
        if sol.t_events[1].size:                         # no stop within the run
            stop = math.inf
        else:
            F_end, T_end = shape(np.array(y_end[0]))
            w_end = w0 * math.exp(y_end[1])
            stop = float(y_end[2] + w_end / (b * float(T_end)))
        tau_t = (sol, tau_end)
    grid = np.asarray(times, dtype=float) if times is not None else None
    if grid is None:
        if tau_t is not None:
            sol, tau_end = tau_t
            grid = np.unique(np.concatenate((np.minimum(sol.y[2], t_end), [min(stop, t_end), t_end])))
        else:
            grid = np.unique(np.array([0.0, min(stop, t_end), t_end]))
    v = np.zeros(grid.size)
    w = np.zeros(grid.size)
    dist = np.zeros(grid.size)
    turn = np.zeros(grid.size)
    moving = grid < stop
    if tau_t is not None:
        sol, tau_end = tau_t
        tg = grid[moving]
        # Invert t(tau) (increasing) by bisection on the dense output.
        lo = np.zeros(tg.size)
        hi = np.full(tg.size, tau_end)
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            below = sol.sol(mid)[2] < tg
            lo = np.where(below, mid, lo)
            hi = np.where(below, hi, mid)
        y = sol.sol(0.5 * (lo + hi))
        wt = w0 * np.exp(y[1])
        v[moving], w[moving], dist[moving], turn[moving] = y[0] * wt, wt, y[3], y[4]
        y_end = sol.sol(tau_end)
        dist[~moving], turn[~moving] = y_end[3], y_end[4]
        ratio = float(y_end[0]) if math.isfinite(stop) else None
        message = ("passive axisymmetric region: reduced ODE of the closed-form force and torque "
                   "(DOP853, rtol 1e-13); " + (f"stops at t = {stop:.12g} s with v / (R omega) -> "
                                               f"{ratio:.12g}" if ratio is not None else
                                               f"still moving at t_end = {t_end:g} s"))
        setting = "reduced ODE, DOP853 rtol=1e-13"
    else:
        tg = np.minimum(grid, stop)
        if w0 == 0.0:
            v = np.maximum(v0 - a * grid, 0.0)
            dist = v0 * tg - 0.5 * a * tg * tg
        else:
            w = np.maximum(w0 - b * T0 * grid, 0.0)
            turn = (w0 * tg - 0.5 * b * T0 * tg * tg) / R
        ratio = None
        message = (f"passive axisymmetric region, pure {'slide' if w0 == 0 else 'spin'}: "
                   f"closed form; stops at t = {stop:.12g} s")
        setting = "closed form"
    pos = s.position + dist[:, None] * direction
    vel = region.velocity + v[:, None] * direction
    heading = s.heading + spin * turn
    omega = spin * w / R
    return _result(grid, pos, heading, vel, omega, SimulationStatus.SUCCESS, "exact", setting,
                   message, steps, started, stop_time=float(stop) if stop <= t_end else None,
                   terminal_ratio=ratio)


# -- Moreau-Jean ---------------------------------------------------------------------------------
def _grid(t_end: float, step: float, times: np.ndarray | None, max_steps: int) -> np.ndarray:
    count = max(1, int(math.ceil(t_end / step - 1e-9)))
    if count > max_steps:           # the budget stops the run there: the rest is never built
        grid = np.arange(max_steps + 1) * (t_end / count)
    else:
        grid = np.linspace(0.0, t_end, count + 1)
    if times is not None:
        grid = np.unique(np.concatenate((grid, times)))
    return grid


def _moreau(plant: PlanarPlant, t_end: float, s: _State, times: np.ndarray | None,
            budget: Budget, step: float | None = None, tol: float = 1e-12) -> PlanarSimulationResult:
    started = time.perf_counter()
    h_nominal = t_end / 1000 if step is None else as_float(step, "step", "simulate", low=0.0, low_open=True)
    tol = as_float(tol, "tol", "simulate", low=0.0, low_open=True)
    grid = _grid(t_end, h_nominal, times, budget.max_steps)
    if grid.size - 1 > budget.max_steps:
        grid = grid[:budget.max_steps + 1]
    M = np.array([plant.mass, plant.mass, plant.inertia])
    C = np.array([plant.damping, plant.damping, plant.angular_damping])
    wext = np.array([plant.external_force[0], plant.external_force[1], plant.external_torque])
    x = np.array([s.V[0], s.V[1], s.omega])
    q = np.array([s.position[0], s.position[1], s.heading])
    keep = np.ones(grid.size, bool) if times is None else np.isin(grid, times)
    if times is None and grid.size > budget.max_samples:
        stride = int(math.ceil(grid.size / budget.max_samples))
        keep = np.zeros(grid.size, bool)
        keep[::stride] = True
        keep[-1] = True
    rec_t, rec_q, rec_x = [], [], []

    def record(k: int) -> None:
        if keep[k]:
            rec_t.append(grid[k])
            rec_q.append(q.copy())
            rec_x.append(x.copy())

    record(0)
    max_gap = 0.0
    max_err = 0.0
    stop_time = None
    status = SimulationStatus.SUCCESS
    passive_ok = plant.unforced and not plant.time_varying
    k_done = 0
    clock = budget_clock()
    for k in range(1, grid.size):
        if budget_clock() - clock > budget.wall_time:
            status = SimulationStatus.WALL_TIME
            break
        h = grid[k] - grid[k - 1]
        body = plant.contacts_at(grid[k])
        world = body.transformed(angle=q[2])
        x, gap = _moreau_step(world, M, C, wext, x, h, tol)
        max_gap = max(max_gap, gap)
        max_err = max(max_err, math.sqrt(2 * gap / plant.mass), math.sqrt(2 * gap / plant.inertia) * world.arm)
        q = q + h * x
        k_done = k
        record(k)
        if (passive_ok and stop_time is None and not np.any(x)
                and not np.any(world.velocities)):
            stop_time = float(grid[k])
            # At rest on passive contacts with nothing pushing: it stays there.
            rest = np.flatnonzero(keep[k + 1:]) + k + 1
            for j in rest:
                rec_t.append(grid[j])
                rec_q.append(q.copy())
                rec_x.append(x.copy())
            k_done = grid.size - 1
            break
    if status is SimulationStatus.SUCCESS and (k_done < grid.size - 1 or grid[-1] < t_end):
        # (the steps left, or a grid the budget cut before t_end)
        status = SimulationStatus.MAX_STEPS
    Qr, Xr = np.array(rec_q), np.array(rec_x)
    setting = f"step={h_nominal:g}"
    message = f"{status.value}; {k_done} steps, largest step gap {max_gap:.3g} J"
    return _result(np.array(rec_t), Qr[:, :2], Qr[:, 2], Xr[:, :2], Xr[:, 2], status, "moreau",
                   setting, message, k_done, started, stop_time=stop_time, max_gap=max_gap,
                   solve_error=max_err)


def _moreau_step(world: PlanarContactSet, M: np.ndarray, C: np.ndarray, wext: np.ndarray,
                 x: np.ndarray, h: float, tol: float) -> tuple[np.ndarray, float]:
    """One implicit step: ``argmin h Phi(x) + (x - x0)^T M (x - x0) / 2 + h x^T C x / 2 -
    h w_ext . x`` (docs/planar.md section 4); returns the new twist and the step's gap (J)."""
    L = world.arm or 1.0
    S = max(float(np.max(np.abs(world.velocities))), float(np.hypot(x[0], x[1])) + abs(x[2]) * L)
    if not S > 0:
        S = 1.0
    prob, _ = twist_problem(world, False, np.zeros(2), S, L)
    D = np.array([S, S, S / L])
    scale = h * world.total_force * S
    Q = np.diag(D * (M + h * C) * D) / scale
    b = D * (M * x + h * wext) / scale
    prob = NormSum(prob.c, prob.B, prob.f, Q, b)
    start = x / D
    # The gap is asked relative to the step's own scale (the kinetic term dominates for
    # small steps: its rounding would otherwise exceed an absolute tolerance).
    relative = tol * max(1.0, float(start @ Q @ start), float(np.sum(prob.f * np.hypot(prob.c[:, 0], prob.c[:, 1]))))
    sol = solve_fast(prob, relative, start)
    return sol.x * D, float(sol.gap * scale)


# -- smoothed ODE (baseline) -------------------------------------------------------------------
def _smooth(plant: PlanarPlant, t_end: float, s: _State, times: np.ndarray | None,
            budget: Budget, epsilon: float | None = None, solver: str = "Radau",
            rtol: float = 1e-8, atol: float = 1e-10) -> PlanarSimulationResult:
    from scipy.integrate import solve_ivp

    started = time.perf_counter()
    if epsilon is None:
        raise ParameterError(parameter_message("epsilon", "simulate", "be given for method "
                                               "'smooth' (the regularization width, m/s)", None))
    eps = as_float(epsilon, "epsilon", "simulate", low=0.0, low_open=True)
    check_option(solver, "solver", "simulate", ("RK45", "Radau", "LSODA", "BDF", "DOP853"))
    M = np.array([plant.mass, plant.mass, plant.inertia])
    C = np.array([plant.damping, plant.damping, plant.angular_damping])
    wext = np.array([plant.external_force[0], plant.external_force[1], plant.external_torque])
    meter = Meter(budget, counts="evaluations")

    def rhs(t, y):
        meter.evaluation()
        world = plant.contacts_at(t).transformed(angle=y[2])
        sl = world.slips(y[3:5], y[5])
        dmat = world.limit_factors
        if dmat.shape[0]:
            z = np.einsum("nji,nj->ni", dmat, sl)
            g = z / np.sqrt(z[:, 0] ** 2 + z[:, 1] ** 2 + eps * eps)[:, None]
            F = np.einsum("nij,nj->ni", dmat, g) * world.forces[:, None]
        else:
            F = sl / np.sqrt(sl[:, 0] ** 2 + sl[:, 1] ** 2 + eps * eps)[:, None] * world.forces[:, None]
        r = world.positions
        wrench = np.array([F[:, 0].sum(), F[:, 1].sum(), np.sum(r[:, 0] * F[:, 1] - r[:, 1] * F[:, 0])])
        acc = (wrench + wext - C * y[3:]) / M
        return np.concatenate((y[3:], acc))

    y0 = np.array([s.position[0], s.position[1], s.heading, s.V[0], s.V[1], s.omega])
    status, detail = SimulationStatus.SUCCESS, "regularized friction"
    try:
        sol = solve_ivp(rhs, (0.0, t_end), y0, method=solver, rtol=rtol, atol=atol, t_eval=times)
        if not sol.success:
            status, detail = SimulationStatus.FAILED, f"{solver}: {sol.message}"
        T, Y = sol.t, sol.y
    except BudgetExceeded as stopped:
        status, detail = stopped.status, f"{stopped.detail}; only the start is reported"
        T, Y = np.array([0.0]), y0[:, None]
    setting = f"{solver} epsilon={eps:g} rtol={rtol:g}"
    return _result(T, Y[:2].T, Y[2], Y[3:5].T, Y[5], status, "smooth", setting,
                   f"{status.value}; {detail}", min(meter.evaluations, budget.max_steps), started)
