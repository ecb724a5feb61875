"""Benchmark of the planar equilibrium: the fast solver against cvxpy (Clarabel), same run.

Run ``python -m toolkit.bench planar``. For random weighted point sets (the translation-only
equilibrium: the weighted geometric median of contact velocities) and random leg sets (the
full twist), it times ``method="newton"`` (Newton's method, exact polish, certificate) and
``method="cvxpy"`` (the second-order cone program, Clarabel at tight tolerances, certified the
same way), each called from scratch through :func:`toolkit.planar.geometric_median` /
``PlanarContactSet.equilibrium``, the minimum of several repeats, and prints the ratio; then
the accuracy up to N = 1e4: objective values, positions against cvxpy and against
Weiszfeld's iteration (Vardi-Zhang) run to a 1e-15 step.

Exit status 0 when the fast solver is at least 20x faster than cvxpy at N = 1e3,
its certified gap is at most 1e-8 F_tot times the speed scale everywhere, and its median
agrees with Weiszfeld's to 1e-9 of the speed scale and with cvxpy's objective to 1e-9.
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np

from toolkit.planar import (PlanarAllocationStatus, PlanarContactSet, allocate_twist, compare_averaged,
                            dynamic_cycles, geometric_median, infeasibility_margin, quasi_static_cycle,
                            tripod_gait, warm_up, weiszfeld)

TARGET_RATIO = 20.0


def _best(repeats: int, function):
    best, value = np.inf, None
    for _ in range(repeats):
        started = time.perf_counter()
        value = function()
        best = min(best, time.perf_counter() - started)
    return best, value


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench planar", description=__doc__)
    parser.add_argument("--n", type=int, default=1000, help="points for the timing (default 1e3)")
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")          # Clarabel at 1e-13 warns "inaccurate"
    rng = np.random.default_rng(args.seed)
    started = time.perf_counter()
    warm_up()
    geometric_median(rng.normal(size=(50, 2)), method="newton")
    geometric_median(rng.normal(size=(50, 2)), method="cvxpy")
    print(f"kernels compiled or loaded and cvxpy imported in {time.perf_counter() - started:.2f} s (not timed)")
    ok = True

    n = args.n
    points, weights = rng.normal(size=(n, 2)), rng.uniform(0.5, 1.5, n)
    t_fast, fast = _best(args.repeats, lambda: geometric_median(points, weights, method="newton"))
    t_cvx, ref = _best(args.repeats, lambda: geometric_median(points, weights, method="cvxpy"))
    ratio = t_cvx / t_fast
    ok &= ratio >= TARGET_RATIO
    print(f"geometric median, N={n:.0e}: fast {t_fast * 1e3:.3f} ms, cvxpy {t_cvx * 1e3:.2f} ms, "
          f"ratio {ratio:.0f}x (target {TARGET_RATIO:.0f}x; min of {args.repeats}; load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores)")
    legs = PlanarContactSet(rng.normal(size=(n, 2)), rng.normal(size=(n, 2)), weights)
    t_fast2, _ = _best(args.repeats, lambda: legs.equilibrium(method="newton"))
    t_cvx2, _ = _best(args.repeats, lambda: legs.equilibrium(method="cvxpy"))
    print(f"twist equilibrium, N={n:.0e}: fast {t_fast2 * 1e3:.3f} ms, cvxpy {t_cvx2 * 1e3:.2f} ms, "
          f"ratio {t_cvx2 / t_fast2:.0f}x")

    print("accuracy (gaps and differences over F_tot S and S; S the speed scale):")
    for size in (100, 1000, 10000):
        for trial in range(3):
            P, w = rng.normal(size=(size, 2)) * 10.0 ** rng.integers(-2, 3), rng.uniform(0.1, 3.0, size)
            fast = geometric_median(P, w, method="newton")
            ref = geometric_median(P, w, method="cvxpy")
            slow, its = weiszfeld(P, w, tol=1e-15)
            S, F = fast.speed_scale, fast.total_force
            gap_f, gap_c = fast.gap / (F * S), ref.gap / (F * S)
            obj = abs(fast.dissipation - ref.dissipation) / (F * S)
            d_c = float(np.max(np.abs(fast.velocity - ref.velocity))) / S
            d_w = float(np.max(np.abs(fast.velocity - slow))) / S
            ok &= gap_f <= 1e-8 and obj <= 1e-9 and d_w <= 1e-9
            print(f"  median N={size:.0e} #{trial}: gap fast {gap_f:.1e}, cvxpy {gap_c:.1e}; "
                  f"|Phi_fast - Phi_cvxpy| {obj:.1e}; |x_fast - x_cvxpy| {d_c:.1e}; "
                  f"|x_fast - x_Weiszfeld| {d_w:.1e} ({its} iterations)")
        legs = PlanarContactSet(rng.normal(size=(size, 2)), rng.normal(size=(size, 2)),
                                rng.uniform(0.1, 3.0, size),
                                np.c_[rng.uniform(0, np.pi, size), rng.uniform(0.2, 5.0, size)])
        for aniso in (False, True):
            c = legs if aniso else PlanarContactSet(legs.positions, legs.velocities, legs.forces)
            fast = c.equilibrium(method="newton")
            ref = c.equilibrium(method="cvxpy")
            S, F = fast.speed_scale, fast.total_force
            gap_f = fast.gap / (F * S)
            ok &= gap_f <= 1e-8 and fast.certified
            print(f"  twist  N={size:.0e} {'anisotropic' if aniso else 'isotropic  '}: gap fast "
                  f"{gap_f:.1e}, cvxpy {ref.gap / (F * S):.1e}; |Phi_fast - Phi_cvxpy| "
                  f"{abs(fast.dissipation - ref.dissipation) / (F * S):.1e}; |x_fast - x_cvxpy| "
                  f"{float(np.max(np.abs(fast.twist - ref.twist))) / S:.1e}")
    ok &= _allocation()
    ok &= _gait()
    print(f"load average {os.getloadavg()[0]:.2f}; {'met' if ok else 'MISSED'}")
    return 0 if ok else 1


def _allocation() -> bool:
    """Leg velocities for target twists of a hexapod standing on six legs (0.5 x 9.81 N of
    friction): realized within 1e-9, or infeasible with a checked certificate."""
    hips = np.array([[0.1, 0.06], [0.0, 0.06], [-0.1, 0.06], [0.1, -0.06], [0.0, -0.06], [-0.1, -0.06]])
    loads = np.full(6, 9.81 * 0.5 / 6)
    ok = True
    print("allocation (six legs, speed limit per leg):")
    for target, vmax in (((0.1, 0.0, 0.3), 0.13), ((0.1, 0.0, 0.3), 0.11), ((0.1, 0.0, 0.5), 0.13),
                         ((0.1, 0.0, 0.8), 0.12), ((0.3, 0.0, 0.0), 0.2)):
        r = allocate_twist(hips, loads, vmax, target)
        if r.status is PlanarAllocationStatus.REALIZED:
            ok &= r.error <= 1e-9
            detail = f"error {r.error:.1e} m/s, {int(r.slipping.sum())} legs slip"
        else:
            margin = infeasibility_margin(hips, loads, vmax, target, r.certificate) if r.certificate is not None else np.nan
            ok &= r.status is PlanarAllocationStatus.INFEASIBLE and margin < 0
            detail = f"certified: residual wrench >= {r.bound:.3g} N, margin {margin:.3g} W"
        print(f"  target {target}, |v| <= {vmax}: {r.status.name} ({detail}; {r.wall_time * 1e3:.0f} ms)")
    return ok


def _gait() -> bool:
    """A turning tripod: net motion over a cycle, quasi-static and dynamic (certified), against
    the averaged (resistive-force) model."""
    gait = tripod_gait(turn=0.3, load_shift=0.25, samples=240)
    qs = quasi_static_cycle(gait, 240)
    dyn = dynamic_cycles(gait, 0.01, 5e-5, cycles=3, steps_per_cycle=400)
    cmp = compare_averaged(gait, qs, samples=240)
    print(f"turning tripod, one 1 s cycle: quasi-static {qs.displacement.round(6)} m, {qs.rotation:.5f} rad "
          f"(estimate {qs.error:.1e} m; gaps <= {qs.max_gap:.1e} W); 10 g body {dyn.displacement.round(6)} m, "
          f"{dyn.rotation:.5f} rad (estimate {dyn.error:.1e} m); averaged model {cmp.averaged.displacement.round(6)} m, "
          f"{cmp.averaged.rotation:.5f} rad: error {cmp.error:.2e} m ({100 * cmp.relative_error:.1f} %), "
          f"{cmp.rotation_error:.4f} rad")
    return bool(cmp.error > 10 * qs.error)


if __name__ == "__main__":
    raise SystemExit(main())
