"""The estimation stage of a study: every estimator of ``[estimation]`` over one encoder
record, simulated from the scene or read from a file, and its shortfalls.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._compiled import warm
from ..errors import SceneError
from .build import SceneObjects
from .spec import Scene
from ..analysis.scenarios import grid_positions, record_world
from ..model.truth import realize
from ..shortfall import Shortfall
from ..simulation import SimulationResult, SimulationStatus
from .stages import _built, _simulation, _spec


@dataclass(frozen=True, eq=False)
class EstimationStudy:
    """Every estimator of ``[estimation]`` over one simulated encoder record.

    Attributes
    ----------
    record : EncoderRecord
        The counts, commands and, when simulated, the truth (body speed and position,
        contact speeds).
    results : tuple of EstimationResult
        One per method, in the scene's order, scored against the truth when there is one.
    simulation : SimulationResult or None
        The exact run that was recorded (None for a recorded file).
    plant : Plant or None
        The plant simulated: the true world's (None for a recorded file).
    compile_time : float, s
        The one-time cost paid before the estimators were timed (the kernels compiled and
        each estimator run once over the record, untimed: the policy of
        :mod:`toolkit._compiled`); in no estimator's ``wall_time``.
    monitors : tuple of (str or None)
        Per result, the consistency monitor's verdict (``"consistent"``, or when and why the
        estimator left its nominal model); None for estimators without a monitor.
    """

    record: Any
    results: tuple[Any, ...]
    simulation: SimulationResult | None
    plant: Any
    compile_time: float = 0.0
    monitors: tuple[str | None, ...] = ()

    @property
    def duration(self) -> float:
        """The record's length, s."""
        return self.record.duration

    def rows(self) -> list[dict[str, Any]]:
        """Per estimator: ``name``, ``rms``, ``max_error`` (m/s), ``rms_phases`` (m/s per
        phase: startup, cruise, brake, braked), ``nees_mean`` (None without a covariance or
        the truth), its 95 % ``nees_band``, ``nees_in_band`` (the share of samples whose NEES
        lies in the 95 % chi-square(2) interval), ``nees_over_100`` (the share above 100:
        gross overconfidence) and ``nees_max``, ``nis_mean``, ``monitor`` (the consistency
        monitor's verdict), ``missed_count_prob`` and ``missed_count_std`` (the encoders'
        missed-count rate the position was reported under, told or identified; None where an
        estimator does not use it), ``wall_time`` (s) and ``real_time_ratio``."""
        monitors = self.monitors or (None,) * len(self.results)
        return [{"name": r.method, "rms": r.rms_error, "max_error": r.max_error,
                 "rms_phases": None if r.rms_phases is None else dict(r.rms_phases),
                 "nees_mean": r.nees_mean, "nees_band": r.nees_band, "nees_in_band": r.nees_in_band,
                 "nees_over_100": r.nees_over_100, "nees_max": r.nees_max,
                 "nis_mean": r.nis_mean, "monitor": monitor, "missed_count_prob": r.missed_count_prob,
                 "missed_count_std": r.missed_count_std, "wall_time": r.wall_time,
                 "real_time_ratio": r.real_time_ratio} for r, monitor in zip(self.results, monitors)]


