"""The paper's viscosity experiment (its Fig. 6) in the closed loop, against the derived correction.

Each run commands a virtual viscosity ``k = dF/dV`` (:class:`~toolkit.controllers.VirtualViscosity`:
``n`` equal contacts spaced ``s = 2 f / k`` around a reference ``c``) on a body the wheels
were carrying at ``V0``, and fits an exponential to the startup
(:func:`~toolkit.predictions._measure.startup_time_constant`, the 63.2 % time). A viscous
law would give ``1 / tau = k / m``; the staircase gives ``1 / tau = (k / m) / C(n, x0)`` with
the correction ``C`` of :func:`~toolkit.predictions.theory.staircase_correction`, which
depends on ``n`` and on where the start lies, ``x0 = (V0 - c) / s``.

Sweep design (seeded, reproducible): ``runs`` draws of the spacing ``s`` uniform in
``spacing`` (the slope ``k = 2 f / s``) and of the start's position relative to the lowest
contact, ``p = (V0 - v_min) / s`` uniform in ``start`` (spacings), each run moving up or
down with equal chance (a start above the reference mirrors one below). The staircase is
centred between the speed limits (``c = 0``): the ideal model depends on ``V - v_i`` only, so
a start at ``V0 != 0`` is the paper's start from rest on a staircase shifted by ``-V0``, and
centring lets the spread use the motors' whole range.

Each run: ``pre_roll`` seconds carried at ``V0`` (motors and estimator settle), then the
staircase, for the predicted time to come to rest (:func:`~toolkit.predictions.theory.travel_time`,
exact) plus ``tail`` seconds; the settled speed is the mean of the last ``tail_samples``.
Over the sweep ``1 / tau`` is fitted against ``k / m`` through the origin
(:func:`~toolkit.predictions._measure.proportional_fit`): ``k_fit`` and its ``R^2``;
``k_predicted`` is the same fit of the predicted ``(k / m) / C``; a purely viscous law would
give 1 for both.
"""

from __future__ import annotations

import enum
import math
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import as_float, as_int
from ..loop.closed_loop import simulate_closed_loop
from ..controllers import VirtualViscosity
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..model import ContactSet, sample_count
from ..simulation import SimulationStatus
from ._measure import proportional_fit, startup_time_constant
from .apparatus import Apparatus, CarryThen
from .theory import resting_speed, travel_time, viscosity_correction

__all__ = ["ViscosityProblem", "ViscosityCheck", "CheckStatus", "viscosity_check"]


class CheckStatus(enum.Enum):
    """Outcome of a prediction check; the value is its message."""

    MET = "every target met"
    SHORT = "finished, but a target was missed"
    FAILED = "a run did not finish or could not be measured"


def _pair(value: Any, name: str, owner: str, low: float | None = None) -> tuple[float, float]:
    try:
        a, b = value
    except (TypeError, ValueError):
        raise ParameterTypeError(parameter_message(name, owner, "be a pair (low, high)", value)) from None
    a = as_float(a, name, owner, low=low, low_open=low is not None)
    b = as_float(b, name, owner, low=low, low_open=low is not None)
    if b < a:
        raise ParameterError(parameter_message(name, owner, "have low <= high", value))
    return a, b


