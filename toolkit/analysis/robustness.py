"""How the estimators fare when the world is not the scene, scored against the practitioner's
baselines.

Named cases (:data:`ROBUSTNESS_CASES`): the carousel's brake record
(:func:`~toolkit.analysis.scenarios.carousel_brake_scenario`) in a world that departs from
the scene in one way or all at once, over seeds (:func:`robustness_table`); and the closed
loops on unequal wheels (:func:`loop_robustness`). Random worlds (:func:`draw_world` over
:data:`WORLD_RANGES`): scene, schedule and departures drawn at random, each a
:class:`RandomWorld` that is also a scene (:func:`toolkit.scenes.worlds.world_scene`), scored by
:func:`score_world` beside the default told the truth and held to :data:`WORLD_LINES`.
The estimators are told the declared scene only, never the truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..errors import as_float, as_int
from ..errors import ParameterError, parameter_message
from ..estimation.registry import TRUTH_TOLD
from ..model import ContactSet, Motors, PiecewiseConstant, Plant
from ..model.carousel import CAROUSEL
from ..model.sensors import MAX_JITTER_PERIODS, Encoder, Sensors
from ..model.truth import ModelPrior, WorldTruth, realize
from .scenarios import BrakeScenario, carousel_brake_scenario, grid_positions, record_world

__all__ = ["RobustnessCase", "ROBUSTNESS_CASES", "BASELINES", "RobustnessTable", "robustness_table",
           "robustness_estimators", "loop_robustness", "LoopRobustness", "WORLD_RANGES", "WORLD_DURATION",
           "DEPARTURES", "WORLD_METHODS", "RandomWorld", "draw_world", "world_scenario", "SCORES", "WorldScores",
           "WORLD_LINES", "score_world"]


@dataclass(frozen=True)
class RobustnessCase:
    """One way the world departs from the scene.

    Attributes
    ----------
    name : str
    truth : WorldTruth
    lag : float, s
        The scene's (nominal) motor lag the estimators are told.
    prior : ModelPrior or None
        What the estimators are told beyond the scene (default ``ModelPrior()``).
    """

    name: str
    truth: WorldTruth
    lag: float = 0.0075
    prior: ModelPrior | None = None

    def scenario(self, seed: int, t_end: float = 10.0) -> Any:
        """The brake scenario recorded in this world (seed and grid phase ``seed``), braked at
        half of ``t_end`` (s)."""
        return carousel_brake_scenario(seed=seed, grid_phase=seed, lag=self.lag, truth=self.truth, t_end=t_end,
                                       brake_time=0.5 * t_end, prior=self.prior)


def _cases() -> dict[str, RobustnessCase]:
    every = WorldTruth(friction_spread=0.2, drag=2.0, lag=0.02, contact_drift=1e-3, read_noise=0.5,
                       missed_count_prob=1e-3, jitter=5e-4)
    cases = [RobustnessCase("nominal", WorldTruth()),
             RobustnessCase("spread 5 %", WorldTruth(friction_spread=0.05)),
             RobustnessCase("spread 20 %", WorldTruth(friction_spread=0.2)),
             RobustnessCase("spread 40 %", WorldTruth(friction_spread=0.4)),
             RobustnessCase("drag 0.5", WorldTruth(drag=0.5)),
             RobustnessCase("drag 2", WorldTruth(drag=2.0)),
             RobustnessCase("lag 20 vs 7.5 ms", WorldTruth(lag=0.02)),
             RobustnessCase("lag 7.5 vs 0 ms", WorldTruth(lag=0.0075), lag=0.0),
             RobustnessCase("drift 1 mm/s/sqrt(s)", WorldTruth(contact_drift=1e-3)),
             RobustnessCase("read noise 0.5", WorldTruth(read_noise=0.5)),
             RobustnessCase("missed 1e-3", WorldTruth(missed_count_prob=1e-3)),
             RobustnessCase("jitter 0.5 ms", WorldTruth(jitter=5e-4)),
             RobustnessCase("all at once", every),
             # The same two worlds with the missed-count rate told (ModelPrior.missed_count_prob).
             RobustnessCase("missed 1e-3, told", WorldTruth(missed_count_prob=1e-3),
                            prior=ModelPrior(missed_count_prob=1e-3)),
             RobustnessCase("all at once, missed told", every, prior=ModelPrior(missed_count_prob=1e-3)),
             # Not told, with the rate's prior mean ten times below and above the truth.
             RobustnessCase("all at once, prior 1e-4", every, prior=ModelPrior(missed_count_mean=1e-4)),
             RobustnessCase("all at once, prior 1e-2", every, prior=ModelPrior(missed_count_mean=1e-2))]
    return {case.name: case for case in cases}


#: The fixed cases: the nominal world, each departure alone, and all at once (the
#: 20 % spread, 2 N s/m drag and 20 ms lag with every sensor fault).
ROBUSTNESS_CASES: dict[str, RobustnessCase] = _cases()

#: The practitioner's baselines the default estimator is held against.
BASELINES = ("central_difference", "foaw_end", "foaw_best", "alpha_beta")


def robustness_estimators(scenario: Any) -> dict[str, Any]:
    """The estimators compared on ``scenario``: the baselines (:data:`BASELINES`, FOAW with
    its band at one count, the alpha-beta tracker at ``F_tot / (2 m)``) and the default
    ``kalman``, all told the nominal scene only."""
    from ..estimation import AdaptiveWindow, AlphaBetaTracker, CentralDifference, KalmanEstimator

    sensors, model = scenario.sensors, scenario.model
    q = sensors.central.distance_per_count
    return {"central_difference": CentralDifference(sensors),
            "foaw_end": AdaptiveWindow(sensors, fit="end", band=q),
            "foaw_best": AdaptiveWindow(sensors, fit="best", band=q),
            "alpha_beta": AlphaBetaTracker.tuned(sensors, float(model.forces.sum()), model.mass),
            "kalman": KalmanEstimator(model, scenario.prior)}


def _with_truth_told(scenario: BrakeScenario) -> dict[str, Any]:
    """``robustness_estimators``, then the default told the scenario's true world
    (:func:`~toolkit.estimation.truth_told`, the reference; it alone reads the world)."""
    from ..estimation import truth_told

    return {**robustness_estimators(scenario), TRUTH_TOLD: truth_told(scenario.world)}


#: The phases scored (:data:`toolkit.estimation.PHASES`).
_PHASES = ("startup", "cruise", "brake", "braked")


@dataclass(frozen=True, eq=False)
class RobustnessTable:
    """Medians over seeds per case and estimator (see the module).

    Attributes
    ----------
    seeds : int
    cases : tuple of str
    estimators : tuple of str
    scores : dict of (case, estimator) to dict
        ``rms`` (m/s), ``startup`` / ``cruise`` / ``brake`` / ``braked`` (m/s), ``nees_in_band``,
        ``nees_over_100`` and ``nees_max`` (None without a covariance), ``us_per_sample``, ``missed_count_prob`` and
        ``missed_count_std`` (the rate the position was reported under, told or identified;
        None for estimators without it): medians over the seeds.
    raw : dict of (case, estimator) to ndarray of shape (seeds, 11)
        The per-seed values (rms, the four phases, nees_in_band, us_per_sample,
        missed_count_prob, missed_count_std, nees_over_100, nees_max).
    """

    seeds: int
    cases: tuple[str, ...]
    estimators: tuple[str, ...]
    scores: dict[tuple[str, str], dict[str, float | None]] = field(repr=False)
    raw: dict[tuple[str, str], np.ndarray] = field(repr=False)

    def checks(self) -> list[tuple[str, str, float, float, bool]]:
        """The robustness lines per case: ``(case, line, value, target, met)``. The default's
        overall RMS at most a fifth of the best baseline's; its cruise and braked RMS at most
        1.5 times the better FOAW's; its NEES in band on at least 80 % of the samples."""
        out = []
        for case in self.cases:
            kf = self.scores[(case, "kalman")]
            best = min(self.scores[(case, b)]["rms"] for b in BASELINES)
            out.append((case, "RMS <= best baseline / 5", kf["rms"], best / 5, kf["rms"] <= best / 5))
            for phase in ("cruise", "braked"):
                foaw = min(self.scores[(case, b)][phase] for b in ("foaw_end", "foaw_best"))
                out.append((case, f"{phase} <= 1.5 FOAW", kf[phase], 1.5 * foaw, kf[phase] <= 1.5 * foaw))
            nees = kf["nees_in_band"]
            out.append((case, "NEES in band >= 0.8", nees, 0.8, nees is not None and nees >= 0.8))
        return out

    def to_frame(self) -> Any:
        """The medians as a pandas DataFrame (mm/s and us), one row per case and estimator."""
        import pandas as pd

        rows = []
        for (case, name), score in self.scores.items():
            row = {"case": case, "estimator": name, "rms_mm_s": score["rms"] * 1e3}
            row.update({f"{p}_mm_s": score[p] * 1e3 for p in _PHASES})
            row.update(nees_in_band=score["nees_in_band"], nees_over_100=score["nees_over_100"],
                       nees_max=score["nees_max"], us_per_sample=score["us_per_sample"],
                       missed_count_prob=score["missed_count_prob"])
            rows.append(row)
        return pd.DataFrame(rows)


