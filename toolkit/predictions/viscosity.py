"""The paper's viscosity experiment (its Fig. 5) in the closed loop, against the ideal model.

Each run commands a virtual viscosity on a moving body and reads the startup's time constant
under each definition; ``1 / tau`` is fitted against ``k / m`` through the origin and compared
with the ideal model's correction. One function per step (:func:`draw_design`,
:func:`plan_runs`, the runs, :func:`measure_time_constants`, :func:`predict_time_constants`,
:func:`fit_viscosity`); the sweep's design: docs/validation.md and docs/methods.md."""

from __future__ import annotations

import enum
import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from .._compiled import budget_clock
from .._compiled import ensure_compiled
from .._forked import fork_map, idle_cores
from ..controllers import OpenLoop, VirtualViscosity
from ..errors import ParameterError, ParameterTypeError, as_float, as_int, check_option, parameter_message
from ..loop.closed_loop import LOOP_RATE, nominal_model, simulate_closed_loop
from ..model import ContactSet, PiecewiseConstant, sample_count
from ..simulation import SimulationStatus, sampled_batch
from ._measure import TIME_CONSTANTS, proportional_fit, startup_time_constant
from .apparatus import Apparatus, CarryThen
from .theory import least_squares_correction, resting_speed, travel_time, viscosity_correction

__all__ = ["ViscosityProblem", "ViscosityDesign", "ViscosityFit", "ViscosityCheck", "CheckStatus",
           "viscosity_check", "draw_design", "plan_runs", "measure_time_constants",
           "predict_time_constants", "fit_viscosity", "START_GROUPS", "EQUILIBRIUM_MARGIN", "MIN_CONTACTS"]

#: The groups of starts fitted apart: inside the spread (``p >= 0``) and below it.
START_GROUPS = ("inside", "outside")
#: Fewest in-loop runs per forked process :func:`viscosity_check` uses by default.
RUNS_PER_PROCESS = 8
_NO_SWITCH = np.empty(0)            # (a PiecewiseConstant's switching times: none, a constant)
#: Spacings between the default starts and the equilibrium set, at least (for ``n >= 10``).
EQUILIBRIUM_MARGIN = 3.0
#: Fewest contacts for which the default starts (0 to 1 spacing above the lowest contact)
#: lie below the equilibrium set: ``(n - 1) / 2 - 1`` spacings must exceed its half-width
#: (0 for odd ``n``, 1/2 for even), so 5 (odd) or 6 (even).
MIN_CONTACTS = 5
_DEFAULT_START = (0.0, 1.0)


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


