"""Work-precision benchmark: the exact method against every reference method, one run.

Run ``python -m toolkit.bench precision [--seed S] [--repeats R] [--quick]``. On the carousel
startup scene (11 random speeds in [-0.35, 0.35] m/s, F_tot/m = 2 m/s^2, from rest, 5 s) it
prints the work-precision table and the ratio of the run time of the fastest reference method
that reaches max |V error| <= 1e-6 m/s to the run time of the exact method, both measured in
this run. Every method, the exact one included, is asked for the same output times (the
exact event times and 1001 uniform times) and timed on those calls
(:func:`toolkit.analysis.precision.precision_report`). The exact method's compiled kernels are loaded
(or compiled) first, outside the timings, and that time is printed. Exit status 0 when the
criterion holds (exact error <= 1e-12 and ratio >= 200).
"""

from __future__ import annotations

import argparse
import os
import time

from toolkit.simulation import warm_up
from toolkit.model.carousel import carousel_startup_plant
from toolkit.analysis.precision import default_settings, exact_speedup, precision_report


TARGET = 200.0          # reference / exact


def _format(value: float) -> str:
    return f"{value:9.2e}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench precision", description=__doc__)
    parser.add_argument("--seed", type=int, default=0, help="seed of the random contact speeds")
    parser.add_argument("--repeats", type=int, default=5, help="timing repeats (minimum reported)")
    parser.add_argument("--t-end", type=float, default=5.0, help="horizon, s")
    parser.add_argument("--quick", action="store_true", help="a few settings only")
    args = parser.parse_args(argv)

    print(f"exact kernels compiled or loaded from the cache in {warm_up():.2f} s (not timed)")
    plant = carousel_startup_plant(args.seed)
    start = time.perf_counter()
    report = precision_report(plant, args.t_end, repeats=args.repeats,
                              settings=default_settings(quick=args.quick))
    total = time.perf_counter() - start
    print(f"{'method':7s} {'setting':46s} {'max err':>9s} {'final err':>9s} {'time ms':>9s} "
          f"{'steps':>8s} {'status':10s} flags")
    for row in report.rows:
        flags = [name for name in ("chattering", "step_collapse", "creep", "stalled")
                 if getattr(row, name)]
        print(f"{row.method:7s} {row.setting:46s} {_format(row.max_error)} "
              f"{_format(row.final_error)} {row.wall_time * 1e3:9.3f} {row.n_steps:8d} "
              f"{row.status.name:10s} {','.join(flags)}")
    speedup = exact_speedup(report, 1e-6)
    exact = speedup.exact
    print(f"report: {len(report.rows)} rows in {total:.1f} s")
    print(f"exact: max error {exact.max_error:.2e} m/s (rational-arithmetic reference), "
          f"{exact.wall_time * 1e6:.1f} us per run")
    if speedup.reference is None:
        print("no reference method reached max error <= 1e-6 m/s")
        return 1
    print(f"fastest reference with max error <= 1e-6 m/s: {speedup.reference.label} "
          f"({speedup.reference.wall_time * 1e3:.2f} ms, error {speedup.reference.max_error:.1e})")
    print(f"ratio reference / exact: {speedup.ratio:.1f}x (target 200x; load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores)")
    return 0 if exact.max_error <= 1e-12 and speedup.ratio >= TARGET else 1