def robustness_table(cases: Any = None, seeds: int = 10, t_end: float = 10.0,
                     progress: Callable[[str, int], None] | None = None) -> RobustnessTable:
    """Score every estimator of ``robustness_estimators``, and beside them the default told
    the truth (``truth_told``), on ``cases`` over ``seeds``.

    Parameters
    ----------
    cases : iterable of str or RobustnessCase, optional
        Names of :data:`ROBUSTNESS_CASES` or cases; default all of them.
    seeds : int
        Seeds ``0 .. seeds - 1`` (each also the grid phase), ``>= 1``.
    t_end : float, s
        Length of each record (10 s; the brake at half of it).
    progress : callable, optional
        Called with ``(case name, seed)`` before each record.
    """
    owner = "robustness_table"
    seeds = as_int(seeds, "seeds", owner, low=1)
    t_end = as_float(t_end, "t_end", owner, low=2.0)
    chosen = []
    for case in (ROBUSTNESS_CASES.values() if cases is None else cases):
        if isinstance(case, str):
            if case not in ROBUSTNESS_CASES:
                raise ParameterError(parameter_message("cases", owner, f"name cases of {list(ROBUSTNESS_CASES)}",
                                                       case))
            case = ROBUSTNESS_CASES[case]
        chosen.append(case)
    raw: dict[tuple[str, str], list] = {}
    names: tuple[str, ...] = ()
    for case in chosen:
        for seed in range(seeds):
            if progress is not None:
                progress(case.name, seed)
            sc = case.scenario(seed, t_end=t_end)
            estimators = _with_truth_told(sc)
            names = tuple(estimators)
            for name, estimator in estimators.items():
                speed_std = 1e-4 if name in ("kalman", TRUTH_TOLD) else None
                result = estimator.run(sc.record, speed_std=speed_std) if speed_std else estimator.run(sc.record)
                phases = result.rms_phases
                raw.setdefault((case.name, name), []).append(
                    [result.rms_error] + [math.nan if phases[p] is None else phases[p] for p in _PHASES]
                    + [math.nan if result.nees_in_band is None else result.nees_in_band,
                       result.wall_time / sc.record.n_samples * 1e6,
                       math.nan if result.missed_count_prob is None else result.missed_count_prob,
                       math.nan if result.missed_count_std is None else result.missed_count_std,
                       math.nan if result.nees_over_100 is None else result.nees_over_100,
                       math.nan if result.nees_max is None else result.nees_max])
    arrays = {key: np.array(rows) for key, rows in raw.items()}
    scores = {}
    for key, table in arrays.items():
        med = np.median(table, axis=0)
        score: dict[str, float | None] = {"rms": float(med[0])}
        score.update({p: float(med[1 + i]) for i, p in enumerate(_PHASES)})
        score["nees_in_band"] = None if np.isnan(med[5]) else float(med[5])
        score["us_per_sample"] = float(med[6])
        score["missed_count_prob"] = None if np.isnan(med[7]) else float(med[7])
        score["missed_count_std"] = None if np.isnan(med[8]) else float(med[8])
        score["nees_over_100"] = None if np.isnan(med[9]) else float(med[9])
        score["nees_max"] = None if np.isnan(med[10]) else float(med[10])
        scores[key] = score
    return RobustnessTable(seeds, tuple(c.name for c in chosen), names, scores, arrays)