def _definitions(value: Any, owner: str) -> tuple[str, ...]:
    if isinstance(value, str) or not hasattr(value, "__iter__"):
        raise ParameterTypeError(parameter_message("definitions", owner, f"be a sequence of {list(TIME_CONSTANTS)}",
                                                   value))
    names = tuple(check_option(d, "definitions", owner, TIME_CONSTANTS) for d in value)
    if not names or len(set(names)) != len(names):
        raise ParameterError(parameter_message("definitions", owner, "name each definition once, at least one",
                                               value))
    return names


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
    spacing : (float, float), m/s, optional
        Range of the contact spacing ``s``; the staircase must fit between the speed limits.
        Default ``(0.2 / n, 0.6 / n)``.
    start : (float, float), optional
        Range of the start's position above the lowest contact, in spacings (negative: below
        the whole staircase, fitted apart). Default ``(0, 1)``, which needs at least
        ``MIN_CONTACTS`` contacts.
    pre_roll, tail : float, s
        Carry time before the staircase (``>= 0``) and settled time after the predicted
        stop (``> 0``).
    tail_samples : int
        Samples averaged for the settled speed, ``>= 1``; they must fit in ``tail``.
    seed : int
        Seeds the design and the sensors.
    targets : (float, float)
        ``R^2`` at least the first; ``|k_fit / k_predicted - 1|`` at most the second (each
        definition, the starts inside the spread).
    definitions : sequence of str
        The time-constant definitions read off every run, the first the primary
        (:attr:`ViscosityCheck.k_fit` and friends). Default: both, ``"least_squares"`` first.
    """

    apparatus: Apparatus = field(default_factory=Apparatus.carousel)
    mode: str = "loop"
    runs: int = 490
    spacing: tuple[float, float] | None = None
    start: tuple[float, float] | None = None
    pre_roll: float = 0.1
    tail: float = 0.2
    tail_samples: int = 5
    seed: int = 0
    targets: tuple[float, float] = (0.98, 0.05)
    definitions: tuple[str, ...] = TIME_CONSTANTS

    def __post_init__(self) -> None:
        owner = "ViscosityProblem"
        if not isinstance(self.apparatus, Apparatus):
            raise ParameterTypeError(parameter_message("apparatus", owner, "be an Apparatus", self.apparatus))
        a = self.apparatus
        object.__setattr__(self, "mode", a.check_mode(self.mode, owner))
        object.__setattr__(self, "runs", as_int(self.runs, "runs", owner, low=2))
        default = (0.2 / a.n, 0.6 / a.n)
        spacing = _pair(default if self.spacing is None else self.spacing, "spacing", owner, low=0.0)
        given = self.start is not None
        start = _pair(self.start if given else _DEFAULT_START, "start", owner)
        object.__setattr__(self, "spacing", spacing)
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "pre_roll", as_float(self.pre_roll, "pre_roll", owner, low=0.0))
        object.__setattr__(self, "tail", as_float(self.tail, "tail", owner, low=0.0, low_open=True))
        object.__setattr__(self, "tail_samples", as_int(self.tail_samples, "tail_samples", owner, low=1))
        object.__setattr__(self, "seed", as_int(self.seed, "seed", owner, low=0))
        object.__setattr__(self, "targets", (as_float(self.targets[0], "targets", owner, high=1.0),
                                             as_float(self.targets[1], "targets", owner, low=0.0)))
        object.__setattr__(self, "definitions", _definitions(self.definitions, owner))
        half = (a.n - 1) / 2.0
        if half * spacing[1] > a.speed_limit:
            raise ParameterError(parameter_message(
                "spacing", owner, f"keep the {a.n} contacts within +-{a.speed_limit:g} m/s "
                f"(at most {a.speed_limit / max(half, 0.5):.6g} m/s)", self.spacing))
        if not given and half - start[1] <= self.resting_position:
            raise ParameterError(parameter_message(
                "apparatus", owner, f"have at least {MIN_CONTACTS} contacts for the default starts (0 to 1 "
                "spacing above the lowest contact) to lie below the equilibrium set, or be given starts "
                "(start)", f"{a.n} contacts"))
        reach = (half - start[0]) * spacing[1]
        if reach > a.speed_limit:
            raise ParameterError(parameter_message(
                "start", owner, f"put every start within +-{a.speed_limit:g} m/s (the lowest start "
                f"with the widest spacing lies {reach:.6g} m/s from the reference)", self.start))
        if half - start[1] <= self.resting_position:
            raise ParameterError(parameter_message(
                "start", owner, f"leave the start outside the equilibrium set (below {half - self.resting_position:g} "
                "spacings from the lowest contact)", self.start))
        if self.tail_samples > sample_count(self.tail, self.rate) - 1:
            raise ParameterError(parameter_message(
                "tail_samples", owner, f"fit in the tail ({self.tail:g} s at {self.rate:g} Hz)", self.tail_samples))

    @property
    def rate(self) -> float:
        """Sample rate of the runs, Hz (the sensors' or the ideal loop's 50 Hz)."""
        sensors = self.apparatus.sensors
        return float(sensors.rate) if sensors is not None else 50.0

    @property
    def resting_position(self) -> float:
        """Distance (spacings) from the reference to the nearest point of the equilibrium set:
        0 for odd ``n``, 1/2 for even ``n``."""
        return 0.0 if self.apparatus.n % 2 else 0.5


@dataclass(frozen=True, eq=False)
class ViscosityDesign:
    """The seeded draw of a sweep and what the ideal model says of each run; arrays of shape (runs,).

    Attributes
    ----------
    slope : N s/m
        Commanded viscosity ``k = dF/dV``.
    spacing, v0 : m/s
        Contact spacing and start speed.
    position : spacings
        The start above the lowest contact (moving up) or below the highest (moving down).
    start : spacings
        ``x0 = (V0 - c) / s``.
    inside : bool
        The start lies inside the spread (``position >= 0``).
    seeds : list of numpy.random.SeedSequence
        Each run's sensor seed.
    settled_predicted : m/s
        The ideal model's resting speed.
    stop_time : s
        The ideal model's time from the start to the resting speed.
    window : s
        From the staircase's switch-on to the record's last sample: what is fitted.
    commanded : ndarray of shape (runs, n), m/s
        The contact speeds each run's :class:`~toolkit.controllers.VirtualViscosity` commands
        (its allocation, solved once here).
    """

    slope: np.ndarray
    spacing: np.ndarray
    v0: np.ndarray
    position: np.ndarray
    start: np.ndarray
    inside: np.ndarray
    seeds: list
    settled_predicted: np.ndarray
    stop_time: np.ndarray
    window: np.ndarray
    commanded: np.ndarray

    @property
    def runs(self) -> int:
        return int(self.slope.size)


def draw_design(problem: ViscosityProblem) -> dict[str, Any]:
    """The seeded draw: ``slope``, ``spacing``, ``position``, ``start``, ``v0``, ``inside``
    (arrays of shape (runs,)) and ``seeds`` (one sensor seed per run)."""
    a, p = problem.apparatus, problem
    design, sensor_seeds = np.random.SeedSequence(p.seed).spawn(2)
    rng = np.random.default_rng(design)
    spacing = rng.uniform(*p.spacing, p.runs)
    position = rng.uniform(*p.start, p.runs)
    up = rng.random(p.runs) < 0.5
    half = (a.n - 1) / 2.0
    x0 = np.where(up, -(half - position), half - position)
    return {"slope": 2.0 * a.force / spacing, "spacing": spacing, "position": position, "start": x0,
            "v0": x0 * spacing, "inside": position >= 0.0, "seeds": sensor_seeds.spawn(p.runs)}


def _commanded(problem: ViscosityProblem, slope: float, v0: float,
               speeds: np.ndarray | None = None) -> ContactSet:
    """The contacts the run's controller commands (the allocator's staircase; ``speeds``:
    the one already allocated, m/s)."""
    a = problem.apparatus
    plant = a.run_plant(v0, problem.mode)
    if speeds is None:
        speeds = VirtualViscosity(float(slope), 0.0).speeds(plant)
    return ContactSet(speeds, plant.contacts.forces)


def plan_runs(problem: ViscosityProblem) -> ViscosityDesign:
    """:func:`draw_design` and, per run, the ideal model's resting speed, the time to reach it
    and the fitted window (switch-on to the record's last sample at the sample rate)."""
    return _plan(problem, draw_design(problem), np.arange(problem.runs))


def _plan(problem: ViscosityProblem, drawn: dict[str, Any], rows: np.ndarray) -> ViscosityDesign:
    """:func:`plan_runs` of the runs ``rows`` (indices into the draw ``drawn``), in that order."""
    p, m = problem, problem.apparatus.mass
    d = {key: value[rows] for key, value in drawn.items() if key != "seeds"}
    seeds = [drawn["seeds"][r] for r in rows]
    runs = rows.size
    stop = np.empty(runs)
    t_stop = np.empty(runs)
    commanded = np.empty((runs, p.apparatus.n))
    for r in range(runs):
        contacts = _commanded(p, d["slope"][r], d["v0"][r])
        commanded[r] = contacts.speeds
        stop[r] = resting_speed(contacts, d["v0"][r])
        t_stop[r] = travel_time(contacts, m, d["v0"][r], stop[r])
    period = 1.0 / p.rate
    switch = np.ceil(p.pre_roll / period - 1e-9) * period          # the first sample from pre_roll on
    last = np.array([sample_count(p.pre_roll + t + p.tail, p.rate) - 1 for t in t_stop]) / p.rate
    return ViscosityDesign(d["slope"], d["spacing"], d["v0"], d["position"], d["start"], d["inside"],
                           seeds, stop, t_stop, last - switch, commanded)


def _progress(total: int, progress: bool, desc: str) -> Any:
    """A tqdm bar on stderr (disabled unless ``progress``)."""
    from tqdm import tqdm

    return tqdm(total=total, disable=not progress, desc=desc, file=sys.stderr, leave=False,
                dynamic_ncols=True)


def _simulate_startups(problem: ViscosityProblem, design: ViscosityDesign, bar: Any = None,
                       index: np.ndarray | None = None) -> tuple[list[Any], list[str]]:
    """Run every closed-loop startup of ``design``. Returns per run ``(times, estimate, speed)``
    from the staircase's switch-on (times from 0, s; speeds m/s), or ``None`` for a run that
    did not finish, and the failure messages (naming each run by ``index``, its number in the
    sweep; default its row). ``bar``: a progress bar to advance run by run (tqdm's ``update``).

    In the loop (encoders and the Kalman filter) each run is one closed loop
    (:func:`simulate_closed_loop`: compiled, the filter called per sample); ideal, every run
    at once (:func:`toolkit.simulation.sampled_batch`, in parallel over the cores: each run
    equals its :func:`simulate_closed_loop` at the default 50 Hz, the same kernel; tested)."""
    a, p = problem.apparatus, problem
    runs = design.runs
    index = np.arange(runs) if index is None else index
    records: list[Any] = []
    failures: list[str] = []
    plants = [a.run_plant(design.v0[r], p.mode) for r in range(runs)]
    # Each run's VirtualViscosity(slope) after the carry: its law is the constant staircase it
    # allocates when bound, which the plan already allocated (design.commanded): replayed
    # as is (the same table, tested equal to binding the VirtualViscosity again).
    controllers = [CarryThen(OpenLoop(PiecewiseConstant(_NO_SWITCH, design.commanded[r][None, :])),
                             p.pre_roll, float(design.v0[r])) for r in range(runs)]
    lengths = [p.pre_roll + float(design.stop_time[r]) + p.tail for r in range(runs)]
    update = bar.update if bar is not None else (lambda count: None)
    if p.mode == "loop":
        from ..estimation import KalmanEstimator   # filterpy: only in the loop

        # simulate_closed_loop's default estimator, a fresh one per run; its model built once
        # (the runs' plants differ only in their contact speeds, which it does not hold).
        model = nominal_model(plants[0], a.sensors) if runs else None
        outcomes = []
        for r in range(runs):
            run = simulate_closed_loop(plants[r], controllers[r], lengths[r], v0=float(design.v0[r]),
                                       sensors=a.sensors, estimator=KalmanEstimator(model),
                                       seed=design.seeds[r])
            update(1)
            failed = None if run.status is SimulationStatus.SUCCESS else run.message
            outcomes.append((run.times, run.estimate, run.speed, failed))
    else:
        outcomes = _together(plants, controllers, lengths, design.v0)
        update(runs)
    for r, (times, estimate, speed, failed) in enumerate(outcomes):
        if failed is not None:
            failures.append(f"run {index[r]}: {failed}")
            records.append(None)
            continue
        first = int(np.searchsorted(times, p.pre_roll - 1e-9))
        records.append((times[first:] - times[first], estimate[first:], speed[first:]))
    return records, failures


def _sweep_rows(problem: ViscosityProblem, drawn: dict[str, Any], rows: np.ndarray,
                bar: Any = None) -> tuple[ViscosityDesign, dict[str, Any], dict[str, np.ndarray], list[str]]:
    """Everything :func:`viscosity_check` does run by run, for the runs ``rows`` of the draw
    ``drawn``: their plan, closed loops, measured and predicted time constants, failures."""
    design = _plan(problem, drawn, rows)
    records, failures = _simulate_startups(problem, design, bar, rows)
    return design, measure_time_constants(problem, records), predict_time_constants(problem, design), failures


def _concatenated(parts: list[Any]) -> Any:
    """Arrays, lists, dicts of them and designs of the parts, joined run after run."""
    first = parts[0]
    if isinstance(first, np.ndarray):
        return np.concatenate(parts)
    if isinstance(first, list):
        return [x for part in parts for x in part]
    if isinstance(first, dict):
        return {key: _concatenated([part[key] for part in parts]) for key in first}
    return type(first)(*(_concatenated([getattr(part, f.name) for part in parts]) for f in fields(first)))


def _sweep(problem: ViscosityProblem, progress: bool, workers: int | None
           ) -> tuple[ViscosityDesign, dict[str, Any], dict[str, np.ndarray], list[str]]:
    """:func:`_sweep_rows` of every run: in the loop over ``workers`` processes (forked,
    :func:`toolkit._forked.fork_map`; default the idle cores, at most one per
    ``RUNS_PER_PROCESS`` runs), each an equal share of the
    runs; ideal in this process (its batch kernel already runs over the cores). Each run is
    computed whole by one process: the results do not depend on ``workers`` (tested)."""
    drawn = draw_design(problem)
    if problem.mode != "loop":
        count = 1
    else:   # (by default at least RUNS_PER_PROCESS runs each: a fork costs about what they do)
        count = min(idle_cores(), problem.runs // RUNS_PER_PROCESS) if workers is None else workers
    count = max(1, min(count, problem.runs))
    bar = _progress(problem.runs, progress, f"viscosity ({problem.mode})")
    try:
        if count == 1:
            return _sweep_rows(problem, drawn, np.arange(problem.runs), bar)
        # Every child inherits the compiled kernels (otherwise each would compile or load them).
        ensure_compiled("core", "lines")
        shares = np.array_split(np.arange(problem.runs), count)
        # (The bar follows this process's share, then counts the others' when they are back.)
        parts = fork_map(lambda rows: _sweep_rows(problem, drawn, rows, bar if rows is shares[0] else None),
                         shares)
        bar.update(problem.runs - shares[0].size)
    finally:
        bar.close()
    return tuple(_concatenated([part[i] for part in parts]) for i in range(4))  # type: ignore[return-value]


def _together(plants: list[Any], controllers: list[Any], lengths: list[float],
              v0: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, str | None]]:
    """The ideal runs at once on the true speed: ``(times, estimate, speed, failure)`` each."""
    laws = [controller.bind(plant, 1.0 / LOOP_RATE).sampled()
            for plant, controller in zip(plants, controllers)]
    samples = [sample_count(length, LOOP_RATE) for length in lengths]
    batch = sampled_batch(plants[0], laws, samples, LOOP_RATE, v0=v0,
                          contact_speeds=np.array([plant.initial_speeds() for plant in plants]))
    runs = []
    for r, count in enumerate(samples):
        failed = None if batch["codes"][r] == 0 else f"a plant step stopped (code {batch['codes'][r]})"
        speed = batch["speed"][r, :count]
        runs.append((batch["times"][:count], speed, speed, failed))
    return runs


def measure_time_constants(problem: ViscosityProblem, records: list[Any]) -> dict[str, Any]:
    """Read every run's time constant under each definition of the problem.

    Returns
    -------
    dict
        ``tau`` and ``tau_true`` (dicts by definition of arrays of shape (runs,), s: on the
        estimate and on the true speed; equal in the ideal mode), ``settled`` (m/s, on the
        estimate) and ``window`` (s, switch-on to the last sample; ``nan`` for a failed run).
    """
    runs = len(records)
    tau = {d: np.full(runs, np.nan) for d in problem.definitions}
    tau_true = {d: np.full(runs, np.nan) for d in problem.definitions}
    settled = np.full(runs, np.nan)
    window = np.full(runs, np.nan)
    for r, record in enumerate(records):
        if record is None:
            continue
        times, estimate, speed = record
        window[r] = times[-1]
        for d in problem.definitions:
            tau[d][r], settled[r] = startup_time_constant(d, times, estimate, problem.tail_samples)
            tau_true[d][r] = (tau[d][r] if problem.mode == "ideal" else
                              startup_time_constant(d, times, speed, problem.tail_samples)[0])
    return {"tau": tau, "tau_true": tau_true, "settled": settled, "window": window}


def predict_time_constants(problem: ViscosityProblem, design: ViscosityDesign) -> dict[str, np.ndarray]:
    """The ideal model's correction ``C`` of every run under each definition (arrays of
    shape (runs,)); ``tau_predicted = C m / k``.

    ``"crossing_63"``: :func:`~toolkit.predictions.theory.viscosity_correction` on the
    commanded contacts (exact travel times; equals the closed form
    :func:`~toolkit.predictions.theory.staircase_correction`). ``"least_squares"``:
    :func:`~toolkit.predictions.theory.least_squares_correction` of the run's ``n``, start and
    window (``design.window k / m``): a fit of the exact ideal trajectory, never of the run.
    """
    p, m = problem, problem.apparatus.mass
    out: dict[str, np.ndarray] = {}
    for d in p.definitions:
        if d == "crossing_63":
            out[d] = np.array([viscosity_correction(_commanded(p, k, v0, speeds), m, v0, k)
                               for k, v0, speeds in zip(design.slope, design.v0, design.commanded)])
        else:
            out[d] = np.asarray(least_squares_correction(p.apparatus.n, design.start,
                                                         design.window * design.slope / m), dtype=float)
    return out


@dataclass(frozen=True)
class ViscosityFit:
    """``1 / tau`` against ``k / m`` through the origin, for one definition and one group of starts.

    Attributes
    ----------
    definition : str
        One of :data:`~toolkit.predictions._measure.TIME_CONSTANTS`.
    starts : str
        ``"inside"`` or ``"outside"`` the spread (``START_GROUPS``).
    n : int
        Contacts.
    mode : str
        ``"ideal"`` or ``"loop"``.
    runs : int
        Runs fitted.
    k_fit, k_predicted : float
        The slope of ``1 / tau`` measured and of ``1 / tau_predicted`` against ``k / m``: the
        ``k`` of ``1 / tau = k (dF/dV) / m``.
    r2 : float
        ``R^2`` of the measured fit (centred, :func:`~toolkit.predictions._measure.proportional_fit`).
    r2_corrected : float
        ``R^2`` of ``1 / tau`` against ``1 / tau_predicted``: the scatter the per-run
        prediction explains.
    k_fit_true, r2_true : float
        The same fit on the true speed (equal to ``k_fit``, ``r2`` in the ideal mode).
    met : bool or None
        Both targets met; ``None`` for starts outside the spread (reported, not judged).
    """

    definition: str
    starts: str
    n: int
    mode: str
    runs: int
    k_fit: float
    k_predicted: float
    r2: float
    r2_corrected: float
    k_fit_true: float
    r2_true: float
    met: bool | None

    @property
    def ratio(self) -> float:
        """``k_fit / k_predicted``."""
        return self.k_fit / self.k_predicted

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: every attribute and ``ratio``."""
        return {"definition": self.definition, "starts": self.starts, "n": self.n, "mode": self.mode,
                "runs": self.runs, "k_fit": self.k_fit, "k_predicted": self.k_predicted, "ratio": self.ratio,
                "r2": self.r2, "r2_corrected": self.r2_corrected,
                "true_speed": {"k_fit": self.k_fit_true, "r2": self.r2_true}, "met": self.met}


def fit_viscosity(problem: ViscosityProblem, design: ViscosityDesign, tau: Mapping[str, np.ndarray],
                  tau_true: Mapping[str, np.ndarray], correction: Mapping[str, np.ndarray],
                  ok: np.ndarray) -> tuple[ViscosityFit, ...]:
    """One :class:`ViscosityFit` per definition and group of starts with at least two measured runs."""
    m = problem.apparatus.mass
    r2_min, rel_max = problem.targets
    fits = []
    for d in problem.definitions:
        for group in START_GROUPS:
            use = ok & (design.inside if group == "inside" else ~design.inside)
            if use.sum() < 2:
                continue
            x = design.slope[use] / m
            k_fit, r2 = proportional_fit(x, 1.0 / tau[d][use])
            predicted = 1.0 / (correction[d][use] * m / design.slope[use])
            k_pred = proportional_fit(x, predicted)[0]
            r2_corrected = proportional_fit(predicted, 1.0 / tau[d][use])[1]
            k_true, r2_true = proportional_fit(x, 1.0 / tau_true[d][use])
            met = (bool(r2 >= r2_min and abs(k_fit / k_pred - 1.0) <= rel_max) if group == "inside" else None)
            fits.append(ViscosityFit(d, group, problem.apparatus.n, problem.mode, int(use.sum()), k_fit, k_pred,
                                     r2, r2_corrected, k_true, r2_true, met))
    return tuple(fits)


@dataclass(frozen=True, eq=False)
class ViscosityCheck:
    """Result of :func:`viscosity_check`.

    Attributes
    ----------
    problem : ViscosityProblem
    design : ViscosityDesign
        The runs' draw and the ideal model's resting speeds and stop times.
    tau, tau_predicted, tau_true : dict of str to ndarray of shape (runs,), s
        By definition: the time constant read off the run (the estimate in the loop), the
        ideal model's ``C m / k``, and the one read off the true speed (equal to ``tau`` in
        the ideal mode; in the loop it separates the motor lag's share from the estimator's).
    correction : dict of str to ndarray of shape (runs,)
        ``C`` by definition.
    settled : ndarray of shape (runs,), m/s
        Settled speed read off the run.
    ok : ndarray of shape (runs,), bool
        The run finished and every definition measured it.
    fits : tuple of ViscosityFit
        Per definition and group of starts.
    status : CheckStatus
    message : str
    wall_time : float, s
    """

    problem: ViscosityProblem
    design: ViscosityDesign
    tau: dict
    tau_predicted: dict
    tau_true: dict
    correction: dict
    settled: np.ndarray
    ok: np.ndarray
    fits: tuple
    status: CheckStatus
    message: str
    wall_time: float

    # -- the design's arrays, by name ----------------------------------------------------
    @property
    def slope(self) -> np.ndarray:
        """Commanded viscosity of each run, N s/m."""
        return self.design.slope

    @property
    def v0(self) -> np.ndarray:
        """Start speed of each run, m/s."""
        return self.design.v0

    @property
    def start(self) -> np.ndarray:
        """``x0 = (V0 - c) / s`` of each run."""
        return self.design.start

    @property
    def inside(self) -> np.ndarray:
        """The run started inside the spread."""
        return self.design.inside

    @property
    def runs(self) -> int:
        """Number of runs."""
        return self.design.runs

    def fit(self, definition: str | None = None, starts: str = "inside") -> ViscosityFit | None:
        """The fit of one definition (default: the primary, ``problem.definitions[0]``) and
        group of starts, or ``None`` when fewer than two runs of that group were measured."""
        definition = self.problem.definitions[0] if definition is None else definition
        check_option(definition, "definition", "ViscosityCheck.fit", self.problem.definitions)
        check_option(starts, "starts", "ViscosityCheck.fit", START_GROUPS)
        return next((f for f in self.fits if f.definition == definition and f.starts == starts), None)

    def _primary(self, name: str) -> float:
        fit = self.fit()
        return getattr(fit, name) if fit is not None else math.nan

    @property
    def k_fit(self) -> float:
        """``k_fit`` of the primary definition, starts inside the spread."""
        return self._primary("k_fit")

    @property
    def k_predicted(self) -> float:
        """``k_predicted`` of the primary definition, starts inside the spread."""
        return self._primary("k_predicted")

    @property
    def r2(self) -> float:
        """``R^2`` of the primary definition, starts inside the spread."""
        return self._primary("r2")

    @property
    def ratio(self) -> float:
        """``k_fit / k_predicted`` of the primary definition, starts inside the spread."""
        return self.k_fit / self.k_predicted

    @property
    def met(self) -> bool:
        """Every target met."""
        return self.status is CheckStatus.MET

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (no per-run arrays): ``n``, ``mode``, ``runs``, ``runs_outside``
        (starts below the spread), ``fits`` (:meth:`ViscosityFit.to_dict`), ``status``,
        ``message``, ``wall_time``, and by definition ``correction_range`` and
        ``tau_ratio_range`` (``tau / tau_predicted``), ``targets``."""
        good = self.ok
        ranges: dict[str, Any] = {}
        corrections: dict[str, Any] = {}
        for d in self.problem.definitions:
            ratio = self.tau[d][good] / self.tau_predicted[d][good]
            ranges[d] = [float(ratio.min()), float(ratio.max())] if ratio.size else None
            c = self.correction[d][np.isfinite(self.correction[d])]
            corrections[d] = [float(c.min()), float(c.max())] if c.size else None
        return {"n": self.problem.apparatus.n, "mode": self.problem.mode, "runs": self.runs,
                "runs_outside": int(np.sum(~self.inside)), "fits": [f.to_dict() for f in self.fits],
                "status": self.status.name, "message": self.message, "wall_time": self.wall_time,
                "correction_range": corrections, "tau_ratio_range": ranges,
                "targets": {"r2_min": self.problem.targets[0], "k_rel_max": self.problem.targets[1]}}


