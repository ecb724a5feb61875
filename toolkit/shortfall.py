"""The shortfall: how a finished run missed what was asked of it (a result several layers share)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

__all__ = ["Shortfall"]


@dataclass(frozen=True)
class Shortfall:
    """A way a finished study missed what the scene asked for.

    Attributes
    ----------
    stage : str
        ``"scene"``, ``"allocation"``, ``"schedule"``, ``"simulation"``, ``"estimation"``,
        ``"control"``, ``"sweep"`` or ``"live"``.
    what : str
        What was missed and by how much, in words, e.g. ``"friction fraction 1.7 is not
        realizable: projected to 1 (distance 7 N)"``.
    amount : float
        By how much (NaN when no amount applies), in ``unit``.
    unit : str
        ``"N"``, ``"m/s"``, ``"s"``, ``"runs"`` or ``"order"`` (of convergence, dimensionless).
    """

    stage: str
    what: str
    amount: float
    unit: str

    def __str__(self) -> str:
        return f"{self.stage}: {self.what}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form: ``stage``, ``what``, ``amount`` (None when NaN), ``unit``."""
        amount = float(self.amount)
        return {"stage": self.stage, "what": self.what,
                "amount": amount if math.isfinite(amount) else None, "unit": self.unit}