@dataclass(frozen=True, eq=False)
class LoopRobustness:
    """One closed loop on unequal wheels the filter is not told of (:func:`loop_robustness`).

    Attributes
    ----------
    controller : str
    spread : float
        The true wheels' friction spread.
    estimate_rms, difference_rms : ndarray of shape (seeds,), m/s
        After the first second: the in-loop estimate's RMS error and central differencing's
        on the same record.
    ratio : float
        Median over the seeds of ``difference_rms / estimate_rms``.
    """

    controller: str
    spread: float
    estimate_rms: np.ndarray
    difference_rms: np.ndarray
    ratio: float


def loop_robustness(controller: str, spread: float = 0.2, seeds: int = 10, t_end: float = 10.0) -> LoopRobustness:
    """The closed loop on the carousel in worlds of unequal wheels, scored against central
    differencing.

    The carousel (ten 1 N wheels, 5 kg, lag 7.5 ms, the paper's encoders) from rest under
    ``controller`` (``"speed_hold"``: SpeedHold(0.2 m/s, 50 N s/m); ``"viscosity"``:
    VirtualViscosity(50 N s/m, 0.15 m/s)) reading the default estimator built from the
    nominal scene, in worlds whose wheels' friction spreads by ``spread`` (seeds ``0`` to
    ``seeds - 1``); the in-loop estimate's RMS after the first second against central
    differencing's on the same record."""
    from ..controllers import SpeedHold, VirtualViscosity
    from ..estimation import CentralDifference, EstimatorModel, KalmanEstimator
    from ..loop.closed_loop import simulate_closed_loop

    owner = "loop_robustness"
    makers = {"speed_hold": lambda: SpeedHold(0.2, 50.0), "viscosity": lambda: VirtualViscosity(50.0, 0.15)}
    if controller not in makers:
        raise ParameterError(parameter_message("controller", owner, f"be one of {list(makers)}", controller))
    spread = as_float(spread, "spread", owner, low=0.0)
    seeds = as_int(seeds, "seeds", owner, low=1)
    nominal = Plant(ContactSet([0.0] * 10, [1.0] * 10), 5.0, motors=CAROUSEL.motors())
    sensors = CAROUSEL.sensors(10)
    model = EstimatorModel(nominal.contacts.forces, nominal.mass, sensors, motor_lag=CAROUSEL.motor_lag,
                           speed_limits=nominal.motors.speed_limits)
    kf, fd = [], []
    for seed in range(seeds):
        world = realize(nominal, sensors, WorldTruth(friction_spread=spread), seed)
        run = simulate_closed_loop(world.plant, makers[controller](), t_end, sensors=world.sensors,
                                   estimator=KalmanEstimator(model), seed=seed)
        late = run.times >= 1.0
        kf.append(float(np.sqrt(np.mean(run.estimation_error[late] ** 2))))
        diff = CentralDifference(sensors).run(run.record).speed - run.speed
        fd.append(float(np.sqrt(np.mean(diff[late] ** 2))))
    kf_a, fd_a = np.array(kf), np.array(fd)
    return LoopRobustness(controller, spread, kf_a, fd_a, float(np.median(fd_a / kf_a)))


