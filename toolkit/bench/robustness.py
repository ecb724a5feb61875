"""Robustness benchmark: the estimators when the world is not the scene.

Run ``python -m toolkit.bench robustness [--seeds N] [--cases NAME ...] [--loop-seeds M]``
(the fixed cases of :data:`toolkit.analysis.robustness.ROBUSTNESS_CASES`), or
``--random N [--seed S] [--write-scenes DIR]`` (worlds drawn at random). What it prints and
its exit status: docs/methods.md."""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from toolkit.analysis.robustness import (ROBUSTNESS_CASES, WORLD_LINES, draw_world, loop_robustness,
                                         robustness_table, score_world)
from toolkit.analysis.scenarios import carousel_brake_scenario
from toolkit.estimation import AdaptiveKalman, KalmanEstimator

_PHASES = ("startup", "cruise", "brake", "braked")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench robustness", description=__doc__)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--cases", nargs="*", default=None, choices=list(ROBUSTNESS_CASES))
    parser.add_argument("--loop-seeds", type=int, default=10)
    parser.add_argument("--random", type=int, default=None, metavar="N", help="run N random worlds instead")
    parser.add_argument("--seed", type=int, default=0, metavar="S", help="the random worlds' seed")
    parser.add_argument("--write-scenes", default=None, metavar="DIR", help="write each random world's scene")
    args = parser.parse_args(argv)
    if args.random is not None and (args.random < 1 or args.seed < 0):
        parser.exit(2, f"error: --random must be >= 1 and --seed >= 0; got {args.random} and {args.seed}\n")
    if args.write_scenes is not None:
        try:
            Path(args.write_scenes).mkdir(parents=True, exist_ok=True)
        except OSError as error:
            parser.exit(2, f"error: --write-scenes {args.write_scenes!r} cannot be made a folder: {error.strerror}\n")

    ideal = carousel_brake_scenario(seed=0)
    KalmanEstimator(ideal.model).warm_up()
    if args.random is not None:
        return _random(args.random, args.seed, args.write_scenes)
    started = time.perf_counter()
    table = robustness_table(args.cases, seeds=args.seeds)
    print(f"{len(table.cases)} cases x {args.seeds} seeds in {time.perf_counter() - started:.0f} s "
          f"(load average {os.getloadavg()[0]:.2f})")
    print("medians over seeds; RMS in mm/s, NEES in band = share of samples in the 95 % chi-square(2) "
          "interval, > 100 = share of samples with NEES above 100, max = largest NEES; cost in us per sample")
    header = (f"  {'estimator':20s} {'RMS':>8s} " + " ".join(f"{p:>8s}" for p in _PHASES)
              + f" {'NEES in':>8s} {'> 100':>7s} {'max':>9s} {'us/s':>7s}")
    for case in table.cases:
        print(f"== {case}")
        print(header)
        for name in table.estimators:
            s = table.scores[(case, name)]
            nees = "-" if s["nees_in_band"] is None else f"{s['nees_in_band']:.2f}"
            over = "-" if s["nees_over_100"] is None else f"{s['nees_over_100']:.4f}"
            top = "-" if s["nees_max"] is None else f"{s['nees_max']:.3g}"
            print(f"  {name:20s} {s['rms'] * 1e3:8.4f} " + " ".join(f"{s[p] * 1e3:8.4f}" for p in _PHASES)
                  + f" {nees:>8s} {over:>7s} {top:>9s} {s['us_per_sample']:7.1f}")
    print("== the missed-count rate the default reported its position under, per transition (medians of "
          "its mean and std; told: std 0; identified from its repairs; 0 where the nominal model held)")
    for case in table.cases:
        s = table.scores[(case, "kalman")]
        print(f"  {case:28s} {s['missed_count_prob']:.3g} +- {s['missed_count_std']:.2g}")
    status = 0
    print("== the robustness lines per case (the default kalman)")
    for case, line, value, target, met in table.checks():
        status |= 0 if met else 1
        scale = 1e3 if "NEES" not in line else 1.0
        print(f"  {'met  ' if met else 'SHORT'} {case:22s} {line:26s} {value * scale:9.4f} vs {target * scale:9.4f}")
    status |= _costs(ideal, args.cases, args.seeds)
    for controller in ("speed_hold", "viscosity"):
        loop = loop_robustness(controller, 0.2, seeds=args.loop_seeds)
        met = loop.ratio >= 10.0
        status |= 0 if met else 1
        print(f"  {'met  ' if met else 'SHORT'} closed loop {controller:10s} 20 % spread: in-loop estimate "
              f"{np.median(loop.estimate_rms) * 1e3:.4f} mm/s after 1 s, central difference "
              f"{np.median(loop.difference_rms) * 1e3:.3f} mm/s: {loop.ratio:.0f}x (target >= 10x)")
    return status