@dataclass(frozen=True, eq=False)
class ViscosityProblem:
    """Settings of the viscosity sweep (see the module docstring).

    Parameters
    ----------
    apparatus : Apparatus, optional
        Default: :meth:`Apparatus.carousel`.
    mode : {"ideal", "loop"}
        ``"ideal"``: no motor lag, the fit on the true speed. ``"loop"``: motor lag, encoders
        and the default estimator of :func:`~toolkit.simulate_closed_loop` (the Kalman
        filter), the fit on the estimate.
    runs : int
        Number of closed-loop runs, ``>= 2``.
    spacing : (float, float), m/s
        Range of the contact spacing ``s``; the staircase must fit between the speed limits.
    start : (float, float)
        Range of the start's position from the lowest contact, in spacings (negative: below
        the whole staircase).
    pre_roll, tail : float, s
        Carry time before the staircase (``>= 0``) and settled time after the predicted
        stop (``> 0``).
    tail_samples : int
        Samples averaged for the settled speed, ``>= 1``; they must fit in ``tail``.
    seed : int
        Seeds the design and the sensors.
    targets : (float, float)
        ``R^2`` at least the first; ``|k_fit / k_predicted - 1|`` at most the second.
    """

    apparatus: Apparatus = field(default_factory=Apparatus.carousel)
    mode: str = "loop"
    runs: int = 490
    spacing: tuple[float, float] = (0.02, 0.06)
    start: tuple[float, float] = (-1.0, 1.0)
    pre_roll: float = 0.1
    tail: float = 0.2
    tail_samples: int = 5
    seed: int = 0
    targets: tuple[float, float] = (0.98, 0.05)

    def __post_init__(self) -> None:
        owner = "ViscosityProblem"
        if not isinstance(self.apparatus, Apparatus):
            raise ParameterTypeError(parameter_message("apparatus", owner, "be an Apparatus", self.apparatus))
        object.__setattr__(self, "mode", self.apparatus.check_mode(self.mode, owner))
        object.__setattr__(self, "runs", as_int(self.runs, "runs", owner, low=2))
        spacing = _pair(self.spacing, "spacing", owner, low=0.0)
        start = _pair(self.start, "start", owner)
        object.__setattr__(self, "spacing", spacing)
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "pre_roll", as_float(self.pre_roll, "pre_roll", owner, low=0.0))
        object.__setattr__(self, "tail", as_float(self.tail, "tail", owner, low=0.0, low_open=True))
        object.__setattr__(self, "tail_samples", as_int(self.tail_samples, "tail_samples", owner, low=1))
        object.__setattr__(self, "seed", as_int(self.seed, "seed", owner, low=0))
        object.__setattr__(self, "targets", (as_float(self.targets[0], "targets", owner, high=1.0),
                                             as_float(self.targets[1], "targets", owner, low=0.0)))
        a = self.apparatus
        half = (a.n - 1) / 2.0
        if half * spacing[1] > a.speed_limit:
            raise ParameterError(parameter_message(
                "spacing", owner, f"keep the {a.n} contacts within +-{a.speed_limit:g} m/s "
                f"(at most {a.speed_limit / max(half, 0.5):.6g} m/s)", self.spacing))
        reach = (half - start[0]) * spacing[1]
        if reach > a.speed_limit:
            raise ParameterError(parameter_message(
                "start", owner, f"put every start within +-{a.speed_limit:g} m/s (the lowest start "
                f"with the widest spacing lies {reach:.6g} m/s from the reference)", self.start))
        stop = 0.0 if a.n % 2 else 0.5
        if half - start[1] <= stop:
            raise ParameterError(parameter_message(
                "start", owner, f"leave the start outside the equilibrium set (below {half - stop:g} "
                "spacings from the lowest contact)", self.start))
        rate = a.sensors.rate if a.sensors is not None else 50.0
        if self.tail_samples > sample_count(self.tail, rate) - 1:
            raise ParameterError(parameter_message(
                "tail_samples", owner, f"fit in the tail ({self.tail:g} s at {rate:g} Hz)", self.tail_samples))