# -- worlds drawn at random --------------------------------------------------------------------

#: The ranges random worlds are drawn from (:func:`draw_world`), each ``(low, high)`` in the
#: unit named: contacts (count), the body mass (kg), the sample rate (Hz), the encoders'
#: counts per turn as a fraction of the carousel's (1), command steps (count), the speeds
#: commanded and the start speed (m/s), the told motor lag (s), and the departures of
#: :class:`~toolkit.model.truth.WorldTruth` (the jitter in periods, up to the encoders' limit).
WORLD_RANGES: dict[str, tuple[float, float]] = {
    "contacts": (3, 40), "mass": (0.25 * CAROUSEL.moving_mass, 4.0 * CAROUSEL.moving_mass),
    "rate": (10.0, 500.0), "wheel_scale": (0.25, 1.0), "central_scale": (0.25, 1.0), "steps": (1, 4),
    "speed": (-CAROUSEL.speed_limit, CAROUSEL.speed_limit), "v0": (-0.3, 0.3), "told_lag": (0.0, 0.05),
    "friction_spread": (0.0, 0.8), "drag": (0.0, 5.0), "lag": (0.0, 0.05), "contact_drift": (0.0, 3e-3),
    "read_noise": (0.0, 1.0), "missed_count_prob": (0.0, 1e-2), "jitter_periods": (0.0, MAX_JITTER_PERIODS)}
