"""Mean against median (the paper's Fig. 3c): hold one, vary the other, watch the speed.

Each run builds ``n = 2 h`` speeds around a middle pair, holding either the mean or the
median, and lets the body settle from rest (exact batch path); with unequal wheels
(``friction_spread``, ``wheel_seed``) the equilibrium is the weighted median. The run's
construction and the ideal model's closed form: docs/methods.md."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..errors import as_float
from ..errors import ParameterError, SolverError, parameter_message
from ..simulation import simulate_batch
from ..sweeps import RunKeys
from ._common import (MAX_CONTACTS, SETTLED_TOLERANCE, STREAM_RUN, as_count, check_common, setter,
                      wheels_for_runs)
from .median_law import median_law_slope

__all__ = ["MeanMedian"]

_OWNER = "MeanMedian"


@dataclass(frozen=True)
class MeanMedian:
    """Hold the mean and vary the median, or the reverse (see the module docstring).

    Parameters
    ----------
    held : {"mean", "median"}
    level : float, m/s
        The held mean or median.
    gap : float, m/s
        Half-width ``g`` of the middle pair (the zero-force band is ``[m - g, m + g]``).
    median_range : float, m/s
        With ``held = "mean"``, medians uniform in ``[-median_range, median_range]``.
    n : int
        Even number of contacts (the paper: 10).
    speed_limit : float, m/s
    acceleration : float, m/s^2
        ``F_tot / m``.
    settle_time : float, s
    friction_spread : float
        Relative std of each wheel's load (0: equal wheels).
    wheel_seed : int, optional
        Draw the loads once from this seed (one carousel); otherwise anew in every run.
    """

    held: str = "mean"
    level: float = 0.0
    gap: float = 0.01
    median_range: float = 0.15
    n: int = 10
    speed_limit: float = 0.35
    acceleration: float = 2.0
    settle_time: float = 20.0
    friction_spread: float = 0.0
    wheel_seed: int | None = None
    #: The ``experiment`` key of a scene's ``[sweep]``.
    name: ClassVar[str] = "mean_median"
    #: Names of :meth:`summarize`'s statistics.
    STATISTICS: ClassVar[tuple[str, ...]] = ("mean_range", "median_range", "speed_range",
                                             "slope_median", "corr_mean", "settled_fraction")

    def __post_init__(self) -> None:
        set_ = setter(self)
        if not isinstance(self.held, str) or self.held not in ("mean", "median"):
            raise ParameterError(parameter_message("held", _OWNER, "be 'mean' or 'median'", self.held))
        set_("n", as_count(self.n, "n", _OWNER, low=4, high=MAX_CONTACTS))
        if self.n % 2:
            raise ParameterError(parameter_message("n", _OWNER, "be even (a middle pair)", self.n))
        check_common(self, _OWNER, positive=("speed_limit", "acceleration", "settle_time", "gap"),
                     nonneg=("friction_spread",))
        set_("median_range", as_float(self.median_range, "median_range", _OWNER, low=0.0))
        set_("level", as_float(self.level, "level", _OWNER))
        reach = self.gap + abs(self.level) + (self.median_range if self.held == "mean" else 0.0)
        if reach >= 0.5 * self.speed_limit:
            raise ParameterError(parameter_message(
                "level", _OWNER, f"leave room for the outer speeds: |level| + gap"
                f"{' + median_range' if self.held == 'mean' else ''} < speed_limit / 2 = "
                f"{0.5 * self.speed_limit:g}", self.level))

    def speeds(self, keys: RunKeys, j: int = 0) -> np.ndarray:
        """Run ``j`` of ``keys``' contact speeds, shape (n,), m/s, from its own stream
        (rejection-sampled within the limits; the outer offsets are at most ``v_max / 2``, so
        with the checked room a draw is accepted with a probability bounded away from 0)."""
        rng = keys.generator(j, STREAM_RUN)
        h, g, v_max = self.n // 2 - 1, self.gap, self.speed_limit
        for _ in range(10_000):
            m = rng.uniform(-self.median_range, self.median_range) if self.held == "mean" else self.level
            below = rng.uniform(0.01, v_max / 2, h)      # offsets of the outer speeds
            above = rng.uniform(0.01, v_max / 2, h)
            if self.held == "mean":
                need = self.n * (self.level - m)         # sum(above) - sum(below) must equal this
                if need >= 0:
                    above *= (below.sum() + need) / above.sum()
                else:
                    below *= (above.sum() - need) / below.sum()
            speeds = np.concatenate((m - g - below, [m - g, m + g], m + g + above))
            if np.all(np.abs(speeds) <= v_max):
                return speeds
        raise SolverError(f"MeanMedian {keys.label(j)}: no speed set within the limits in 10000 draws.")

    def loads(self, keys: RunKeys) -> np.ndarray:
        """Each run's friction magnitudes, shape (runs, n), N: the carousel of ``wheel_seed``
        (:func:`toolkit.experiments.carousel_wheels`, the same wheels as every experiment
        with that seed) or each run's own carousel."""
        return wheels_for_runs(keys, self.wheel_seed, self.n, self.acceleration / self.n,
                               self.friction_spread)[1]

    def run(self, keys: RunKeys) -> dict[str, np.ndarray]:
        """Columns ``mean``, ``median`` (of the speeds) and ``speed`` (at ``settle_time``),
        m/s, and ``settled`` (the speed changed by at most
        :data:`~toolkit.experiments._common.SETTLED_TOLERANCE` over the second half: unequal
        loads can leave a small net force, and a run still moving is not at its steady speed;
        read from the same run's closed form at half the time)."""
        speeds = np.array([self.speeds(keys, j) for j in range(len(keys))])
        forces = self.loads(keys)
        batch = simulate_batch(speeds, forces, 1.0, self.settle_time, v0=0.0,
                               t_probe=0.5 * self.settle_time)
        half, final = batch.probe_speeds, batch.final_speeds
        return {"mean": speeds.mean(axis=1), "median": np.median(speeds, axis=1),
                "speed": final, "settled": np.abs(final - half) <= SETTLED_TOLERANCE}

    def summarize(self, table: Any) -> dict[str, float]:
        """``mean_range`` and ``median_range`` (max - min over the runs, m/s), ``speed_range``
        (m/s), ``slope_median`` (speed against median through the origin) and
        ``corr_mean`` (correlation of speed and mean; nan when either spans <= 1e-12 m/s) and
        ``settled_fraction``."""
        mean, median, speed = (table[c].to_numpy() for c in ("mean", "median", "speed"))
        spread = lambda x: float(x.max() - x.min())  # noqa: E731
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = float(np.corrcoef(speed, mean)[0, 1]) if min(spread(speed), spread(mean)) > 1e-12 else math.nan
        return {"mean_range": spread(mean), "median_range": spread(median), "speed_range": spread(speed),
                "slope_median": median_law_slope(median, speed)[0], "corr_mean": corr,
                "settled_fraction": float(np.mean(table["settled"]))}
