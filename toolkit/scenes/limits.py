"""The bounds of every scene value and command-line flag that no constructor checks: one table.

A scene key and the flag that overrides it (``report.curve_points`` and ``curve --points``,
``sweep.runs`` and ``sweep --runs``, ...) share one :class:`Limit`, so the command line
refuses what the scene file refuses, with the same rule. The sizes of what a run writes are
bounded here too (:data:`MAX_OUTPUT_BYTES`), before any work starts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..errors import SceneError
from ..sweeps import MAX_RUNS

__all__ = ["Limit", "LIMITS", "FLAGS", "MAX_SAMPLES", "MAX_RUN_SAMPLES", "MAX_OUTPUT_BYTES",
           "BYTES_PER_NUMBER", "MAX_CURVE_POINTS", "MAX_TABLE_BYTES", "scene_value_error"]

#: Largest generated array a scene may ask for (random contacts, curve samples): 1e7.
MAX_SAMPLES = 10_000_000
#: Most samples an estimation record or a closed loop may take (its arrays grow with them).
MAX_RUN_SAMPLES = 10_000_000
#: Largest output file a run may write (``result.json``, ``estimate.json``), bytes: 64 MiB.
MAX_OUTPUT_BYTES = 64 << 20
#: Largest sweep table (``results.csv``, one row per run) a sweep may write, bytes: 512 MiB.
MAX_TABLE_BYTES = 512 << 20
#: Bytes one number of a series takes in the JSON outputs (17 significant digits, the
#: indentation of a list item, the comma and newline): the estimate of an output's size.
BYTES_PER_NUMBER = 30
#: Most samples of a sampled force-speed curve: its two series (speeds, forces) within
#: :data:`MAX_OUTPUT_BYTES` (1118481).
MAX_CURVE_POINTS = MAX_OUTPUT_BYTES // (2 * BYTES_PER_NUMBER)


@dataclass(frozen=True)
class Limit:
    """Bounds of one value: ``low`` (strict when ``open``), ``high``, integer or not.

    Attributes
    ----------
    low, high : float or None
        The bounds (None: unbounded on that side).
    open : bool
        ``low`` itself is refused (``> low``).
    integer : bool
        Only whole numbers (``bool`` refused).
    flag : str or None
        The command-line flag that sets the same value, e.g. ``"curve --points"``.
    """

    low: float | None = None
    high: float | None = None
    open: bool = False
    integer: bool = False
    flag: str | None = None

    @property
    def rule(self) -> str:
        """The rule in words: ``"be > 0"``, ``"be an integer >= 1"``, ``"be an integer <= 10000000"``."""
        kind = "an integer " if self.integer else ""
        parts = []
        if self.low is not None:
            parts.append(f"{'>' if self.open else '>='} {self.low:g}")
        if self.high is not None:
            parts.append(f"<= {self.high:g}" if not self.integer else f"<= {int(self.high)}")
        return f"be {kind}{' and '.join(parts)}".rstrip() if parts else f"be {kind}".rstrip()

    def broken(self, value: Any) -> str:
        """The rule ``value`` breaks, in words (the bound it passes, or its kind)."""
        if self.integer and (isinstance(value, bool) or not isinstance(value, int)):
            return "be an integer"
        kind = "an integer " if self.integer else ""
        if self.low is not None and (value <= self.low if self.open else value < self.low):
            return f"be {kind}{'>' if self.open else '>='} {self.low:g}"
        if self.high is not None and value > self.high:
            return f"be {kind}<= {int(self.high)}" if self.integer else f"be <= {self.high:g}"
        return self.rule

    def holds(self, value: Any) -> bool:
        """Whether ``value`` keeps the bounds (and is a whole number when ``integer``)."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return False
        if self.integer and not isinstance(value, int):
            return False
        if isinstance(value, float) and math.isnan(value):
            return False
        if self.low is not None and (value <= self.low if self.open else value < self.low):
            return False
        return self.high is None or value <= self.high


def scene_value_error(key: str, rule: str, value: Any) -> SceneError:
    """The scene's one error template: ``The 'body.mass' value in the scene must <rule>. Got
    <value> instead.``"""
    return SceneError(f"The {key!r} value in the scene must {rule}. Got {value!r} instead.")


_POSITIVE = Limit(low=0.0, open=True)
_NON_NEGATIVE = Limit(low=0.0)
_SEED = Limit(low=0, integer=True)
_INDEX = Limit(low=0, integer=True)

#: Every bounded scene key (``section.key``; ``[]`` marks each entry of a list).
LIMITS: dict[str, Limit] = {
    "contacts.random.n": Limit(low=1, high=MAX_SAMPLES, integer=True),
    "contacts.random.seed": _SEED,
    "body.inertia": _POSITIVE,
    "body.contact_radius": _POSITIVE,
    "motors.speed_limit": _POSITIVE,
    "target.dt": _POSITIVE,
    "target.time_limit": _POSITIVE,
    "target.fixed[]": _INDEX,
    "target.failed[]": _INDEX,
    "target.liftable[]": _INDEX,
    "schedule.period": _POSITIVE,
    "schedule.epsilon": _POSITIVE,
    "schedule.horizon": _POSITIVE,
    "schedule.time_limit": _POSITIVE,
    "simulation.t_end": _POSITIVE,
    "estimation.duration": _POSITIVE,
    "estimation.brake_time": _NON_NEGATIVE,
    "estimation.spread": _NON_NEGATIVE,
    "estimation.seed": _SEED,
    "estimation.friction_spread": _NON_NEGATIVE,
    "estimation.speed_std": _POSITIVE,
    "control.duration": _POSITIVE,
    "control.seed": _SEED,
    "report.curve_points": Limit(low=2, high=MAX_CURVE_POINTS, integer=True, flag="curve --points"),
    "sweep.runs": Limit(low=1, high=MAX_RUNS, integer=True, flag="sweep --runs"),
    "sweep.seed": Limit(low=0, integer=True, flag="sweep --seed"),
    "sweep.chunk_size": Limit(low=1, integer=True),
    "planar.mass": _POSITIVE,
    "planar.inertia": _POSITIVE,
    "planar.radius": _POSITIVE,
    "planar.inner_radius": _NON_NEGATIVE,
    "planar.mu": _POSITIVE,
    "planar.gravity": _POSITIVE,
    "planar.t_end": _POSITIVE,
    "planar.step": _POSITIVE,
    "planar.epsilon": _POSITIVE,
    # A disc's quadrature has about pi resolution^2 nodes: 1000 rings, 3e6 nodes.
    "planar.resolution": Limit(low=1, high=1000, integer=True),
    "planar.forces[]": _NON_NEGATIVE,
    "planar.precision.steps[]": _POSITIVE,
    "planar.precision.epsilons[]": _POSITIVE,
    "planar.precision.resolutions[]": Limit(low=1, high=1000, integer=True),
}

#: Command-line flags with no scene key of their own, bounded like the keys above.
FLAGS: dict[str, Limit] = {
    "precision --repeats": Limit(low=1, high=1000, integer=True),
    "sweep --workers": Limit(low=1, high=1024, integer=True),
    "predict --runs": Limit(low=2, high=MAX_RUNS, integer=True),
    "predict --seed": Limit(low=0, integer=True),
    # Apparatus.with_contacts' bound, and the viscosity check's default starts' (MIN_CONTACTS)
    "predict --contacts": Limit(low=5, high=10_000, integer=True),
}