#: Length of a random world's record, s.
WORLD_DURATION = 10.0
#: The departures a world may draw, each present with probability one half (any subset).
DEPARTURES = ("friction_spread", "drag", "lag", "contact_drift", "read_noise", "missed_count_prob", "jitter")
#: The estimators a world scores: the baselines, the default and the default told the truth.
WORLD_METHODS = (*BASELINES, "kalman")


@dataclass(frozen=True)
class RandomWorld:
    """One world drawn at random (:func:`draw_world`): a scene and how the truth departs from it.

    Attributes
    ----------
    label : str
        ``"S/i"``: drawn as world ``i`` of seed ``S``.
    seed : int
        Draws the truth's wheels and wander, the sensors' noise and the grids' phase (the
        scene's ``[estimation] seed``).
    forces : tuple of float, N
        The declared friction magnitudes (the truth spreads them).
    mass : float, kg
    rate : float, Hz
    wheel_scale, central_scale : float
        Counts per turn of the wheel and central encoders as a fraction of the carousel's.
    lag : float, s
        The motor lag the scene declares (the truth may differ).
    v0 : float, m/s
        Start speed (0: from rest).
    times : tuple of float, s
        When the commands change (1-4 steps; two within one period are a transient the
        samples do not see).
    commands : tuple of tuple of float, m/s
        The commands: before ``times[0]`` (the motors settled there), then from each time.
    truth : WorldTruth
    duration : float, s
    """

    label: str
    seed: int
    forces: tuple[float, ...]
    mass: float
    rate: float
    wheel_scale: float
    central_scale: float
    lag: float
    v0: float
    times: tuple[float, ...]
    commands: tuple[tuple[float, ...], ...]
    truth: WorldTruth
    duration: float = WORLD_DURATION

    @property
    def n(self) -> int:
        """Number of contacts."""
        return len(self.forces)

    def sensors(self) -> Sensors:
        """The declared encoders: the carousel's, coarser by the scales, read at ``rate``."""
        return Sensors(Encoder(CAROUSEL.central_counts_per_rev * self.central_scale, CAROUSEL.contact_radius,
                               self.rate),
                       Encoder(CAROUSEL.wheel_counts_per_rev * self.wheel_scale, CAROUSEL.wheel_radius, self.rate,
                               CAROUSEL.wheel_backlash), self.n)

    def plant(self) -> Plant:
        """The declared plant: the contacts at the first command, the mass, the told lag, the
        carousel's speed limits and the commands."""
        v_max = CAROUSEL.speed_limit
        return Plant(ContactSet(self.commands[0], self.forces), self.mass,
                     motors=Motors(lag=self.lag, speed_limits=(-v_max, v_max)),
                     commands=PiecewiseConstant(self.times, self.commands))

    def __str__(self) -> str:
        return self.describe()

    def describe(self) -> str:
        """What was drawn, in words with units (also ``str(world)``)."""
        f = np.array(self.forces)
        period = 1.0 / self.rate
        steps = ", ".join(f"{t:.4g}" + (" (within a period of the last)" if i and t - self.times[i - 1] < period
                                       else "") for i, t in enumerate(self.times))
        start = "from rest" if self.v0 == 0.0 else f"from {self.v0 * 1e3:.0f} mm/s"
        return (f"world {self.label} (seed {self.seed}): {self.n} contacts ({f.min():.2g}-{f.max():.2g} N, "
                f"F_tot {f.sum():.3g} N), {self.mass:.3g} kg, {self.rate:.4g} Hz, wheel x{self.wheel_scale:.2f} "
                f"central x{self.central_scale:.2f} counts per turn, lag told {self.lag * 1e3:.3g} ms, {start}; "
                f"commands change at {steps} s; truth: {self.truth.describe()}")