def _verdict(problem: ViscosityProblem, fits: tuple[ViscosityFit, ...],
             failures: list[str]) -> tuple[CheckStatus, str]:
    if failures:
        return CheckStatus.FAILED, f"{len(failures)} of {problem.runs} runs failed ({failures[0]})"
    inside = [f for f in fits if f.starts == "inside"]
    if not inside:
        return CheckStatus.SHORT, "fewer than two runs started inside the spread: nothing to judge"
    r2_min, rel_max = problem.targets
    missed, said = [], []
    for f in inside:
        said.append(f"{f.definition}: R^2 {f.r2:.4f}, k_fit / k_predicted = {f.ratio:.4f}")
        if not f.r2 >= r2_min:
            missed.append(f"{f.definition}: R^2 {f.r2:.4f} < {r2_min:g}")
        if not abs(f.ratio - 1.0) <= rel_max:
            missed.append(f"{f.definition}: k_fit / k_predicted = {f.ratio:.4f}, off by "
                          f"{abs(f.ratio - 1.0):.1%} > {rel_max:.0%}")
    if missed:
        return CheckStatus.SHORT, "; ".join(missed)
    return CheckStatus.MET, "; ".join(said)


def viscosity_check(problem: ViscosityProblem | None = None, *, progress: bool = False,
                    workers: int | None = None) -> ViscosityCheck:
    """Run the viscosity sweep and compare each definition's time constants with the ideal model.

    Parameters
    ----------
    problem : ViscosityProblem, optional
        Default: ``ViscosityProblem()`` (the carousel, 490 runs, in the loop).
    progress : bool
        Show a progress bar (tqdm) on stderr.
    workers : int, optional
        Processes the in-loop runs are shared among (forked; ``>= 1``); default: the cores
        the load average leaves idle, at most one per ``RUNS_PER_PROCESS`` runs. The
        results do not depend on it; ideal runs always run in one batch kernel over the cores.

    Returns
    -------
    ViscosityCheck
    """
    if problem is None:
        problem = ViscosityProblem()
    if not isinstance(problem, ViscosityProblem):
        raise ParameterTypeError(parameter_message("problem", "viscosity_check", "be a ViscosityProblem", problem))
    if workers is not None:
        workers = as_int(workers, "workers", "viscosity_check", low=1)
    started = budget_clock()
    design, measured, correction, failures = _sweep(problem, progress, workers)
    m = problem.apparatus.mass
    tau_predicted = {d: correction[d] * m / design.slope for d in problem.definitions}
    ok = np.isfinite(measured["window"])
    # The prediction is fitted over the planned window: a record of another length is not comparable.
    period = 1.0 / problem.rate
    off = ok & ~(np.abs(measured["window"] - design.window) <= 1e-6 * period)
    for r in np.flatnonzero(off):
        failures.append(f"run {r}: recorded {measured['window'][r]:.6g} s after the switch, "
                        f"planned {design.window[r]:.6g} s")
    ok &= ~off
    for d in problem.definitions:
        good = np.isfinite(measured["tau"][d]) & (measured["tau"][d] > 0)
        for r in np.flatnonzero(ok & ~good):
            failures.append(f"run {r}: no startup to measure under {d} (tau = {measured['tau'][d][r]})")
        ok &= good
    fits = fit_viscosity(problem, design, measured["tau"], measured["tau_true"], correction,
                         ok & np.all([np.isfinite(measured["tau_true"][d]) for d in problem.definitions], axis=0))
    status, message = _verdict(problem, fits, failures)
    return ViscosityCheck(problem, design, measured["tau"], tau_predicted, measured["tau_true"], correction,
                          measured["settled"], ok, fits, status, message, budget_clock() - started)
