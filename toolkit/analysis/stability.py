"""Stability suite: stiff and extreme cases every simulation method must survive.

:func:`stability_suite` runs a fixed list of cases, each under its own budgets, and reports
per case whether it finished, stayed finite, produced a bounded number of events and ended
right (:class:`StabilityCase` says what "right" means); a wall-clock guard that fires leaves
its case unjudged. The cases: docs/guide/simulation.md and docs/methods.md. Pure numerics."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..model import ContactSet, Motors, PiecewiseConstant, Plant
from ..simulation import Budget, SimulationResult, SimulationStatus, simulate

__all__ = ["StabilityCase", "StabilityReport", "case_label", "stability_suite", "EXACT_TOLERANCE",
           "SMOOTH_TOLERANCE_FACTOR"]

#: Tolerance (m/s) of the exact and Moreau methods: a few ulps of speeds of order 1.
EXACT_TOLERANCE = 1e-12
#: Smoothed methods end within ``SMOOTH_TOLERANCE_FACTOR * epsilon`` of the Coulomb
#: equilibrium set (the smoothed zero of ``sum f_i tanh((v_i - V)/eps)`` near the median
#: ``s`` is ``s + eps atanh(G / W)`` with ``|G| / W <= tanh(1)`` here) plus their own ``atol``.
SMOOTH_TOLERANCE_FACTOR = 10.0


@dataclass(frozen=True)
class StabilityCase:
    """The outcome of one case of the suite.

    Attributes
    ----------
    name, method, setting : str
    finished : bool
        The run reached its horizon (status ``SUCCESS``).
    finite : bool
        Every sample of ``V``, the contact speeds and the force is finite.
    events : int
        Events of the run (the exact method; the others report none).
    max_events : int
        The bound this case states for ``events`` (from the number of contact levels and
        command switches: each level is crossed at most once per constant-command interval).
    wall_time : float, s
        Wall time of the call, measured around ``simulate``.
    budget : float, s
        The case's wall-clock guard (compile time is not charged to it).
    judged : bool
        False when the wall-clock guard stopped the run: the case then has no verdict
        (``ok`` is False, but the case did not fail), since a verdict never depends on the
        machine's speed.
    ok : bool
        ``judged and finished and finite and events <= max_events`` and the check holds:
        ``"equilibrium"``: the final speed lies in the plant's equilibrium set
        ``[lo - tolerance, hi + tolerance]``; ``"mirror"``: the run on the mirrored plant
        (every speed, command, force and ``v0`` negated) gives ``-V`` at the same times
        within ``tolerance``.
    check : str
    tolerance : float, m/s
    final_speed : float, m/s
    expected : tuple of float, m/s
        The equilibrium set ``(lo, hi)`` (for a mirror check: that of the original plant).
    deviation : float, m/s
        Distance of the final speed to the set, or the max mirror mismatch.
    message : str
        The run's status message.
    status : str
        Name of the run's :class:`~toolkit.simulation.SimulationStatus` (``"SUCCESS"`` when it finished;
        ``"WALL_TIME"``, ``"MAX_STEPS"`` or ``"ZENO"`` when its budget stopped it). For a
        mirror check, that of the first run that did not succeed.
    samples : int
        Samples the run returned (``t.size``).
    max_samples : int
        The case's ``Budget.max_samples``. A ``"horizon"`` check (the 1e9 s cases) is ok when
        the run is finite, keeps at most ``max_samples + 1`` samples, and either finished in
        the equilibrium set or was stopped by its step budget (``finished`` is then False: the
        budget stop is the expected outcome).
    """

    name: str
    method: str
    setting: str
    finished: bool
    finite: bool
    events: int
    max_events: int
    wall_time: float
    budget: float
    ok: bool
    check: str
    tolerance: float
    final_speed: float
    expected: tuple[float, float]
    deviation: float
    message: str
    status: str
    samples: int = 0
    max_samples: int = Budget().max_samples
    judged: bool = True

    @property
    def failed(self) -> bool:
        """Judged and not ok."""
        return self.judged and not self.ok

    def to_dict(self) -> dict[str, Any]:
        """JSON-able dictionary (``name``, ``method``, ``finished``, ``finite``, ``events``,
        ``wall_time``, ``ok`` and the details)."""
        return {"name": self.name, "method": self.method, "setting": self.setting,
                "finished": self.finished, "finite": self.finite, "events": self.events,
                "max_events": self.max_events, "wall_time": self.wall_time,
                "budget": self.budget, "ok": self.ok, "check": self.check,
                "tolerance": self.tolerance,
                "final_speed": self.final_speed if np.isfinite(self.final_speed) else None,
                "expected": list(self.expected),
                "deviation": self.deviation if np.isfinite(self.deviation) else None,
                "message": self.message, "status": self.status, "samples": self.samples,
                "max_samples": self.max_samples, "judged": self.judged, "failed": self.failed}


@dataclass(frozen=True)
class StabilityReport:
    """All cases of one run of :func:`stability_suite`."""

    cases: tuple[StabilityCase, ...]

    @property
    def all_ok(self) -> bool:
        """True when every case is ``ok``."""
        return all(case.ok for case in self.cases)

    @property
    def failed(self) -> tuple[StabilityCase, ...]:
        """The judged cases that are not ok."""
        return tuple(case for case in self.cases if case.failed)

    @property
    def unjudged(self) -> tuple[StabilityCase, ...]:
        """The cases a wall-clock guard stopped (no verdict)."""
        return tuple(case for case in self.cases if not case.judged)

    def to_dict(self) -> dict[str, Any]:
        """``{"all_ok": bool, "failed": [...], "unjudged": [...], "cases": [case.to_dict(),
        ...]}`` (the failed and unjudged cases by ``"name (method)"``), JSON-able."""
        return {"all_ok": self.all_ok, "failed": [case_label(c) for c in self.failed],
                "unjudged": [case_label(c) for c in self.unjudged],
                "cases": [case.to_dict() for case in self.cases]}


def case_label(case: StabilityCase) -> str:
    """``"name (method)"``: how a case is named in messages."""
    return f"{case.name} ({case.method})"


@dataclass(frozen=True)
class _Spec:
    name: str
    plant: Plant
    t_end: float
    method: str = "exact"
    v0: float = 0.0
    options: dict[str, Any] = field(default_factory=dict)
    wall_time: float = 120.0        # a guard only: verdicts come from max_steps and the events
    max_steps: int = Budget().max_steps
    check: str = "equilibrium"
    tolerance: float = EXACT_TOLERANCE
    switches: int = 0
    max_samples: int = Budget().max_samples


def _equal(speeds: Any, mass: float = 1.0, total: float = 2.0, **kwargs: Any) -> Plant:
    speeds = np.asarray(speeds, dtype=float)
    return Plant(ContactSet(speeds, np.full(speeds.size, total / speeds.size)), mass=mass, **kwargs)


def _settle_time(plant: Plant, v0: float) -> float:
    """A horizon that lets a Coulomb startup reach equilibrium: twice the worst-case time.

    The body moves monotonically toward the equilibrium set at an acceleration of at least
    ``f_min / m`` (the smallest non-zero plateau force is at least the smallest magnitude),
    over at most the span of speeds plus ``|v0|``.
    """
    speeds = plant.final_command()
    f_min = float(np.min(plant.contacts.forces[plant.contacts.forces > 0]))
    span = float(np.ptp(np.append(speeds, v0)))
    return 2.0 * plant.mass * max(span, 1e-3) / f_min


def _mirror(plant: Plant) -> Plant:
    ext = plant.external_force
    ext_m = (PiecewiseConstant(ext.times, -ext.values) if isinstance(ext, PiecewiseConstant)
             else -ext)
    commands = (None if plant.commands is None
                else PiecewiseConstant(plant.commands.times, -plant.commands.values))
    motors = plant.motors
    if motors is not None:
        low, high = motors.speed_limits
        motors = Motors(motors.lag, motors.rate_limit, (-high, -low), motors.compliance,
                        motors.backlash)
    return Plant(plant.contacts.with_speeds(-plant.contacts.speeds), plant.mass, plant.damping,
                 ext_m, motors, commands)


def _specs(quick: bool) -> list[_Spec]:
    rng = np.random.default_rng(20250117)
    eleven = rng.uniform(-0.35, 0.35, 11)
    ten = rng.uniform(-0.35, 0.35, 10)
    specs = [
        _Spec("odd N sliding mode", _equal(eleven), 5.0),
        _Spec("odd N sliding mode", _equal(eleven), 5.0, "moreau", options={"step": 1e-3}),
        _Spec("even N zero band from below", _equal(ten), 5.0, v0=-0.5),
        _Spec("even N zero band, start inside", _equal([-0.35] * 5 + [0.35] * 5), 5.0, v0=0.1),
        _Spec("even N zero band, start inside", _equal([-0.35] * 5 + [0.35] * 5), 5.0, "moreau",
              v0=0.1, options={"step": 1e-2}),
        _Spec("coincident speeds", _equal([0.1] * 4 + [-0.2, 0.3, 0.3, -0.2, 0.1]), 5.0, v0=-0.4),
        _Spec("N = 1", _equal([0.25], total=0.5), 5.0, v0=-0.3),
    ]
    big = 10_000 if quick else 100_000
    specs.append(_Spec(f"N = {big:.0e} random", _equal(rng.uniform(-0.35, 0.35, big + 1)), 50.0))
    for mass in (1e-6, 1e6):
        plant = _equal(eleven, mass=mass)
        specs.append(_Spec(f"mass {mass:g} kg", plant, _settle_time(plant, 0.0)))
        h = _settle_time(plant, 0.0) / 5000
        specs.append(_Spec(f"mass {mass:g} kg", plant, _settle_time(plant, 0.0), "moreau",
                           options={"step": h}))
    limits = Motors(lag=0.03, speed_limits=(-0.35, 0.35))
    at_limits = [-0.35, -0.35, -0.5, -0.9, -0.35, -0.35, 0.35, 0.35, 0.6, 0.35, 0.35]
    specs.append(_Spec("speeds at the motor limits", _equal(at_limits, motors=limits), 5.0))
    specs.append(_Spec("speeds at the motor limits", _equal(at_limits, motors=limits), 5.0,
                       "moreau", options={"step": 1e-3}))
    epsilons = (1e-3, 1e-6) if quick else (1e-3, 1e-6, 1e-9)
    for eps in epsilons:
        specs.append(_Spec(f"tanh epsilon {eps:g}", _equal(eleven), 5.0, "radau",
                           options={"friction": "tanh", "epsilon": eps, "rtol": 1e-8, "atol": 1e-13},
                           tolerance=SMOOTH_TOLERANCE_FACTOR * eps + 1e-12))
    specs.append(_Spec(f"tanh epsilon {epsilons[-1]:g}", _equal(eleven), 5.0, "casadi",
                       options={"friction": "tanh", "epsilon": epsilons[-1], "rtol": 1e-10,
                                "atol": 1e-13},
                       tolerance=SMOOTH_TOLERANCE_FACTOR * epsilons[-1] + 1e-12))
    specs += [
        _Spec("horizon 1e4 s", _equal(eleven), 1e4),
        _Spec("horizon 1e4 s", _equal(eleven), 1e4, "moreau", options={"step": 1.0}),
        _Spec("horizon 1e4 s", _equal(eleven), 1e4, "radau",
              options={"friction": "tanh", "epsilon": 1e-6, "rtol": 1e-8, "atol": 1e-13},
              tolerance=SMOOTH_TOLERANCE_FACTOR * 1e-6 + 1e-12),
    ]
    # The median contact's speed is a square wave around the body's speed (0 m/s): 40
    # switches at 20 Hz through a 10 ms motor lag, then it settles at 0.
    periods = 20
    times = 0.025 * np.arange(1, 2 * periods + 1)
    wave = np.where(np.arange(2 * periods + 1) % 2 == 0, 0.05, -0.05)
    wave[-1] = 0.0
    rows = np.column_stack((np.full(wave.size, -0.2), wave, np.full(wave.size, 0.2)))
    oscillating = _equal([-0.2, 0.05, 0.2], motors=Motors(lag=0.01),
                         commands=PiecewiseConstant(times, rows))
    specs.append(_Spec("contact speed oscillating around V", oscillating, 3.0,
                       switches=times.size))
    specs.append(_Spec("contact speed oscillating around V", oscillating, 3.0, "moreau",
                       options={"step": 1e-4}, switches=times.size))
    if not quick:                    # (about 2 s: the full suite only)
        specs += _horizon_specs(_equal(eleven))
    pushed = _equal(eleven, external_force=PiecewiseConstant([1.0, 2.0], [0.0, 1.5, -0.7]))
    specs.append(_Spec("mirrored sign conventions", pushed, 5.0, v0=0.3, check="mirror",
                       switches=2))
    specs.append(_Spec("mirrored sign conventions", pushed, 5.0, "moreau", v0=0.3,
                       options={"step": 1e-3}, check="mirror", switches=2))
    return specs


#: Step budget (steps, events or evaluations, as each method counts) and memory cap (samples)
#: of the 1e9 s horizon cases.
_HORIZON_STEPS, _HORIZON_SAMPLES = 20_000, 10_000


def _horizon_specs(plant: Plant) -> list[_Spec]:
    """One case per method at ``t_end = 1e9`` s (see the module docstring)."""
    smooth = SMOOTH_TOLERANCE_FACTOR * 1e-6 + 1e-12
    runs = [("exact", {}, EXACT_TOLERANCE),
            ("moreau", {"step": 1e-3}, EXACT_TOLERANCE),
            ("rk45", {"friction": "sign"}, smooth),
            ("lsoda", {"friction": "sign"}, smooth),
            ("radau", {"friction": "tanh", "epsilon": 1e-6, "rtol": 1e-8, "atol": 1e-13}, smooth),
            ("bdf", {"friction": "stribeck", "epsilon": 1e-6, "rtol": 1e-8, "atol": 1e-13}, smooth),
            ("casadi", {"integrator": "cvodes", "friction": "tanh", "epsilon": 1e-6}, smooth),
            ("casadi", {"integrator": "idas", "friction": "stribeck", "epsilon": 1e-6}, smooth)]
    return [_Spec("horizon 1e9 s", plant, 1e9, method, options=options, tolerance=tolerance,
                  max_steps=_HORIZON_STEPS, check="horizon", max_samples=_HORIZON_SAMPLES)
            for method, options, tolerance in runs]


def _run(spec: _Spec, plant: Plant, v0: float, t_eval: Any = None) -> tuple[SimulationResult, float]:
    start = time.perf_counter()
    result = simulate(plant, spec.t_end, v0=v0, method=spec.method, t_eval=t_eval,
                      budget=Budget(wall_time=spec.wall_time, max_steps=spec.max_steps,
                                    max_samples=spec.max_samples),
                      **spec.options)
    return result, time.perf_counter() - start


def _finite(result: SimulationResult) -> bool:
    return bool(np.all(np.isfinite(result.V)) and np.all(np.isfinite(result.force))
                and np.all(np.isfinite(result.contact_speeds)))


def _case(spec: _Spec) -> StabilityCase:
    plant = spec.plant
    grid = np.linspace(0.0, spec.t_end, 201) if spec.check == "mirror" else None
    result, wall = _run(spec, plant, spec.v0, grid)
    finished, finite, status = result.success, _finite(result), result.status
    lo, hi = plant.equilibrium()
    final = float(result.V[-1]) if result.V.size else float("nan")
    if spec.check == "mirror":
        mirrored, wall_m = _run(spec, _mirror(plant), -spec.v0, grid)
        wall += wall_m
        finished = finished and mirrored.success
        status = result.status if not result.success else mirrored.status
        finite = finite and _finite(mirrored)
        same = result.V.size == mirrored.V.size
        deviation = float(np.max(np.abs(result.V + mirrored.V))) if same else float("inf")
        events = max(result.n_events, mirrored.n_events)
    else:
        deviation = max(lo - final, final - hi, 0.0) if np.isfinite(final) else float("inf")
        events = result.n_events
    levels = np.unique(plant.final_command()).size if plant.commands is None else np.unique(
        plant.commands.values).size
    max_events = (levels + 2) * (spec.switches + 1) + spec.switches
    judged = status is not SimulationStatus.WALL_TIME      # the guard fired: no verdict
    if spec.check == "horizon":
        stopped = status is SimulationStatus.MAX_STEPS
        bounded = result.t.size <= spec.max_samples + 1
        ok = finite and bounded and events <= max_events and (
            stopped or (finished and deviation <= spec.tolerance))
        if stopped:                  # a partial run: its final speed is not judged
            deviation = 0.0
    else:
        ok = finished and finite and events <= max_events and deviation <= spec.tolerance
    ok = ok and judged
    return StabilityCase(
        name=spec.name, method=spec.method, setting=result.setting, finished=finished,
        finite=finite, events=int(events), max_events=int(max_events), wall_time=wall,
        budget=spec.wall_time * (2 if spec.check == "mirror" else 1), ok=bool(ok),
        check=spec.check, tolerance=spec.tolerance, final_speed=final,
        expected=(float(lo), float(hi)), deviation=float(deviation), message=result.message,
        status=status.name, samples=int(result.t.size), max_samples=spec.max_samples, judged=judged)


def stability_suite(*, quick: bool = False) -> StabilityReport:
    """Run the stability cases (each under its own step budget and a wall-clock guard).

    Parameters
    ----------
    quick : bool
        Smaller extremes (N = 1e4 instead of 1e5, epsilon down to 1e-6 instead of 1e-9), and
        without the 1e9 s horizon cases.

    Returns
    -------
    StabilityReport
        One :class:`StabilityCase` per case; ``report.all_ok`` says whether all passed,
        ``report.failed`` and ``report.unjudged`` name the others.
    """
    return StabilityReport(tuple(_case(spec) for spec in _specs(bool(quick))))