def _draw(rng: np.random.Generator, key: str, size: int | None = None, log: bool = False) -> Any:
    """A uniform (or log-uniform) draw over :data:`WORLD_RANGES` ``[key]``."""
    low, high = WORLD_RANGES[key]
    if log:
        return np.exp(rng.uniform(np.log(low), np.log(high), size))
    return rng.uniform(low, high, size)


def draw_world(seed: int, index: int) -> RandomWorld:
    """World ``index`` of ``seed``, drawn from ``numpy.random.default_rng([seed, index])`` over
    :data:`WORLD_RANGES` (so it does not depend on how many worlds are drawn with it).

    The contacts' count is uniform; each magnitude is a log-uniform 0.2-2 N scale times a
    lognormal factor (std 0.5 of its log); mass and rate are log-uniform; every commanded
    speed is a uniform centre in +-0.25 m/s plus a uniform offset of up to a uniform
    0-0.1 m/s, clipped to the speed limits; the step times are uniform over 0.5 s to 1.5 s
    before the end, and with probability 0.3 (two steps or more) one step follows another
    within a period. Half the worlds start from rest. Each departure of :data:`DEPARTURES`
    is present with probability one half, uniform over its range.
    """
    owner = "draw_world"
    seed, index = as_int(seed, "seed", owner, low=0), as_int(index, "index", owner, low=0)
    rng = np.random.default_rng([seed, index])
    lo, hi = WORLD_RANGES["contacts"]
    n = int(rng.integers(lo, hi + 1))
    forces = rng.uniform(np.log(0.2), np.log(2.0)) + rng.normal(0.0, 0.5, n)
    mass, rate = float(_draw(rng, "mass", log=True)), float(_draw(rng, "rate", log=True))
    lo, hi = WORLD_RANGES["steps"]
    k = int(rng.integers(lo, hi + 1))
    times = np.sort(rng.uniform(0.5, WORLD_DURATION - 1.5, k))
    if k >= 2 and rng.random() < 0.3:
        j = int(rng.integers(0, k - 1))
        times[j + 1] = times[j] + rng.uniform(0.05, 0.95) / rate
        times = np.sort(times)
    low, high = WORLD_RANGES["speed"]
    commands = np.clip(rng.uniform(-0.25, 0.25, (k + 1, 1))
                       + rng.uniform(0.0, 0.1, (k + 1, 1)) * rng.uniform(-1.0, 1.0, (k + 1, n)), low, high)
    departures: dict[str, float] = {}
    for key in DEPARTURES:
        if rng.random() < 0.5:
            departures[key] = float(_draw(rng, "jitter_periods" if key == "jitter" else key))
    if "jitter" in departures:
        departures["jitter"] /= rate
    return RandomWorld(
        label=f"{seed}/{index}", seed=int(rng.integers(0, 2**31)), forces=tuple(np.exp(forces).tolist()),
        mass=mass, rate=rate, wheel_scale=float(_draw(rng, "wheel_scale")),
        central_scale=float(_draw(rng, "central_scale")), lag=float(_draw(rng, "told_lag")),
        v0=0.0 if rng.random() < 0.5 else float(_draw(rng, "v0")), times=tuple(times.tolist()),
        commands=tuple(tuple(row) for row in commands.tolist()), truth=WorldTruth(**departures))


