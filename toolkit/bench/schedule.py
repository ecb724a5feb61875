"""Schedule design timings on the shipped scenes: constructive design against ipopt refinement.

``python -m toolkit.bench schedule [--quick]`` designs the ``[schedule]`` of
``designs/brake_schedule.toml`` and ``designs/carousel.toml`` twice, measured in the same run:

- ``constructive`` (``design_schedule(..., refine=False)``, the default: construction,
  proven prediction bound, exact simulation and lower bound, everything included);
- baseline, ``refine=True``: the same plus ipopt's multiple-shooting refinement warm-started
  at the constructive schedule (``max_iter`` 30; ``--quick``: 10).

Each line gives the wall time, status, exact sup tracking error, objective and ipopt's return
status of both (the refined schedule is kept only when it verifies and lowers the objective),
and the ratio baseline / constructive.
"""

from __future__ import annotations

import time

from ..scenes.designs import load_design
from ..schedule import design_schedule
from ..simulation import warm_up
from ..scenes.build import build_scene

SCENES = ("brake_schedule", "carousel")


def main(argv: list[str]) -> int:
    quick = "--quick" in argv
    iterations = 10 if quick else 30
    print(f"kernels compiled or loaded from the cache in {warm_up():.2f} s (not timed)")
    print(f"{'scene':>15} {'method':>22} {'wall [s]':>9} {'status':>9} {'sup error':>10}"
          f" {'objective':>10}  ipopt")
    for name in SCENES:
        scene = load_design(name)
        spec = scene.schedule
        objects = build_scene(scene)
        plant, target = objects.plant, objects.schedule_target
        walls = {}
        for refine in (False, True):
            started = time.perf_counter()
            result = design_schedule(plant, target, v0=spec.v0, horizon=spec.horizon,
                                     period=spec.period, epsilon=spec.epsilon,
                                     time_limit=spec.time_limit, refine=refine,
                                     max_iter=iterations)
            walls[refine] = time.perf_counter() - started
            print(f"{name:>15} {result.method:>22} {walls[refine]:9.3f} "
                  f"{result.status.name:>9} {result.exact_tracking_error:10.4g} "
                  f"{result.objective:10.4g}  {result.solver_status}")
        print(f"{name:>15} {'refined / constructive':>22} {walls[True] / walls[False]:9.1f}x")
    return 0
