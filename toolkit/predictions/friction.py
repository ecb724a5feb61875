"""The paper's friction-fraction experiment (its Fig. 6) in the closed loop.

``N/2 - j`` equal contacts at ``+v_max`` and ``N/2 + j`` at ``-v_max`` give ``mu/mu0 =
2 j / N``: measured with a test rig (:class:`~toolkit.controllers.ForceDrive`) as the paper
measured force-speed curves, and the transition time read off the speed and compared with
``dT = m 2 v_max / (F_tot mu/mu0)``, ideal or in the loop. The procedure:
docs/validation.md and docs/methods.md."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._compiled import budget_clock
from ..errors import as_float, as_int, check_option
from ..allocation import FrictionFraction, allocate
from ..loop.closed_loop import simulate_closed_loop
from ..controllers import ForceDrive, FrictionBrake
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..simulation import SimulationStatus
from ._measure import crossing_duration, rig_friction
from .apparatus import Apparatus
from .theory import transition_time
from .viscosity import CheckStatus, _progress

__all__ = ["FrictionFractionProblem", "FrictionFractionCheck", "friction_fraction_check", "RIG_ESTIMATORS"]

#: What the rig's speed loop may close on in the loop mode.
RIG_ESTIMATORS = ("kalman", "central_difference")


@dataclass(frozen=True, eq=False)
class FrictionFractionProblem:
    """Settings of the friction-fraction check (see the module docstring).

    Parameters
    ----------
    apparatus : Apparatus, optional
        An even number of equal contacts. Default: :meth:`Apparatus.carousel`.
    mode : {"ideal", "loop"}
    ramp : float, s
        Duration of each rig ramp (``> 0``): ``0.8 v_max -> -0.8 v_max`` through the band,
        ``0.9 v_max -> 0.1 v_max`` for the brake condition.
    window : float
        Share of the ramp, at its start, left out of the force reading (the rig's
        transient), in ``[0, 1)``.
    pre_roll, tail : float, s
        Carry time before braking (``>= 0``) and time after the predicted arrival (``> 0``).
    margin : float
        Share of ``v_max`` left out at both ends of the transition reading, in ``(0, 0.5)``.
    seed : int
    rig_estimator : {"kalman", "central_difference"}
        What the rig's speed loop closes on in the loop mode: the Kalman filter (default)
        or the central encoder's finite difference (the baseline, for comparison).
    targets : (float, float)
        ``|mu/mu0 - 2 j / N|`` at most the first; ``|dT / dT_predicted - 1|`` at most the second.
    """

    apparatus: Apparatus = field(default_factory=Apparatus.carousel)
    mode: str = "loop"
    ramp: float = 4.0
    window: float = 0.25
    pre_roll: float = 0.1
    tail: float = 0.3
    margin: float = 0.1
    seed: int = 0
    targets: tuple[float, float] = (0.02, 0.05)
    rig_estimator: str = "kalman"

    def __post_init__(self) -> None:
        owner = "FrictionFractionProblem"
        if not isinstance(self.apparatus, Apparatus):
            raise ParameterTypeError(parameter_message("apparatus", owner, "be an Apparatus", self.apparatus))
        if self.apparatus.n % 2:
            raise ParameterError(parameter_message(
                "apparatus", owner, "have an even number of contacts (they cancel in pairs)",
                f"{self.apparatus.n} contacts"))
        object.__setattr__(self, "mode", self.apparatus.check_mode(self.mode, owner))
        object.__setattr__(self, "ramp", as_float(self.ramp, "ramp", owner, low=0.0, low_open=True))
        window = as_float(self.window, "window", owner, low=0.0, high=1.0)
        rate = self.apparatus.sensors.rate if self.apparatus.sensors is not None else 50.0
        if (1.0 - window) * self.ramp * rate < 2.0:
            raise ParameterError(parameter_message(
                "window", owner, f"leave at least two sample periods of the {self.ramp:g} s ramp to read",
                self.window))
        object.__setattr__(self, "window", window)
        object.__setattr__(self, "pre_roll", as_float(self.pre_roll, "pre_roll", owner, low=0.0))
        object.__setattr__(self, "tail", as_float(self.tail, "tail", owner, low=0.0, low_open=True))
        margin = as_float(self.margin, "margin", owner, low=0.0, low_open=True)
        if margin >= 0.5:
            raise ParameterError(parameter_message("margin", owner, "be < 0.5", self.margin))
        object.__setattr__(self, "margin", margin)
        object.__setattr__(self, "seed", as_int(self.seed, "seed", owner, low=0))
        object.__setattr__(self, "rig_estimator", check_option(self.rig_estimator, "rig_estimator", owner,
                                                               RIG_ESTIMATORS))
        object.__setattr__(self, "targets", (as_float(self.targets[0], "targets", owner, low=0.0),
                                             as_float(self.targets[1], "targets", owner, low=0.0)))


@dataclass(frozen=True, eq=False)
class FrictionFractionCheck:
    """Result of :func:`friction_fraction_check`; arrays have one entry per ``j = 0..N/2``.

    Attributes
    ----------
    problem : FrictionFractionProblem
    n : ndarray of int
        ``j``, the number of contacts moved from ``+v_max`` to ``-v_max`` beyond half.
    mu_predicted, mu_ratio : ndarray
        ``2 j / N`` and the measured ``F / F0``.
    brake_force : float, N
        ``F0``, the brake condition's measured force (``-F_tot`` ideally).
    dT, dT_predicted : ndarray, s
        Measured and predicted transition times (``inf``: no transition).
    dT_measured_mu : ndarray, s
        The prediction from the measured ratio (the curve of the paper's transition-time
        panel, its Fig. 6c).
    ok : ndarray of bool
        Each ``j`` within both targets.
    status : CheckStatus
    message : str
    wall_time : float, s
    """

    problem: FrictionFractionProblem
    n: np.ndarray
    mu_predicted: np.ndarray
    mu_ratio: np.ndarray
    brake_force: float
    dT: np.ndarray
    dT_predicted: np.ndarray
    dT_measured_mu: np.ndarray
    ok: np.ndarray
    status: CheckStatus
    message: str
    wall_time: float

    @property
    def met(self) -> bool:
        """Every target met."""
        return self.status is CheckStatus.MET

    def rows(self) -> list[dict[str, Any]]:
        """One JSON-able dict per ``j``: ``n``, ``mu_ratio``, ``mu_predicted``, ``dT``,
        ``dT_predicted``, ``dT_measured_mu`` (s; None for an infinite time), ``ok``."""
        def finite(value: float) -> float | None:
            return float(value) if math.isfinite(value) else None

        return [{"n": int(j), "mu_ratio": float(mu), "mu_predicted": float(mp), "dT": finite(dt),
                 "dT_predicted": finite(dp), "dT_measured_mu": finite(dm), "ok": bool(good)}
                for j, mu, mp, dt, dp, dm, good in zip(self.n, self.mu_ratio, self.mu_predicted, self.dT,
                                                       self.dT_predicted, self.dT_measured_mu, self.ok)]


def _rig(a: Apparatus, speeds: np.ndarray, v_start: float, v_end: float, p: FrictionFractionProblem,
         seed: Any) -> tuple[float, str]:
    """Mean contact force (N) over the read part of one rig ramp, and a failure message."""
    loop = p.mode == "loop"
    plant = a.run_plant(speeds, p.mode)
    estimator = None                # with sensors: simulate_closed_loop's Kalman filter
    if loop and p.rig_estimator == "central_difference":
        from ..estimation import CentralDifference
        estimator = CentralDifference(a.sensors)
    run = simulate_closed_loop(plant, ForceDrive(speeds, v_start, v_end, p.ramp), p.ramp, v0=v_start,
                               sensors=a.sensors if loop else None, estimator=estimator, seed=seed)
    if run.status is not SimulationStatus.SUCCESS:
        return math.nan, run.message
    first = int(np.searchsorted(run.times, p.window * p.ramp - 1e-9))
    last = run.times.size - 1
    return rig_friction(run.times, run.estimate, run.force, a.mass, first, last), ""


def friction_fraction_check(problem: FrictionFractionProblem | None = None, *,
                            progress: bool = False) -> FrictionFractionCheck:
    """Measure ``mu/mu0`` and the transition time for ``j = 0..N/2`` and compare with the model.

    Parameters
    ----------
    problem : FrictionFractionProblem, optional
        Default: ``FrictionFractionProblem()`` (the carousel in the loop).
    progress : bool
        Show a progress bar (tqdm) on stderr.

    Returns
    -------
    FrictionFractionCheck
    """
    if problem is None:
        problem = FrictionFractionProblem()
    if not isinstance(problem, FrictionFractionProblem):
        raise ParameterTypeError(parameter_message(
            "problem", "friction_fraction_check", "be a FrictionFractionProblem", problem))
    started = budget_clock()
    p, a = problem, problem.apparatus
    v, m, N = a.speed_limit, a.mass, a.n
    js = np.arange(N // 2 + 1)
    fractions = 2.0 * js / N
    seeds = np.random.SeedSequence(p.seed).spawn(2 * js.size + 1)
    loop = p.mode == "loop"
    failures: list[str] = []
    bar = _progress(2 * js.size + 1, progress, f"friction fraction ({p.mode})")
    mu = np.full(js.size, np.nan)
    dT = np.full(js.size, np.nan)
    try:
        F0, failed = _rig(a, np.zeros(N), 0.9 * v, 0.1 * v, p, seeds[0])
        bar.update(1)
        if failed:
            failures.append(f"brake condition: {failed}")
        dT_pred = transition_time(m, v, a.total_force, fractions)
        slowest = transition_time(m, v, a.total_force, 2.0 / N)
        for i, (j, fraction) in enumerate(zip(js, fractions)):
            split = allocate(FrictionFraction(float(fraction), (-v, v)), a.plant.contacts,
                             speed_limits=(-v, v)).speeds
            F, failed = _rig(a, split, 0.8 * v, -0.8 * v, p, seeds[1 + 2 * i])
            bar.update(1)
            if failed:
                failures.append(f"rig at j = {j}: {failed}")
            mu[i] = F / F0
            window = dT_pred[i] if math.isfinite(dT_pred[i]) else 2.0 * slowest
            run = simulate_closed_loop(a.run_plant(v, p.mode), FrictionBrake(float(fraction), start=p.pre_roll),
                                       p.pre_roll + window + p.tail, v0=v,
                                       sensors=a.sensors if loop else None, seed=seeds[2 + 2 * i])
            bar.update(1)
            if run.status is not SimulationStatus.SUCCESS:
                failures.append(f"brake at j = {j}: {run.message}")
                continue
            first = int(np.searchsorted(run.times, p.pre_roll - 1e-9))
            dT[i] = crossing_duration(run.times[first:], run.estimate[first:], v, -v, p.margin * v)
    finally:
        bar.close()
    with np.errstate(divide="ignore", invalid="ignore"):
        dT_mu = transition_time(m, v, a.total_force, np.clip(np.nan_to_num(mu), 0.0, None))
        mu_tol, dT_tol = p.targets
        mu_ok = np.abs(mu - fractions) <= mu_tol
        dT_ok = np.where(np.isinf(dT_pred), np.isinf(dT), np.abs(dT / dT_pred - 1.0) <= dT_tol)
    ok = mu_ok & dT_ok
    if failures:
        status, message = CheckStatus.FAILED, f"{len(failures)} runs failed ({failures[0]})"
    elif ok.all():
        status = CheckStatus.MET
        finite = np.isfinite(dT_pred)
        rel = np.abs(dT[finite] / dT_pred[finite] - 1.0)
        message = (f"|mu/mu0 - 2j/N| <= {np.max(np.abs(mu - fractions)):.2g}, "
                   f"|dT / dT_predicted - 1| <= {np.max(rel):.2%}")
    else:
        status = CheckStatus.SHORT
        bad = []
        for i in np.flatnonzero(~ok):
            if not mu_ok[i]:
                bad.append(f"j = {js[i]}: mu/mu0 {mu[i]:.4f} vs {fractions[i]:.4f}")
            if not dT_ok[i]:
                bad.append(f"j = {js[i]}: dT {dT[i]:.4g} s vs {dT_pred[i]:.4g} s")
        message = "; ".join(bad)
    return FrictionFractionCheck(p, js, fractions, mu, float(F0), dT, np.asarray(dT_pred, dtype=float),
                                 np.asarray(dT_mu, dtype=float), ok, status, message,
                                 budget_clock() - started)