def _costs(ideal, cases, seeds: int) -> int:
    """The default's real-time ratio on the shipped scene, and the adaptive filter's cost per
    sample with every adaptive part active (module docstring)."""
    est = KalmanEstimator(ideal.model)
    best = min(est.run(ideal.record, speed_std=1e-4).wall_time for _ in range(20))
    ratio = ideal.record.duration / best
    rms = est.run(ideal.record, speed_std=1e-4).rms_error
    status = 0 if (ratio >= 1000 and rms <= 0.03e-3) else 1
    print(f"  {'met  ' if ratio >= 1000 else 'SHORT'} nominal scene: kalman {best * 1e3:.2f} ms per "
          f"{ideal.record.duration:g} s record, {ratio:.0f}x real time (target >= 1000x; load average "
          f"{os.getloadavg()[0]:.2f})")
    print(f"  {'met  ' if rms <= 0.03e-3 else 'SHORT'} nominal scene: kalman RMS {rms * 1e3:.4f} mm/s (target <= 0.03)")
    costs, spans = {}, {}
    names = [name for name in (cases or ROBUSTNESS_CASES) if name != "nominal"]
    if not names:
        return status
    print(f"  adaptive filter stepped, every adaptive part active, us per 50 Hz sample (best of 3 per record; "
          f"median over seeds 0-{seeds - 1}, their range):")
    for name in names:
        per_seed = []
        for seed in range(seeds):
            sc = ROBUSTNESS_CASES[name].scenario(seed)
            adaptive = AdaptiveKalman(sc.model, sc.prior)
            walls = []
            for _ in range(3):
                adaptive.reset(speed_std=1e-4, contact_speeds=sc.record.initial_commands)
                start = time.perf_counter()
                for k in range(sc.record.n_samples):
                    adaptive.step(sc.record.sample(k))
                walls.append(time.perf_counter() - start)
            per_seed.append(min(walls) / sc.record.n_samples * 1e6)
        costs[name], spans[name] = float(np.median(per_seed)), (min(per_seed), max(per_seed))
        print(f"    {name:28s} {costs[name]:6.1f}  ({spans[name][0]:.0f}-{spans[name][1]:.0f})")
    worst = max(costs, key=costs.get)
    met = costs[worst] <= 100.0
    print(f"  {'met  ' if met else 'SHORT'} adaptive filter stepped, every adaptive part active: at most "
          f"{costs[worst]:.0f} us per sample ({worst}, median over {seeds} seeds; median "
          f"{np.median(list(costs.values())):.0f} over the {len(costs)} mismatch cases; target <= 100 in every "
          f"case; load average {os.getloadavg()[0]:.2f})")
    return status | (0 if met else 1)