def estimate_scene(scene: Scene | SceneObjects, simulation: SimulationResult | None = None
                   ) -> EstimationStudy:
    """Simulate, record and estimate as the scene's ``[estimation]`` declares.

    Parameters
    ----------
    scene : Scene or SceneObjects
        Needs ``[estimation]`` (and so ``[sensors]`` and ``[body]``).
    simulation : SimulationResult, optional
        For ``scenario = "simulation"``: the scene's ``[simulation]`` run when already
        computed (the study passes its own); otherwise it is run here.

    Returns
    -------
    EstimationStudy
        One result per method and, when the scene has ``[estimation.truth]``, last, the
        default told that true world (:func:`~toolkit.estimation.truth_told`, named
        ``truth_told``: the reference of what is achievable).

    Notes
    -----
    The encoders' count grids start where ``[estimation] seed`` puts them
    (:func:`~toolkit.analysis.scenarios.grid_positions`): each seed is another phase of the
    quantization, so a nominal scene too gives other records for other seeds.
    """
    from ..estimation import truth_told
    from ..model.sensors import record_simulation

    built = _built(scene)
    spec, objects = built.scene.estimation, built.estimation
    if spec is None or objects is None:
        raise SceneError(f"The scene {built.scene.name!r} has no [estimation] section.")
    plant, told = objects.plant, None
    grid = grid_positions(objects.sensors, spec.seed)     # the seed's phase of the count grids
    if spec.scenario == "simulation" and objects.truth.is_nominal:      # the scene's own run
        run = simulation if simulation is not None else _simulation(built, built.contacts)
        record = record_simulation(run, plant, objects.sensors, rng=np.random.default_rng(spec.seed), **grid)
    else:     # the true world ([estimation.truth]; the scene itself when it says nothing)
        world = realize(plant, objects.sensors, objects.truth, spec.seed)
        run, record = record_world(world, objects.duration, seed=spec.seed, v0=objects.v0, **grid)
        plant = world.plant
        if spec.truth is not None:        # the default told this world: the reference
            told = truth_told(world, initial_covariance=None if spec.initial_covariance is None
                              else np.array(spec.initial_covariance))
    return _run_estimators(objects, spec, record, run, plant, told)


def estimate_record(scene: Scene | SceneObjects, record: Any) -> EstimationStudy:
    """Run the scene's ``[estimation]`` estimators over a recorded file's ``record`` (no truth:
    estimates, NIS and the monitor's verdict; no simulation).

    Parameters
    ----------
    scene : Scene or SceneObjects
        Needs ``[estimation]`` (the estimators, the model and the prior).
    record : EncoderRecord
        From :func:`toolkit.model.record_io.read_record_csv`; its channels must match the
        scene's contacts.
    """
    built = _built(scene)
    spec, objects = built.scene.estimation, built.estimation
    if spec is None or objects is None:
        raise SceneError(f"The scene {built.scene.name!r} has no [estimation] section.")
    if record.wheel_counts.shape[1] != built.contacts.n:
        raise SceneError(f"The record has {record.wheel_counts.shape[1]} wheel channels; the scene "
                         f"{built.scene.name!r} has {built.contacts.n} contacts.")
    return _run_estimators(objects, spec, record, None, None)


def _run_estimators(objects: Any, spec: Any, record: Any, run: SimulationResult | None,
                    plant: Any, told: Any = None) -> EstimationStudy:
    """Every estimator over ``record``, each timed on compiled code (warmed first, untimed),
    then ``told`` (the default told the true world) when there is one."""
    compile_time = warm(None, "core", "lines")     # every wall time below: compiled code
    results, monitors = [], []
    for estimator in [*objects.estimators.values(), *([] if told is None else [told])]:
        compile_time += warm(lambda: estimator.warm_up(record))
        results.append(estimator.run(record, speed=objects.v0, speed_std=spec.speed_std))
        monitors.append(_verdict(estimator))
    return EstimationStudy(record, tuple(results), run, plant, compile_time, tuple(monitors))


def _verdict(estimator: Any) -> str | None:
    """What an estimator's consistency monitor concluded over its last run (None: no monitor)."""
    if not hasattr(estimator, "tripped"):
        return None
    if estimator.tripped is None:
        return "consistent: the nominal model held throughout"
    time_, reason = estimator.tripped
    return f"left the nominal model at t = {time_:.3f} s ({reason})"


def estimation_shortfalls(scene: Scene | SceneObjects, study: EstimationStudy) -> list[Shortfall]:
    """A recorded run that stopped before its end (the time not recorded, s)."""
    run = study.simulation
    if run is None or run.status is SimulationStatus.SUCCESS:        # a recorded file, or a full run
        return []
    spec = _spec(scene)
    duration = spec.estimation.record_duration if spec.estimation.scenario == "brake" else spec.simulation.t_end
    reached = float(run.t_final)
    return [Shortfall("estimation", f"the recorded simulation {run.status.value} at t = {reached:.6g} s "
                      f"of {duration:g} s ({duration - reached:.6g} s not recorded)", duration - reached, "s")]