def world_scenario(world: RandomWorld) -> BrakeScenario:
    """Simulate ``world`` as a scene does (:func:`~toolkit.scenes.study.estimate_scene` on
    :func:`toolkit.scenes.worlds.world_scene`): the truth realized from the seed, recorded exactly with the
    seed's grid phase; the model the declared plant's (what the estimators are told)."""
    from ..loop.closed_loop import nominal_model

    nominal, sensors = world.plant(), world.sensors()
    true = realize(nominal, sensors, world.truth, world.seed)
    result, record = record_world(true, world.duration, seed=world.seed, v0=world.v0,
                                  **grid_positions(sensors, world.seed))
    return BrakeScenario(true.plant, result, record, sensors, nominal_model(nominal, sensors), ModelPrior(), true,
                         nominal)


#: Per estimator, the scores a world reports (:func:`score_world`).
SCORES = ("rms", *_PHASES, "nees_in_band", "nees_over_100", "nees_max", "us_per_sample")


@dataclass(frozen=True, eq=False)
class WorldScores:
    """The estimators' scores on one random world (:func:`score_world`).

    Attributes
    ----------
    world : RandomWorld
    scores : dict of str to dict of str to float or None
        Per estimator (:data:`WORLD_METHODS`, then ``truth_told``), :data:`SCORES`: RMS
        overall and per phase (m/s; None for a phase the record lacks), the NEES shares and
        largest NEES (None without a covariance), wall time per sample (us).
    """

    world: RandomWorld
    scores: dict[str, dict[str, float | None]]

    def best_baseline(self, key: str = "rms") -> float | None:
        """The best baseline's ``key`` (m/s; None where no baseline has it)."""
        values = [self.scores[b][key] for b in BASELINES if self.scores[b][key] is not None]
        return min(values) if values else None

    @property
    def ratio(self) -> float:
        """The default's overall RMS over the best baseline's."""
        return self.scores["kalman"]["rms"] / self.best_baseline()

    def checks(self, name: str = "kalman") -> dict[str, bool]:
        """Each line of :data:`WORLD_LINES`: met on this world by the estimator ``name`` (the
        default ``kalman``; ``truth_told`` shows what is achievable)."""
        kf, told = self.scores[name], self.scores[TRUTH_TOLD]
        best = self.best_baseline()
        phases = [(kf[p], self.best_baseline(p)) for p in _PHASES if kf[p] is not None]
        return {"never worse than the best baseline": kf["rms"] <= best,
                "each phase <= 1.5 x the best baseline's": all(v <= 1.5 * b for v, b in phases if b is not None),
                "RMS <= best baseline / 5": kf["rms"] <= best / 5,
                "RMS <= 2 x truth-told": kf["rms"] <= 2.0 * told["rms"],
                "nees_in_band >= 0.8": kf["nees_in_band"] is not None and kf["nees_in_band"] >= 0.8,
                "nees_over_100 <= 0.005": kf["nees_over_100"] is not None and kf["nees_over_100"] <= 0.005}


#: The lines a random world is held to (:meth:`WorldScores.checks`) and the share of worlds
#: each must hold on.
WORLD_LINES: dict[str, float] = {"never worse than the best baseline": 1.0,
                                 "each phase <= 1.5 x the best baseline's": 1.0,
                                 "RMS <= best baseline / 5": 0.9, "RMS <= 2 x truth-told": 0.9,
                                 "nees_in_band >= 0.8": 0.9, "nees_over_100 <= 0.005": 1.0}


def score_world(world: RandomWorld) -> WorldScores:
    """Run :data:`WORLD_METHODS` and ``truth_told`` over ``world``'s record as a scene does
    (:func:`world_scenario`): each from the start speed with a prior std of 1e-4 m/s (the
    scene's ``speed_std``)."""
    sc = world_scenario(world)
    estimators = _with_truth_told(sc)
    scores: dict[str, dict[str, float | None]] = {}
    for name, estimator in estimators.items():
        result = estimator.run(sc.record, speed=world.v0, speed_std=1e-4)
        row: dict[str, float | None] = {"rms": result.rms_error, **result.rms_phases}
        row.update(nees_in_band=result.nees_in_band, nees_over_100=result.nees_over_100,
                   nees_max=result.nees_max, us_per_sample=result.wall_time / sc.record.n_samples * 1e6)
        scores[name] = row
    return WorldScores(world, scores)