def _random(count: int, seed: int, folder: str | None) -> int:
    """Score ``count`` random worlds of ``seed`` (module docstring); the exit status."""
    from toolkit.scenes.spec import dumps_scene
    from toolkit.scenes.worlds import world_scene

    print(f"{count} random worlds of seed {seed}; RMS in mm/s; NEES in band = share of samples in the 95 % "
          "chi-square(2) interval, > 100 = share above 100, max = largest; cost in us per sample")
    header = (f"  {'estimator':20s} {'RMS':>8s} " + " ".join(f"{p:>8s}" for p in _PHASES)
              + f" {'NEES in':>8s} {'> 100':>7s} {'max':>9s} {'us/s':>7s}")
    worlds = []
    started = time.perf_counter()
    for index in range(count):
        world = draw_world(seed, index)
        if folder is not None:
            scene = world_scene(world)
            (Path(folder) / f"{scene.name}.toml").write_text(dumps_scene(scene), encoding="utf-8")
        scored = score_world(world)
        worlds.append(scored)
        print(f"== {world.describe()}")
        print(header)
        for name, row in scored.scores.items():
            def cell(key: str, scale: float = 1e3, form: str = "8.3f") -> str:
                width = int(form.split(".")[0])
                return f"{'-':>{width}s}" if row[key] is None else format(row[key] * scale, form)
            print(f"  {name:20s} {cell('rms')} " + " ".join(cell(p) for p in _PHASES)
                  + f" {cell('nees_in_band', 1.0, '8.3f')} {cell('nees_over_100', 1.0, '7.4f')}"
                  f" {cell('nees_max', 1.0, '9.3g')} {cell('us_per_sample', 1.0, '7.0f')}")
        checks = scored.checks()
        told = scored.scores["truth_told"]["rms"] / scored.best_baseline()
        print(f"  kalman / best baseline {scored.ratio:.3f} (truth_told {told:.3f}); "
              + "; ".join(f"{'met' if ok else 'SHORT'} {line}" for line, ok in checks.items()), flush=True)
    print(f"== {count} worlds in {time.perf_counter() - started:.0f} s (load average {os.getloadavg()[0]:.2f})")
    status = 0
    for line, target in WORLD_LINES.items():
        share = float(np.mean([w.checks()[line] for w in worlds]))
        told = float(np.mean([w.checks("truth_told")[line] for w in worlds]))
        met = share >= target
        status |= 0 if met else 1
        print(f"  {'met  ' if met else 'SHORT'} {line:42s} in {share:6.1%} of the worlds (target >= {target:.0%}; "
              f"truth_told {told:6.1%})")
    reach = [w for w in worlds if w.checks("truth_told")["RMS <= best baseline / 5"]]
    print(f"  where truth_told itself is 5x better than the best baseline ({len(reach)} worlds) kalman is too in "
          f"{sum(w.checks()['RMS <= best baseline / 5'] for w in reach)}")
    print("  by sample rate: worlds; share 5x better than the best baseline and median ratio to it, kalman and "
          "truth_told")
    for low, high in ((10, 25), (25, 50), (50, 100), (100, 250), (250, 501)):
        group = [w for w in worlds if low <= w.world.rate < high]
        if group:
            ratios = {name: np.array([w.scores[name]["rms"] / w.best_baseline() for w in group])
                      for name in ("kalman", "truth_told")}
            print(f"    {low:3d}-{min(high, 500):3d} Hz: {len(group):3d} worlds; " + "; ".join(
                f"{name} {np.mean(r <= 0.2):6.1%}, median {np.median(r):.3f}" for name, r in ratios.items()))
    cost = np.median([w.scores["kalman"]["us_per_sample"] for w in worlds])
    print(f"  kalman median cost {cost:.0f} us per sample over the worlds (at their own rates and contact counts)")
    print("  worst worlds (kalman / best baseline RMS):")
    for w in sorted(worlds, key=lambda w: -w.ratio)[:10]:
        kf = w.scores["kalman"]
        print(f"    {w.world.label:10s} ratio {w.ratio:7.3f}  truth_told {w.scores['truth_told']['rms'] / w.best_baseline():6.3f}"
              f"  nees_in_band {kf['nees_in_band']:.2f}  > 100 {kf['nees_over_100']:.4f}  max {kf['nees_max']:.3g}"
              f"  ({w.world.n} contacts, {w.world.rate:.4g} Hz; {w.world.truth.describe()})")
    return status
