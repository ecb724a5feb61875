"""Estimation benchmark: the carousel's 10 s startup-then-brake run (issue 9).

Run ``python -m toolkit.bench estimation [--seed K] [--repeat R]``. Simulates the run
exactly, records it through the sensor law (paper's encoders, 50 Hz), and runs every
estimator on it. Prints the Kalman filter's wall time (best of ``R``), its real-time ratio,
and the RMS / max speed error of each estimator, with the NEES and NIS means against their
95 % bands. Exit status 0 when the issue-9 criteria hold: KF RMS <= FD RMS / 10, KF RMS
<= 1.5 RTS RMS, KF NEES mean in its band, KF >= 1000x real time.
"""

from __future__ import annotations

import argparse

from toolkit.estimation import (CentralDifference, KalmanEstimator, RTSSmoother, UnscentedEstimator,
                                WheelDifference)
from toolkit.scenarios import carousel_brake_scenario


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m toolkit.bench estimation", description=__doc__)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args(argv)

    sc = carousel_brake_scenario(seed=args.seed)
    record = sc.record
    kf_est = KalmanEstimator(sc.model)
    runs = [kf_est.run(record, speed_std=1e-4) for _ in range(max(args.repeat, 1))]
    kf = min(runs, key=lambda r: r.wall_time)
    results = [CentralDifference(sc.sensors).run(record),
               WheelDifference(sc.sensors, sc.model.forces).run(record), kf,
               RTSSmoother(sc.model).run(record, speed_std=1e-4),
               UnscentedEstimator(sc.model).run(record, speed_std=1e-4)]
    print(f"record: {record.n_samples} samples over {record.duration:g} s at {sc.sensors.rate:g} Hz")
    print(f"kalman wall time (best of {len(runs)}): {kf.wall_time * 1e3:.2f} ms, "
          f"{kf.real_time_ratio:.0f}x real time (target >= 1000x)")
    for r in results:
        extra = ""
        if r.nees_mean is not None:
            extra += f"  NEES {r.nees_mean:.2f} in [{r.nees_band[0]:.2f}, {r.nees_band[1]:.2f}]"
        if r.nis_mean is not None:
            extra += f"  NIS {r.nis_mean:.2f} in [{r.nis_band[0]:.2f}, {r.nis_band[1]:.2f}]"
        print(f"{r.method:20s} RMS {r.rms_error * 1e3:8.4f} mm/s  max {r.max_error * 1e3:8.3f} mm/s"
              f"  wall {r.wall_time * 1e3:8.2f} ms{extra}")
    fd, rts = results[0], results[3]
    checks = {"KF RMS <= FD RMS / 10": kf.rms_error <= fd.rms_error / 10,
              "KF RMS <= 1.5 RTS RMS": kf.rms_error <= 1.5 * rts.rms_error,
              "KF NEES mean in band": bool(kf.nees_consistent),
              "KF >= 1000x real time": kf.real_time_ratio >= 1000}
    for name, ok in checks.items():
        print(f"{'met  ' if ok else 'SHORT'} {name}")
    return 0 if all(checks.values()) else 1