@dataclass(frozen=True, eq=False)
class ViscosityCheck:
    """Result of :func:`viscosity_check`.

    Attributes
    ----------
    problem : ViscosityProblem
    slope : ndarray of shape (runs,), N s/m
        Commanded viscosity ``k = dF/dV`` of each run.
    spacing, v0 : ndarray of shape (runs,), m/s
        Contact spacing and start speed.
    start : ndarray of shape (runs,)
        Start relative to the reference in spacings, ``x0 = (V0 - c) / s``.
    tau, tau_predicted : ndarray of shape (runs,), s
        Fitted time constant and ``C m / k``.
    tau_true : ndarray of shape (runs,), s
        The same fit on the true speed of the same runs (equals ``tau`` in the ideal mode;
        in the loop it separates the motor lag's share from the estimator's).
    correction : ndarray of shape (runs,)
        ``C`` on the commanded speeds (:func:`~toolkit.predictions.theory.viscosity_correction`).
    settled, settled_predicted : ndarray of shape (runs,), m/s
        Settled speed read off the run and the model's resting speed.
    ok : ndarray of shape (runs,), bool
        The run finished and was measured.
    k_fit, k_predicted : float
        Slopes of ``1 / tau`` and of ``1 / tau_predicted`` against ``k / m`` (through 0).
    r2 : float
        ``R^2`` of the fit of ``1 / tau`` (see :func:`~toolkit.predictions._measure.proportional_fit`).
    r2_corrected : float
        ``R^2`` of ``1 / tau`` fitted against ``1 / tau_predicted`` (through 0): how much of
        the scatter about the proportional law the per-run correction explains.
    k_fit_true, r2_true : float
        ``k_fit`` and ``r2`` from ``tau_true``.
    status : CheckStatus
    message : str
    wall_time : float, s
    """

    problem: ViscosityProblem
    slope: np.ndarray
    spacing: np.ndarray
    v0: np.ndarray
    start: np.ndarray
    tau: np.ndarray
    tau_predicted: np.ndarray
    tau_true: np.ndarray
    correction: np.ndarray
    settled: np.ndarray
    settled_predicted: np.ndarray
    ok: np.ndarray
    k_fit: float
    k_predicted: float
    r2: float
    r2_corrected: float
    k_fit_true: float
    r2_true: float
    status: CheckStatus
    message: str
    wall_time: float

    @property
    def runs(self) -> int:
        """Number of runs."""
        return int(self.slope.size)

    @property
    def ratio(self) -> float:
        """``k_fit / k_predicted``."""
        return self.k_fit / self.k_predicted

    @property
    def met(self) -> bool:
        """Every target met."""
        return self.status is CheckStatus.MET

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (no per-run arrays): ``runs``, ``r2``, ``k_fit``, ``k_predicted``,
        ``ratio``, ``r2_corrected``, ``true_speed`` (``k_fit``, ``r2`` on the true speed), ``mode``, ``status``, ``message``, ``wall_time``, ``correction_range``,
        ``tau_ratio_range`` (``tau / tau_predicted``), ``targets``."""
        good = self.ok
        ratio = self.tau[good] / self.tau_predicted[good]
        return {"runs": self.runs, "r2": self.r2, "k_fit": self.k_fit, "k_predicted": self.k_predicted,
                "ratio": self.ratio, "r2_corrected": self.r2_corrected,
                "true_speed": {"k_fit": self.k_fit_true, "r2": self.r2_true}, "mode": self.problem.mode, "status": self.status.name,
                "message": self.message, "wall_time": self.wall_time,
                "correction_range": [float(self.correction.min()), float(self.correction.max())],
                "tau_ratio_range": [float(ratio.min()), float(ratio.max())] if ratio.size else None,
                "targets": {"r2_min": self.problem.targets[0], "k_rel_max": self.problem.targets[1]}}


def _progress(total: int, progress: bool, desc: str) -> Any:
    """A tqdm bar on stderr (disabled unless ``progress``)."""
    from tqdm import tqdm

    return tqdm(total=total, disable=not progress, desc=desc, file=sys.stderr, leave=False,
                dynamic_ncols=True)


def viscosity_check(problem: ViscosityProblem | None = None, *, progress: bool = False) -> ViscosityCheck:
    """Run the viscosity sweep and compare it with the derived correction.

    Parameters
    ----------
    problem : ViscosityProblem, optional
        Default: ``ViscosityProblem()`` (the carousel, 490 runs, in the loop).
    progress : bool
        Show a progress bar (tqdm) on stderr.

    Returns
    -------
    ViscosityCheck
    """
    if problem is None:
        problem = ViscosityProblem()
    if not isinstance(problem, ViscosityProblem):
        raise ParameterTypeError(parameter_message("problem", "viscosity_check", "be a ViscosityProblem", problem))
    started = time.perf_counter()
    a, p = problem.apparatus, problem
    n, f, m = a.n, a.force, a.mass
    design, sensor_seeds = np.random.SeedSequence(p.seed).spawn(2)
    rng = np.random.default_rng(design)
    spacing = rng.uniform(*p.spacing, p.runs)
    position = rng.uniform(*p.start, p.runs)
    up = rng.random(p.runs) < 0.5
    seeds = sensor_seeds.spawn(p.runs)
    half = (n - 1) / 2.0
    slope = 2.0 * f / spacing
    x0 = np.where(up, -(half - position), half - position)
    v0 = x0 * spacing
    loop = p.mode == "loop"
    out = {name: np.full(p.runs, np.nan) for name in ("tau", "tau_predicted", "tau_true", "correction",
                                                      "settled", "settled_predicted")}
    ok = np.zeros(p.runs, dtype=bool)
    failures: list[str] = []
    bar = _progress(p.runs, progress, f"viscosity ({p.mode})")
    try:
        for r in range(p.runs):
            plant = a.run_plant(v0[r], p.mode)
            controller = VirtualViscosity(float(slope[r]), 0.0)
            commanded = controller.speeds(plant)
            contacts = ContactSet(commanded, plant.contacts.forces)
            stop = resting_speed(contacts, v0[r])
            t_stop = travel_time(contacts, m, v0[r], stop)
            C = viscosity_correction(contacts, m, v0[r], slope[r])
            out["correction"][r], out["settled_predicted"][r] = C, stop
            out["tau_predicted"][r] = C * m / slope[r]
            run = simulate_closed_loop(plant, CarryThen(controller, p.pre_roll, float(v0[r])),
                                       p.pre_roll + t_stop + p.tail, v0=float(v0[r]),
                                       sensors=a.sensors if loop else None, seed=seeds[r])
            bar.update(1)
            if run.status is not SimulationStatus.SUCCESS:
                failures.append(f"run {r}: {run.message}")
                continue
            first = int(np.searchsorted(run.times, p.pre_roll - 1e-9))
            tau, settled = startup_time_constant(run.times[first:], run.estimate[first:], p.tail_samples)
            out["tau"][r], out["settled"][r] = tau, settled
            out["tau_true"][r] = (tau if not loop else
                                  startup_time_constant(run.times[first:], run.speed[first:], p.tail_samples)[0])
            if math.isfinite(tau) and tau > 0:
                ok[r] = True
            else:
                failures.append(f"run {r}: no startup to measure (tau = {tau})")
    finally:
        bar.close()
    x = slope[ok] / m
    k_fit, r2 = proportional_fit(x, 1.0 / out["tau"][ok]) if ok.sum() >= 2 else (math.nan, math.nan)
    k_pred = proportional_fit(x, 1.0 / out["tau_predicted"][ok])[0] if ok.sum() >= 2 else math.nan
    r2_corrected = (proportional_fit(1.0 / out["tau_predicted"][ok], 1.0 / out["tau"][ok])[1]
                    if ok.sum() >= 2 else math.nan)
    ok_true = ok & np.isfinite(out["tau_true"])
    k_true, r2_true = (proportional_fit(slope[ok_true] / m, 1.0 / out["tau_true"][ok_true])
                       if ok_true.sum() >= 2 else (math.nan, math.nan))
    r2_min, rel_max = p.targets
    rel = abs(k_fit / k_pred - 1.0) if math.isfinite(k_fit) else math.inf
    if failures:
        status = CheckStatus.FAILED
        message = f"{len(failures)} of {p.runs} runs failed ({failures[0]})"
    else:
        missed = []
        if not r2 >= r2_min:
            missed.append(f"R^2 {r2:.4f} < {r2_min:g}")
        if not rel <= rel_max:
            missed.append(f"k_fit / k_predicted = {k_fit / k_pred:.4f}, off by {rel:.1%} > {rel_max:.0%}")
        status = CheckStatus.SHORT if missed else CheckStatus.MET
        message = ("; ".join(missed) if missed else
                   f"R^2 {r2:.4f} >= {r2_min:g}, k_fit / k_predicted = {k_fit / k_pred:.4f}")
    return ViscosityCheck(p, slope, spacing, v0, x0, out["tau"], out["tau_predicted"], out["tau_true"],
                          out["correction"], out["settled"], out["settled_predicted"], ok, k_fit, k_pred, r2,
                          r2_corrected, k_true, r2_true, status,
                          message, time.perf_counter() - started)
