"""Bounds of values that no constructor checks: :class:`Limit`, the scene's error template, the
bounds of command-line flags without a scene key (:data:`FLAGS`) and the sizes of what a run writes.

A scene key declares its own bound (:mod:`toolkit.scenes.spec`); the flag that sets the same
value (``curve --points``, ``sweep --runs``) takes the key's, so both refuse with one rule.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..errors import SceneError
from ..sweeps import MAX_RUNS

__all__ = ["Limit", "FLAGS", "POSITIVE", "NON_NEGATIVE", "SEED", "INDEX", "MAX_SAMPLES", "MAX_RUN_SAMPLES",
           "MAX_OUTPUT_BYTES", "BYTES_PER_NUMBER", "MAX_CURVE_POINTS", "MAX_TABLE_BYTES", "scene_value_error"]

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
    """

    low: float | None = None
    high: float | None = None
    open: bool = False
    integer: bool = False

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


#: The bounds most scene keys share (each key names its own in its declaration,
#: :mod:`toolkit.scenes.spec`).
POSITIVE = Limit(low=0.0, open=True)
NON_NEGATIVE = Limit(low=0.0)
SEED = Limit(low=0, integer=True)
INDEX = Limit(low=0, integer=True)

#: Command-line flags with no scene key of their own, and their bounds.
FLAGS: dict[str, Limit] = {
    "precision --repeats": Limit(low=1, high=1000, integer=True),
    "sweep --workers": Limit(low=1, high=1024, integer=True),
    "predict --runs": Limit(low=2, high=MAX_RUNS, integer=True),
    "predict --seed": Limit(low=0, integer=True),
    # Apparatus.with_contacts' bound, and the viscosity check's default starts' (MIN_CONTACTS)
    "predict --contacts": Limit(low=5, high=10_000, integer=True),
}
