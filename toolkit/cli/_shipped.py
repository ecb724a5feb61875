"""The commands over what ships with the toolkit: ``designs`` (list or copy the shipped
scenes), ``warm`` (compile their kernels), ``stability`` (the stiff-case suite) and
``predict`` (the paper's predictions checked in the loop).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import multiprocessing
import sys
from pathlib import Path

from ._common import EXIT_FAILED, EXIT_OK, _finish, _print_json, _scene
from ._stages import _cmd_run


def _cmd_designs(args: argparse.Namespace) -> int:
    from ..scenes.designs import copy_designs, design_names, design_text

    if args.copy is not None:
        written = copy_designs(args.copy)
        if args.json:
            _print_json({"written": [str(p) for p in written]})
        else:
            print(f"wrote {len(written)} designs into {args.copy}")
        return EXIT_OK
    names = design_names()
    if args.json:
        _print_json({"designs": list(names)})
    else:
        import tomllib

        for name in names:
            about = tomllib.loads(design_text(name)).get("scene", {}).get("description", "")
            print(f"{name:20} {about}")
        print("copy them for editing: active-contacts designs --copy DIR")
    return EXIT_OK


def _cmd_warm(args: argparse.Namespace) -> int:
    """Compile and cache every kernel the shipped designs use: with ``--processes 2`` (the
    default where this process may run on two cores or more and fork) the kernels' warm-ups
    in parallel processes (:func:`toolkit._warmups.warm_groups`), then every shipped design
    run once, outputs discarded (whatever the warm-ups left). After this, every design's
    first run starts warm."""
    import io
    import tempfile
    import time

    from tqdm import tqdm

    from .. import _compiled
    from .._forked import allowed_cores
    from .._warmups import warm_groups
    from ..scenes.designs import design_names, design_text

    names = design_names()
    started = time.perf_counter()
    processes = args.processes
    if processes is None:
        processes = 2 if allowed_cores() >= 2 and "fork" in multiprocessing.get_all_start_methods() else 1
    print(f"active-contacts: warm: compiling the kernels of every shipped design in {processes} "
          f"process{'es' if processes > 1 else ''} (loaded from the cache where it has them)",
          file=sys.stderr, flush=True)
    quiet = _compiled.on_compile(None)          # (this command says what it compiles, once)
    try:
        compiled_before = -sum(compiling for _, compiling in warm_groups()) if processes > 1 else 0.0
        compiled_before += _compiled.compile_seconds()
        with tempfile.TemporaryDirectory(prefix="active-contacts-warm-") as folder:
            for name in tqdm(names, desc="warming", unit=" designs", file=sys.stderr, leave=False,
                             disable=args.json or not sys.stderr.isatty()):
                scene = Path(folder) / f"{name}.toml"
                scene.write_text(design_text(name), encoding="utf-8")
                run = argparse.Namespace(command="run", scene=str(scene), out=str(Path(folder) / "out" / name),
                                         json=False, strict=False)
                with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                    _cmd_run(run)            # (a design's own shortfalls do not matter here)
    finally:
        _compiled.on_compile(quiet)
    compile_time = _compiled.compile_seconds() - compiled_before
    wall = time.perf_counter() - started
    if args.json:
        _print_json({"designs": list(names), "compile_time": compile_time, "wall_time": wall})
    else:
        print(f"{len(names)} shipped designs run once in {wall:.1f} s ({compile_time:.1f} s compiling kernels, "
              "summed over the processes): they are cached, and every design's first run starts warm")
    return EXIT_OK


def _cmd_stability(args: argparse.Namespace) -> int:
    from ..analysis.stability import case_label, stability_suite
    from ..shortfall import Shortfall
    report = stability_suite(quick=args.quick)
    if args.json:
        _print_json(report.to_dict())
    else:
        print(f"{'case':34} {'method':8} {'finished':>8} {'finite':>6} {'events':>8} {'wall_time':>10}  ok")
        for case in report.cases:
            verdict = case.ok if case.judged else "unjudged (wall-clock guard)"
            print(f"{case.name:34} {case.method:8} {case.finished!s:>8} {case.finite!s:>6} "
                  f"{case.events:8d} {case.wall_time:10.2e}  {verdict}")
        print("all cases ok" if report.all_ok else "SOME CASES FAILED" if report.failed
              else "SOME CASES UNJUDGED")
    if report.failed:
        print("active-contacts: stability: failed: "
              + "; ".join(f"{case_label(c)}: {c.message}" for c in report.failed), file=sys.stderr)
        return EXIT_FAILED
    return _finish([Shortfall("stability", f"unjudged: the wall-clock guard stopped {case_label(c)} "
                              f"({c.message})", math.nan, "") for c in report.unjudged])


# -- predict: the paper's viscosity and friction-fraction predictions checked in the loop ----
def _cmd_predict(args: argparse.Namespace) -> int:
    from ..scenes.report import compile_line
    from ..shortfall import Shortfall
    from ..predictions import Apparatus, prediction_checks

    if args.scene is None:
        apparatus = Apparatus.carousel()
    else:
        apparatus = _scene(args).apparatus()
    if args.contacts is not None:
        apparatus = apparatus.with_contacts(args.contacts)
    progress = not args.json and sys.stderr.isatty()
    result = prediction_checks(apparatus, runs=args.runs, seed=args.seed, progress=progress)
    if args.json:
        _print_json(result.to_dict())
    else:
        for label, check in result.checks():
            if hasattr(check, "fits"):
                print(f"{label}: {check.runs} runs on {apparatus.n} contacts, 1/tau = k dF/dV / m, "
                      f"{check.wall_time:.1f} s: {check.status.name}")
                for fit in check.fits:
                    print(f"  {fit.definition} ({fit.runs} starts {fit.starts} the spread): k_fit "
                          f"{fit.k_fit:.4f}, k_predicted {fit.k_predicted:.4f} (ratio {fit.ratio:.4f}), "
                          f"R^2 {fit.r2:.4f}")
            else:
                print(f"{label}: {check.status.name} ({check.wall_time:.1f} s)")
                for row in check.rows():
                    print(f"  n = {row['n']}: mu/mu0 {row['mu_ratio']:.4f} (predicted "
                          f"{row['mu_predicted']:.4g}), dT {_seconds(row['dT'])} (predicted "
                          f"{_seconds(row['dT_predicted'])})")
        if apparatus.sensors is None:
            print("the scene has no [sensors]: only the ideal checks ran")
        if apparatus.n % 2:
            print(f"friction fraction: left out ({apparatus.n} contacts; the split needs an even number)")
        print(compile_line(result.compile_time))
    return _finish([Shortfall("prediction", line, math.nan, "") for line in result.shortfalls()])


def _seconds(value: float | None) -> str:
    """A time for the predict summary: ``inf`` for None (no transition)."""
    return "inf" if value is None else f"{value:.4g} s"
