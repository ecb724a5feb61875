"""Design of contact-speed schedules: :func:`design_schedule`.

A schedule is a table of contact-speed commands, constant over each controller period, that
firmware can play. Four steps: construction from physics
(:mod:`~toolkit.schedule.construct`), optional refinement (casadi + ipopt, kept only when it
verifies and improves), verification (:mod:`~toolkit.schedule.verify`) and optimality
against a lower bound or the closed-form minimum braking time; the result's
:class:`~toolkit.schedule.ScheduleStatus` says which held. Details: docs/methods.md."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from .._compiled import budget_clock
from ..errors import as_float, as_float_array, as_int
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..model import Motors, PiecewiseConstant, Plant
from .braking import braking_time
from .commands import _OWNER, _clip_commands, _Motor, _motor_of, _project
from .construct import construct, tracking_lower_bound
from .result import ScheduleResult, ScheduleStatus
from .targets import Braking, SpeedTrajectory
from .verify import _INTERVALS, _smoothed_rate, _Verified, _verifier

__all__ = ["design_schedule"]

#: Smoothing width divisor of the second prediction when the first does not verify.
_RETRY = 4.0
#: Every ``_COARSE``-th dense sample enters the tracking lower bound (16 per period).
_COARSE = 4
#: Most controller periods a schedule may span (the design is O(K) work and memory).
_MAX_PERIODS = 100_000


def _limits(plant: Plant, speed_limits: Any) -> tuple[float, float]:
    if speed_limits is None:
        lo, hi = plant.motors.speed_limits if plant.motors is not None else (-np.inf, np.inf)
    else:
        pair = as_float_array(speed_limits, "speed_limits", _OWNER)
        if pair.size != 2 or not pair[0] < pair[1]:
            raise ParameterError(parameter_message(
                "speed_limits", _OWNER, "be a pair (lo, hi) with lo < hi (m/s)", speed_limits))
        lo, hi = float(pair[0]), float(pair[1])
        if plant.motors is not None:
            lo, hi = max(lo, plant.motors.speed_limits[0]), min(hi, plant.motors.speed_limits[1])
    if not (math.isfinite(lo) and math.isfinite(hi)) or not lo < hi:
        raise ParameterError(parameter_message(
            "speed_limits", _OWNER, "be finite with lo < hi: pass speed_limits=(lo, hi) or "
            "Motors(speed_limits=...)", (lo, hi)))
    return lo, hi


def _reference(target: Any, v0: float, horizon: float | None, period: float, motor: _Motor,
               plant: Plant, lo: float, hi: float) -> tuple[Any, float, float | None]:
    """Return (reference function, horizon, closed-form minimum time or None)."""
    if isinstance(target, SpeedTrajectory):
        end = horizon if horizon is not None else target.end
        return target, end, None
    goal = target.speed
    if not lo <= goal <= hi:
        raise ParameterError(parameter_message(
            "target", _OWNER, f"have a speed within the speed limits [{lo:g}, {hi:g}] m/s",
            goal))
    hold = period if motor.dynamic else 0.0
    total = plant.contacts.total_force
    try:
        minimum = braking_time(replace(plant, motors=Motors(
            motor.tau, motor.rate, (lo, hi))), v0, goal, hold=hold) \
            if plant.damping == 0 and plant.external(0.0) == 0 \
            and not isinstance(plant.external_force, PiecewiseConstant) else None
    except ParameterError:
        minimum = None
    rough = hold + plant.mass * abs(v0 - goal) / total
    if target.duration is None:
        end = (minimum if minimum is not None else rough)
        end = horizon if horizon is not None else end + max(0.25 * end, 5 * motor.tau, 10 * period)

        def ref(t: Any) -> np.ndarray:
            return np.full(np.shape(t), goal)
        return ref, end, minimum
    duration = target.duration
    end = horizon if horizon is not None else duration + hold + max(5 * motor.tau, 10 * period)
    ramp = SpeedTrajectory([0.0, hold, hold + duration], [v0, v0, goal]) if hold > 0 \
        else SpeedTrajectory([0.0, duration], [v0, goal])
    return ramp, end, minimum


def _build_interval(ca: Any, plant: Plant, motor: _Motor, M: int, epsilon: float) -> Any:
    """casadi Function (V, v, u, ref[2M+1], fext[M]) -> (V_next, int (V - ref)^2): ``M``
    RK4 steps over one period of the law smoothed at ``epsilon`` (m/s)."""
    n = plant.n
    h = motor.period / M
    V, s, F_ext = ca.SX.sym("V"), ca.SX.sym("s"), ca.SX.sym("F")
    v, u = ca.SX.sym("v", n), ca.SX.sym("u", n)
    ref, fext = ca.SX.sym("ref", 2 * M + 1), ca.SX.sym("fext", M)
    g_expr = _smoothed_rate(ca, plant, motor.symbolic(ca, v, u, s), V, F_ext, epsilon)
    g = ca.Function("g", [s, V, v, u, F_ext], [g_expr])
    x, cost = V, 0
    for j in range(M):                                  # classical RK4, F_ext frozen per step
        a = j * h
        k1 = g(a, x, v, u, fext[j])
        k2 = g(a + h / 2, x + h / 2 * k1, v, u, fext[j])
        k3 = g(a + h / 2, x + h / 2 * k2, v, u, fext[j])
        k4 = g(a + h, x + h * k3, v, u, fext[j])
        nxt = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        cost += h / 6 * ((x - ref[2 * j]) ** 2 + 4 * ((x + nxt) / 2 - ref[2 * j + 1]) ** 2
                         + (nxt - ref[2 * j + 2]) ** 2)
        x = nxt
    return ca.Function("interval", [V, v, u, ref, fext], [x, cost])


def _stable_substeps(plant: Plant, period: float, epsilon: float) -> int:
    """RK4 substeps per period that keep the stiff smoothed law stable (``h lambda <= 2.5``)."""
    stiffness = plant.contacts.total_force / (plant.mass * epsilon) + plant.damping / plant.mass
    return max(4, math.ceil(period * stiffness / 2.5))


def _refine(ca: Any, plant: Plant, motor: _Motor, *, U0: np.ndarray, start: np.ndarray,
            v0: float, lo: float, hi: float, pin_first: bool, ref_fn: Any, epsilon: float,
            substeps: int, smoothness: float, max_iter: int,
            wall_time: float) -> tuple[np.ndarray, np.ndarray, int, str]:
    """Refine commands with ipopt (multiple shooting on the smoothed law), warm-started at U0.

    Speeds are scaled by the largest speed limit, the objective by the horizon; the RK4
    substeps follow the law's stiffness so the shooting model is stable at ``epsilon``.

    Returns
    -------
    U : ndarray of shape (K, n), m/s
        The last iterate (not projected).
    V : ndarray of shape (K + 1,), m/s
        The shooting states of the last iterate.
    iterations : int
    solver_status : str
    """
    K, n = U0.shape
    period = motor.period
    M = max(substeps, _stable_substeps(plant, period, epsilon))
    scale = max(abs(lo), abs(hi))
    fine = np.arange(2 * M * K + 1) * (period / (2 * M))
    ref_fine = np.asarray(ref_fn(fine), dtype=float)
    ref_nodes = np.stack([ref_fine[2 * M * k: 2 * M * k + 2 * M + 1] for k in range(K)], axis=1)
    mids = (np.arange(M * K) + 0.5) * (period / M)
    fext = np.array([plant.external(t) for t in mids]).reshape(K, M).T
    interval = _build_interval(ca, plant, motor, M, epsilon)
    opti = ca.Opti()
    Un = opti.variable(n, K)                      # speeds in units of the largest limit
    Vn = opti.variable(1, K + 1)
    vn = opti.variable(n, K + 1)
    U, Vs, vs = scale * Un, scale * Vn, scale * vn
    V_next, cost = interval.map(K)(Vs[:, :K], vs[:, :K], U, ref_nodes, fext)
    opti.subject_to(Vn[:, 1:] == V_next / scale)
    opti.subject_to(Vn[0] == v0 / scale)
    opti.subject_to(vn[:, 0] == start / scale)
    opti.subject_to(vn[:, 1:] == motor.period_end(vn[:, :K], Un, xp=ca))
    opti.subject_to(opti.bounded(lo / scale, Un, hi / scale))
    if pin_first:
        opti.subject_to(Un[:, 0] == start / scale)
    if math.isfinite(motor.max_step):
        opti.subject_to(opti.bounded(-motor.max_step / scale, Un - vn[:, :K],
                                     motor.max_step / scale))
    changes = ca.diff(ca.horzcat(ca.DM(start / scale), Un), 1, 1)
    opti.minimize(ca.sum2(cost) / (K * period * scale ** 2)
                  + smoothness * ca.sumsqr(changes) / (n * K))
    commands, contact = _project(U0, start, motor, lo, hi, pin_first)
    V_guess = [v0]
    for k in range(K):
        V_guess.append(float(interval(V_guess[-1], contact[k], commands[k], ref_nodes[:, k],
                                      fext[:, k])[0]))
    opti.set_initial(Un, commands.T / scale)
    opti.set_initial(vn, contact.T / scale)
    opti.set_initial(Vn, np.array(V_guess)[None, :] / scale)
    opti.solver("ipopt", {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                          "ipopt.max_iter": max_iter, "ipopt.max_wall_time": wall_time,
                          "ipopt.tol": 1e-8, "ipopt.acceptable_tol": 1e-6,
                          "ipopt.acceptable_iter": 3, "ipopt.mu_init": 1e-4,
                          "ipopt.warm_start_init_point": "yes"})
    try:
        sol = opti.solve()
        stats = sol.stats()
    except RuntimeError:
        sol = opti.debug
        stats = opti.stats()
    U = np.atleast_2d(sol.value(U)).reshape(n, K).T
    return (U, np.ravel(sol.value(Vs)), int(stats.get("iter_count", 0)),
            str(stats.get("return_status", "unknown")))


def design_schedule(plant: Plant, target: SpeedTrajectory | Braking, *, v0: float = 0.0,
                    horizon: float | None = None, period: float = 0.02,
                    speed_limits: Any = None, epsilon: float = 1e-3, substeps: int = 8,
                    smoothness: float = 1e-4, max_iter: int = 80,
                    time_limit: float = 30.0, refine: bool = False,
                    tolerance: float = 1e-3) -> ScheduleResult:
    """Design piecewise-constant contact-speed commands that take the body along a target.

    A constructive schedule comes first (``toolkit._schedule_construct``: every contact
    follows a lag-compensated path the body sticks to, or pushes at a speed limit when the
    body must catch up, chosen period by period on the exact Coulomb law). Optionally ipopt
    refines it (multiple shooting on the tanh-smoothed law, warm-started there). Every
    candidate is then predicted on the smoothed law at tight tolerance, bounded against
    the exact model (:func:`deviation_bound`) and simulated exactly (compared with the
    prediction over the whole run); the status says what the returned schedule achieves.

    Parameters
    ----------
    plant : Plant
        Contacts (magnitudes ``f_i`` and current commands, m/s), mass, damping, external
        force and motors (lag ``tau``, rate limit ``r``, speed limits; compliance must be
        0). ``plant.commands`` is ignored: the schedule replaces it.
    target : SpeedTrajectory or Braking
    v0 : float, m/s
        Body speed at ``t = 0``.
    horizon : float, optional, s
        Length of the schedule (rounded up to whole periods). Default: the trajectory's last
        sample; for braking the closed-form minimum time (or the requested duration) plus
        a settling margin.
    period : float, s
        Controller period (0.02 s = 50 Hz on the paper's hardware).
    speed_limits : pair of float, optional, m/s
        ``(lo, hi)`` for the commands (intersected with the motors' limits). Required when
        the motors have none.
    epsilon : float, m/s
        Width of the tanh smoothing of the prediction and of the refinement (the
        prediction bound is a few ``epsilon``).
    substeps : int
        Minimum RK4 steps per period inside the refinement (raised to keep it stable).
    smoothness : float
        Weight of the command-change penalty ``sum ||u_k - u_{k-1}||^2`` relative to the
        tracking term (both normalized by the speed range) in ``objective``.
    max_iter : int
        ipopt iterations of the refinement.
    time_limit : float, s
        Wall-clock budget; the refinement gets what the construction leaves.
    refine : bool
        Also run the ipopt refinement (bounded by ``max_iter`` and ``time_limit``). The
        refined schedule is kept only when it verifies and lowers ``objective``. Off by
        default: on the carousel scene it lowers ``objective`` by ~6 % in ~5 s while the
        sup error does not improve.
    tolerance : float, m/s
        A tracking schedule is OPTIMAL when its exact sup error is within this of the
        certified lower bound.

    Returns
    -------
    ScheduleResult
        Always returned; errors, arrival and bounds are evaluated on the projected
        commands (the exact simulation and the bounded prediction), never taken from a
        solver.

    Examples
    --------
    >>> from toolkit import ContactSet
    >>> from toolkit.model import Motors, Plant
    >>> plant = Plant(ContactSet([0.3] * 10, [0.2] * 10), mass=1.0,
    ...               motors=Motors(lag=0.01, speed_limits=(-0.35, 0.35)))
    >>> result = design_schedule(plant, Braking(0.0), v0=0.3)   # doctest: +SKIP
    >>> result.status.name                                      # doctest: +SKIP
    'OPTIMAL'
    """
    start_clock = budget_clock()
    if not isinstance(plant, Plant):
        raise ParameterTypeError(parameter_message("plant", _OWNER, "be a Plant", plant))
    if not isinstance(target, (SpeedTrajectory, Braking)):
        raise ParameterTypeError(parameter_message(
            "target", _OWNER, "be a SpeedTrajectory or a Braking", target))
    v0 = as_float(v0, "v0", _OWNER)
    period = as_float(period, "period", _OWNER, low=0.0, low_open=True)
    epsilon = as_float(epsilon, "epsilon", _OWNER, low=0.0, low_open=True)
    substeps = as_int(substeps, "substeps", _OWNER, low=1)
    smoothness = as_float(smoothness, "smoothness", _OWNER, low=0.0)
    max_iter = as_int(max_iter, "max_iter", _OWNER, low=1)
    time_limit = as_float(time_limit, "time_limit", _OWNER, low=0.0, low_open=True)
    tolerance = as_float(tolerance, "tolerance", _OWNER, low=0.0)
    if not isinstance(refine, bool):
        raise ParameterTypeError(parameter_message("refine", _OWNER, "be True or False", refine))
    if horizon is not None:
        horizon = as_float(horizon, "horizon", _OWNER, low=0.0, low_open=True)
    motor = _motor_of(plant, period)
    lo, hi = _limits(plant, speed_limits)
    start = np.clip(plant.contacts.speeds, lo, hi) if motor.dynamic else plant.contacts.speeds
    if motor.dynamic and np.any(plant.initial_speeds() != start):
        raise ParameterError(parameter_message(
            "plant", _OWNER, f"have current commands within the speed limits [{lo:g}, {hi:g}]",
            plant.contacts.speeds.tolist()))
    ref_fn, end, minimum = _reference(target, v0, horizon, period, motor, plant, lo, hi)
    periods = end / period
    if not periods <= _MAX_PERIODS:             # before allocating anything of size K
        if horizon is not None:
            name, span = "horizon", "'horizon'"
        elif isinstance(target, SpeedTrajectory):
            name, span = "target", "the trajectory's last sample time 'times[-1]'"
        else:
            name, span = "target", "the braking 'duration' plus settling"
        raise ParameterError(parameter_message(
            name, _OWNER, f"span at most {_MAX_PERIODS} controller periods ({span} / "
            f"'period' = {end:g} s / {period:g} s = {periods:.4g}): shorten it or lengthen "
            f"'period'", end))
    K = max(1, math.ceil(periods - 1e-9))
    times = np.arange(K + 1) * period
    pin_first = motor.dynamic
    fastest = isinstance(target, Braking) and target.duration is None
    forces = plant.contacts.forces

    built = construct(forces=forces, mass=plant.mass, damping=plant.damping,
                      external=plant.external, tau=motor.tau, rate=motor.rate, period=period,
                      lo=lo, hi=hi, start=start, v0=v0, K=K, pinned=pin_first,
                      reference=ref_fn, squared=fastest,
                      project=lambda u, v: _clip_commands(u, v, lo, hi, motor.max_step))

    import casadi as ca      # heavy optional package: loaded only when a schedule is designed

    verify = _verifier(ca, plant, motor, start=start, v0=v0, lo=lo, hi=hi, pin_first=pin_first,
                       ref_fn=ref_fn, times=times, smoothness=smoothness, epsilon=epsilon)

    def certify(candidate: _Verified) -> tuple[float | None, float | None, float | None]:
        """(lower bound, gap, arrival) of a verified candidate."""
        t_d, exact_V = candidate.t_dense, candidate.exact_V
        if fastest:
            near = np.flatnonzero(np.abs(exact_V - target.speed) <= candidate.bound)
            return None, None, (float(t_d[near[0]]) if near.size else None)
        t_free = period if pin_first else 0.0
        forced_part = t_d <= t_free * (1 + 1e-12)
        ref_d = np.asarray(ref_fn(t_d), dtype=float)
        # The motion before t_free is the same under every schedule: its error is forced.
        forced = float(np.max(np.abs(exact_V[forced_part] - ref_d[forced_part])))
        j = int(np.flatnonzero(forced_part)[-1])
        # The funnel runs on every _COARSE-th dense sample (both ends of every piece): a
        # bound over fewer samples is still a bound over all of them, at a quarter the cost.
        coarse = np.arange(t_d.size) % (_INTERVALS + 1) % _COARSE == 0
        free = (t_d >= t_d[j]) & (coarse | (np.arange(t_d.size) == j))
        bound_value = tracking_lower_bound(
            forces=forces, mass=plant.mass, damping=plant.damping, external=plant.external,
            tau=motor.tau, rate=motor.rate, lo=lo, hi=hi, t=t_d[free], reference=ref_d[free],
            t_free=float(t_d[j]), V_free=float(exact_V[j]), v_free=start, forced=forced)
        return bound_value, candidate.exact_tracking - bound_value, None

    def is_optimal(candidate: _Verified, gap: float | None, arrival: float | None) -> bool:
        if not candidate.verified:
            return False
        if fastest:
            return minimum is not None and arrival is not None and \
                arrival <= minimum + period * (1 + 1e-9)
        return gap is not None and gap <= tolerance

    best = verify(built.commands)
    used_epsilon = epsilon
    if best.exact_finished and not best.verified:
        # The exact simulation left a proven bound: only rounding, CVODES missing its
        # tolerance or a simulator defect can do that. Guard: predict closer to the exact law.
        used_epsilon = epsilon / _RETRY
        best = verify(best.commands, used_epsilon)
    lower, gap, arrival = certify(best) if best.verified else (None, None, None)
    design_model = built.body_speed
    method, iterations, solver_status = "constructive", 0, "not run"
    optimal = is_optimal(best, gap, arrival)
    remaining = time_limit - (budget_clock() - start_clock)
    if refine and remaining > 0:
        U_r, V_r, iterations, solver_status = _refine(
            ca, plant, motor, U0=best.commands, start=start, v0=v0, lo=lo, hi=hi,
            pin_first=pin_first, ref_fn=ref_fn, epsilon=epsilon, substeps=substeps,
            smoothness=smoothness, max_iter=max_iter, wall_time=remaining)
        refined = verify(U_r, used_epsilon)
        if refined.verified and (refined.objective < best.objective or not best.verified):
            best, design_model, method = refined, V_r, "constructive + ipopt"
            lower, gap, arrival = certify(best)
            optimal = is_optimal(best, gap, arrival)
    if not best.verified:
        status = ScheduleStatus.UNVERIFIED
    else:
        status = ScheduleStatus.OPTIMAL if optimal else ScheduleStatus.VERIFIED
    speeds = np.vstack((best.commands, best.commands[-1]))
    mismatch = float(np.max(np.abs(np.asarray(design_model) - best.body)))
    pushes = int(np.sum(np.any((best.commands == lo) | (best.commands == hi), axis=1)))
    detail = [f"{method} schedule (a contact commanded at a speed limit in {pushes} of {K} "
              f"periods)",
              f"ipopt {solver_status}" + (f" after {iterations} iterations" if iterations else ""),
              f"exact simulation within {best.deviation:.3g} m/s of the prediction "
              f"at the dense samples (proven bound {best.bound:.3g} m/s, epsilon "
              f"{used_epsilon:g} m/s)"
              if best.exact_finished else f"exact simulation: {best.exact_message}",
              f"exact tracking error {best.exact_tracking:.4g} m/s"]
    if lower is not None:
        detail.append(f"no schedule can do better than {lower:.4g} m/s (gap {gap:.3g} m/s, "
                      f"tolerance {tolerance:g} m/s)")
    if fastest:
        reached = "never reached" if arrival is None else f"reached at {arrival:.4g} s"
        floor = "" if minimum is None else f", closed-form minimum time {minimum:.4g} s"
        detail.append(f"target speed {reached}{floor}")
    if isinstance(target, Braking) and minimum is not None and target.duration is not None \
            and target.duration + (period if pin_first else 0.0) < minimum:
        detail.append(f"the requested duration is shorter than the minimum braking time "
                      f"{minimum - (period if pin_first else 0.0):.4g} s")
    return ScheduleResult(
        times, speeds, best.contact_speeds, best.body, ref_fn(times), best.bound,
        best.tracking, best.objective, arrival, minimum, used_epsilon, period, mismatch,
        iterations, solver_status, status, f"{status.value}; " + "; ".join(detail),
        budget_clock() - start_clock, method=method, exact_tracking_error=best.exact_tracking,
        exact_deviation=best.deviation, lower_bound=lower, gap=gap, tolerance=tolerance,
        exact_body_speed=best.exact_body, target=target)
