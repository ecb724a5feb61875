"""Run the stages a scene declares (numerics only: no files, no plots, no building).

:func:`run_study` computes the force-speed curve and each declared stage (encoders, allocation,
simulation, schedule, estimation, closed loop) on the objects
:func:`~toolkit.scenes.build.build_scene` makes once per run; a stage not declared is not run
and the packages only it needs are not imported. With a target and a simulation, the
simulation runs on the allocated speeds; a schedule is designed, then simulated exactly. Each
way a finished study misses its request is a :class:`Shortfall` (listed on :func:`run_study`);
those known before any work are ``request_shortfalls``, refused with ``strict=True``.
The stages live in :mod:`~toolkit.scenes.stages` (curve, allocation, schedule, simulation),
:mod:`~toolkit.scenes.estimate` and :mod:`~toolkit.scenes.control`; this module runs them,
and runs the one stage of a planar or a sweep scene. Every name they export is also here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .._compiled import compile_seconds, warm
from ..allocation import AllocationResult
from ..errors import SceneError
from ..model import ContactSet, Plant
from .build import SceneObjects
from .spec import ReportSpec, Scene
from ..schedule import ScheduleResult
from ..shortfall import Shortfall
from ..simulation import SimulationResult
from .control import ControlStudy, control_scene, control_shortfalls, control_world
from .estimate import EstimationStudy, estimate_record, estimate_scene, estimation_shortfalls
from .stages import (CurveSamples, CurveStep, _built, _simulation, allocate_scene, allocation_shortfalls,
                     design_scene_schedule, force_curve, request_shortfalls, schedule_shortfalls,
                     simulation_shortfalls)

__all__ = ["CurveSamples", "CurveStep", "Shortfall", "StudyResult", "force_curve", "run_study",
           "allocate_scene", "design_scene_schedule", "request_shortfalls", "allocation_shortfalls",
           "schedule_shortfalls", "simulation_shortfalls", "EstimationStudy", "ControlStudy",
           "estimate_scene", "estimate_record", "control_scene", "control_world", "estimation_shortfalls",
           "control_shortfalls", "sweep_scene", "sweep_shortfalls", "planar_scene",
           "planar_precision", "check_sweep_table"]


@dataclass(frozen=True)
class StudyResult:
    """What :func:`run_study` computed; ``None`` for stages the scene does not declare.

    ``contacts`` are those the study ran on (the allocated ones when the scene has a
    ``[target]``) and ``plant`` the scene's plant on them (None without ``[body]``).
    """

    scene: Scene
    contacts: ContactSet
    curve: CurveSamples
    sensors: dict[str, dict[str, float]] | None = None
    allocation: AllocationResult | None = None
    schedule: ScheduleResult | None = None
    schedule_check: SimulationResult | None = None
    simulation: SimulationResult | None = None
    shortfalls: tuple[Shortfall, ...] = ()
    estimation: EstimationStudy | None = None
    control: ControlStudy | None = None
    plant: Plant | None = None
    #: Seconds spent compiling kernels during the study (numba's compile events: 0 when every
    #: kernel came from the cache); in no ``wall_time`` of the result.
    compile_time: float = 0.0

    @property
    def stages(self) -> tuple[str, ...]:
        """The stages that ran."""
        return self.scene.stages

    @property
    def met(self) -> bool:
        """True when the study met every request (no shortfall)."""
        return not self.shortfalls
def run_study(scene: Scene | SceneObjects, *, strict: bool = False) -> StudyResult:
    """Build the scene's objects once and run every stage it declares.

    Parameters
    ----------
    scene : Scene or SceneObjects
        From :func:`toolkit.load_scene` (built here), or already built.
    strict : bool
        Refuse, before any work, a request that is known to fall short
        (``request_shortfalls``) instead of running it and reporting the shortfall.

    Returns
    -------
    StudyResult
        With ``StudyResult.shortfalls``: every way the result misses the request, one
        :class:`Shortfall` kind per way of missing:

        =============  =====================================================================  ======
        stage          what                                                                   unit
        =============  =====================================================================  ======
        scene          speeds beyond the motor limits clipped (``[motors] clip = true``)      m/s
        allocation     a target that is not realizable, projected (distance to it)            N
        allocation     a target the contacts cannot reach (best achievable error)             N
        allocation     no allocation (infeasible, time limit, solver error)                   N
        schedule       a target beyond the speed limits (best achievable error)               m/s
        schedule       an unverified schedule (exact run left the prediction bound)           m/s
        schedule       a braking target not reached (final distance to it)                    m/s
        simulation     a run stopped before ``t_end`` (budget, Zeno, failure; time left)      s
        estimation     the recorded run stopped before its end (time not recorded)            s
        control        the closed loop stopped before ``duration`` (budget; time left)        s
        control        python-control's simulation of the loop differs from the toolkit's     m/s
        =============  =====================================================================  ======

    Raises
    ------
    SceneError
        ``strict=True`` and the request falls short before any work.
    """
    compiled_before = compile_seconds()
    objects = _built(scene)
    scene = objects.scene
    if scene.sweep is not None:
        from .build import sweep_scene_error

        raise sweep_scene_error(scene, "run_study")
    if scene.planar is not None:
        from .build import planar_scene_error

        raise planar_scene_error(scene, "run_study")
    known = request_shortfalls(objects)
    if strict and known:
        raise SceneError(f"--strict: {known[0]}" + (f" (and {len(known) - 1} more)" if len(known) > 1 else ""))
    contacts = objects.contacts
    found = [s for s in known if s.stage == "scene"]
    points = (scene.report or ReportSpec()).curve_points
    sensors = ({name: encoder.summary() for name, encoder in objects.encoders.items()}
               if scene.sensors is not None else None)
    allocation = None
    if scene.target is not None:
        allocation = allocate_scene(objects, contacts)
        found += allocation_shortfalls(objects, allocation, contacts)
        contacts = allocation.contacts
    schedule = check = None
    if scene.schedule is not None:
        schedule, check = design_scene_schedule(objects, contacts)
        found += schedule_shortfalls(objects, schedule, check)
    simulation = None
    if scene.simulation is not None:
        if scene.simulation.method == "exact":       # its wall time: of compiled kernels
            warm(lambda: _simulation(objects, contacts, 1e-3), "core")
        simulation = _simulation(objects, contacts)
        found += simulation_shortfalls(scene, simulation)
    estimation = None
    if scene.estimation is not None:
        estimation = estimate_scene(objects, simulation)
        found += estimation_shortfalls(objects, estimation)
    loop = None
    if scene.control is not None:
        loop = control_scene(objects, schedule)
        found += control_shortfalls(objects, loop)
    plant = objects.plant_on(contacts) if objects.plant is not None else None
    return StudyResult(scene, contacts, force_curve(contacts, points), sensors, allocation,
                       schedule, check, simulation, tuple(found), estimation, loop, plant,
                       compile_seconds() - compiled_before)


# -- planar scenes ----------------------------------------------------------------------------------

def planar_scene(scene: Scene | SceneObjects) -> Any:
    """Run a planar scene's ``[planar]`` (:func:`toolkit.planar.scene.run_planar`): the
    simulation, the terminal ratio of a disc or ring, the equilibrium of legs, the optional
    work-precision rows. Returns a :class:`toolkit.planar.scene.PlanarStudyResult`.

    Raises
    ------
    SceneError
        The scene has no ``[planar]``.
    """
    from ..planar.scene import run_planar   # the planar package loads with a planar scene only

    return run_planar(_planar(scene))


def planar_precision(scene: Scene | SceneObjects) -> Any:
    """A planar scene's work-precision report (:func:`toolkit.planar.scene.scene_precision`:
    its ``[planar.precision]`` settings or the defaults), what ``active-contacts precision``
    runs on a planar scene. Returns a :class:`toolkit.planar.PlanarPrecisionReport`.

    Raises
    ------
    SceneError
        The scene has no ``[planar]``.
    """
    from ..planar.scene import scene_precision

    return scene_precision(_planar(scene))


def _planar(scene: Scene | SceneObjects) -> Any:
    objects = _built(scene)
    if objects.planar is None:
        raise SceneError(f"The scene {objects.scene.name!r} has no [planar] section to run.")
    return objects.planar


# -- sweeps -------------------------------------------------------------------------------------

def sweep_scene(scene: Scene | SceneObjects, *, runs: int | None = None, seed: int | None = None,
                scheduler: Any = None, workers: int | None = None, progress: bool = False) -> Any:
    """Run a sweep scene's ``[sweep]`` (:func:`toolkit.sweep`); ``runs`` and ``seed`` override
    the scene's.

    Returns
    -------
    SweepResult

    Raises
    ------
    SceneError
        The scene has no ``[sweep]``.
    """
    from ..sweeps import sweep   # pandas comes with the first sweep

    objects = _built(scene)
    spec = objects.scene.sweep
    if spec is None:
        raise SceneError(f"The scene {objects.scene.name!r} has no [sweep] section to run.")
    return sweep(objects.sweep, spec.runs if runs is None else runs,
                 seed=spec.seed if seed is None else seed, scheduler=scheduler, workers=workers,
                 chunk_size=spec.chunk_size, progress=progress)


#: Runs of the probe that measures a sweep table's bytes per run (:func:`check_sweep_table`).
TABLE_PROBE_RUNS = 16


def check_sweep_table(scene: Scene | SceneObjects, *, runs: int | None = None,
                      seed: int | None = None) -> int:
    """Refuse, before the sweep, a ``results.csv`` larger than
    :data:`~toolkit.scenes.limits.MAX_TABLE_BYTES`: its size is estimated from the bytes per
    run of the first :data:`TABLE_PROBE_RUNS` runs (the table's own CSV form; the run index
    counted at its full width). Returns the estimate (bytes).

    Raises
    ------
    SceneError
        The estimate exceeds the limit (the message gives the most runs that fit).
    """
    from ..sweeps import sweep
    from .limits import MAX_TABLE_BYTES

    objects = _built(scene)
    spec = objects.scene.sweep
    if spec is None:
        raise SceneError(f"The scene {objects.scene.name!r} has no [sweep] section to run.")
    total = spec.runs if runs is None else runs
    probe = min(total, TABLE_PROBE_RUNS)
    table = sweep(objects.sweep, probe, seed=spec.seed if seed is None else seed,
                  chunk_size=spec.chunk_size).table
    text = table.to_csv(index=False, float_format="%.17g")
    header = len(text.split("\n", 1)[0]) + 1
    per_run = (len(text) - header) / probe + len(str(total)) - len(str(probe))
    size = int(header + per_run * total)
    if size > MAX_TABLE_BYTES:
        fit = int((MAX_TABLE_BYTES - header) // per_run)
        raise SceneError(
            f"The sweep of {objects.scene.name!r} with {total} runs would write a results.csv of about "
            f"{size / 2**20:.0f} MiB ({per_run:.0f} bytes per run, measured on its first {probe} runs); "
            f"tables are limited to {MAX_TABLE_BYTES >> 20} MiB. Run at most about {fit} runs, or leave "
            "out --out for the summary alone.")
    return size


def sweep_shortfalls(result: Any) -> list[Shortfall]:
    """Runs that had not settled by the end of their observation time (median law, mean
    against median): their speeds are not steady speeds (the count of such runs)."""
    table = result.table
    if "settled" not in table:
        return []
    unsettled = int((~table["settled"]).sum())
    if not unsettled:
        return []
    return [Shortfall("sweep", f"{unsettled} of {result.runs} runs had not settled when observed "
                      "(their speeds are not steady)", float(unsettled), "runs")]
