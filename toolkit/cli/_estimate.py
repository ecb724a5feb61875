"""The commands over encoder records: ``estimate`` (every estimator over a simulated or
recorded record) and ``live`` (the scene's control loop on a device).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from ._common import EXIT_INTERRUPTED, _finish, _out_dir, _parsed, _print_json, _scene


def _cmd_estimate(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from ..errors import SceneError
    from ..model.record_io import read_record_csv, record_csv_text
    from ..scenes._io import atomic_write_text, check_output_file, claim_output_dir, write_tree
    from ..scenes.build import build_scene, check_record_outputs
    from ..scenes.report import estimation_files, estimation_lines, estimation_to_dict, shortfall_dicts
    from ..scenes.spec import EstimationSpec
    from ..scenes.study import estimate_record, estimate_scene, estimation_shortfalls

    scene = _parsed(args)
    if args.record is not None and args.save_record is not None:
        raise SceneError("--save-record writes the simulated record; with --record there is none to write "
                         "(give one of the two).")
    save = None if args.save_record is None else check_output_file(args.save_record)
    if scene.estimation is None:      # the scene's own run, recorded: never another scenario
        if scene.sensors is None:
            raise SceneError(f"The scene {scene.name!r} has no [sensors] section (the encoders to "
                             "estimate from).")
        if args.record is not None:   # a recorded file: the section's estimators and priors
            scene = replace(scene, estimation=EstimationSpec())
        elif scene.simulation is None:
            raise SceneError(f"The scene {scene.name!r} has no [estimation] section and no [simulation] "
                             "run to record: add [estimation] (scenario = \"brake\", the startup-then-brake "
                             "record on the scene's wheel forces, as in the shipped 'estimate' design).")
        else:
            scene = replace(scene, estimation=EstimationSpec(scenario="simulation"))
    objects = build_scene(scene)
    record = None if args.record is None else read_record_csv(
        args.record, sensors=objects.estimation.sensors, motors=objects.estimation.plant.motors,
        progress=sys.stderr.isatty())
    if record is not None:
        check_record_outputs(record.n_samples, objects.estimation, args.record)
    with claim_output_dir(_out_dir(args, scene)) as out:
        study = estimate_scene(objects) if record is None else estimate_record(objects, record)
        shortfalls = estimation_shortfalls(objects, study)
        plots_too = scene.report is None or scene.report.plots
        written = write_tree(out, estimation_files(study, scene.name, plots_too=plots_too))
        if save is not None:
            written.append(atomic_write_text(save, record_csv_text(study.record)))
    if args.json:
        data = estimation_to_dict(study)
        data.pop("series")
        _print_json({"scene": scene.name, **data, "shortfalls": shortfall_dicts(shortfalls),
                     "written": [str(p) for p in written]})
    else:
        for line in estimation_lines(study):
            print(line)
        print(f"wrote {', '.join(str(p) for p in written)}")
    return _finish(shortfalls)


def _cmd_live(args: argparse.Namespace) -> int:
    from ..live import run_live
    from ..live.report import live_files, live_lines, live_to_dict
    from ..live.runner import LiveStatus
    from ..live.scene import scene_device, scene_loop, warm_loop
    from ..scenes._io import claim_output_dir, write_tree
    from ..shortfall import Shortfall

    objects = _scene(args, "control", "to run live")
    loop = scene_loop(objects, args.duration)
    device = scene_device(objects, args.device, loop.duration)
    scene = objects.scene

    def status(s: dict[str, float]) -> None:
        sys.stderr.write(f"\rt {s['t']:8.2f} s  V^ {s['estimate']:+.5f} +- {s['sigma']:.5f} m/s  u {s['command']:+.4f} "
                         f"m/s  p99 {s['p99_ms']:.2f} ms  missed {s['missed']}  ")
        sys.stderr.flush()

    with claim_output_dir(_out_dir(args, scene)) as out:
        warm_loop(loop)
        def started(hello: Any) -> None:
            if not args.json:
                print(f"live on {args.device}: {hello.wheels} wheels at {hello.rate:g} Hz; Ctrl-C stops "
                      "(zero commands sent)", flush=True)

        result = run_live(loop, device, status=status if sys.stderr.isatty() else None, started=started)
        if sys.stderr.isatty():
            sys.stderr.write("\n")
        truth, report = getattr(device, "truth", None), getattr(device, "report", None)
        plots_too = scene.report is None or scene.report.plots
        written = write_tree(out, live_files(result, truth, report, name=scene.name, plots_too=plots_too))
    if args.json:
        _print_json({"scene": scene.name, **live_to_dict(result, truth, report), "written": [str(p) for p in written]})
    else:
        for line in live_lines(result, truth):
            print(line)
        print(f"wrote {', '.join(str(p) for p in written)}")
    if result.status is LiveStatus.INTERRUPTED:
        print(f"active-contacts: {result.message}", file=sys.stderr)
        return EXIT_INTERRUPTED
    reached = float(result.record.times[-1]) if result.record is not None else 0.0
    return _finish([] if result.status is LiveStatus.COMPLETED else
                   [Shortfall("live", result.message, loop.duration - reached, "s")])
