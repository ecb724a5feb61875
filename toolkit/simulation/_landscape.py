"""The force landscapes of the ideal-motor engine: the Coulomb staircase and the compliant
piecewise-linear force of constant contact speeds, and their cache per plant and command.
"""

from __future__ import annotations

import weakref

import numpy as np

from .._compiled import core as _core     # the kernels' source module (imports no numba)
from ..model import ContactSet, Plant, compliant_breakpoints
from ..laws import tie_tolerance

_EMPTY = np.empty(0)
_EMPTY.setflags(write=False)
_NO_FIRST = np.empty(0, dtype=np.int64)      # (never written: the kernel caches nothing in it)


# -- the force landscape of constant contact speeds ----------------------------------------
# Both landscapes answer the ideal engine's three questions: where is ``V``, what is the force
# and its slope inside an interval (:meth:`force`), and what holds at a breakpoint
# (:meth:`stiction`, :meth:`contact`); the kernel (toolkit._compiled.core.ideal_piece) asks
# them of the arrays in ``args``. Interval ``j`` is ``(xs[j-1], xs[j])`` (``xs[-1] = -inf``,
# ``xs[K] = +inf``).
class _CoulombLandscape:
    """The staircase of Coulomb contacts, read from the prefix sums a :class:`ContactSet`
    already holds (its sorted distinct speeds and the magnitudes below / above each).

    Nothing is rebuilt: each event reads two prefix sums, snapped to zero within
    ``4 (K + 1) eps F_tot`` (the rule of :attr:`ContactSet.tie_tolerance`). Breakpoint ``k``
    holds the stiction magnitude ``W = below[k+1] - below[k]``; the other contacts push with
    ``G``, the mean of the two plateaus beside it.
    """

    __slots__ = ("total", "first", "args", "_contacts")
    kind = "cross"

    def __init__(self, contacts: ContactSet) -> None:
        # The private prefix sums of ContactSet (levels, below, above: its _table) are exactly
        # the staircase; reading them spares an O(N log N) sort per new plant.
        table = contacts._table
        K = table.shape[1] - 1
        self.total = contacts._prefix_total        # F_tot as the prefix sums add it up
        # The lowest contact per level, filled by the kernel as events need it; few contacts
        # are scanned instead (toolkit._compiled.core.lowest_contact): no array needed.
        self.first = np.full(K, -1, dtype=np.int64) if contacts.n > _core.SMALL else _NO_FIRST
        self._contacts = contacts
        self.args = (True, K, table, self.first, contacts.speeds, contacts.forces, self.total)

    @property
    def levels(self) -> np.ndarray:
        return self._contacts._levels

    @property
    def below(self) -> np.ndarray:
        return self._contacts._below

    @property
    def above(self) -> np.ndarray:
        return self._contacts._above

    @property
    def xs(self) -> list[float]:
        """The breakpoints: the distinct speeds of the touching contacts, ascending, m/s."""
        return self.levels.tolist()

    @property
    def _tol(self) -> float:
        return tie_tolerance(self.levels.size, self.total)

    def force(self, j: int, V: float) -> tuple[float, float]:
        """Force (N) at ``V`` inside interval ``j`` (the plateau), and its slope: 0."""
        return _core.net_force(float(self.above[j]), float(self.below[j]), self._tol), 0.0

    def stiction(self, k: int) -> tuple[float, float]:
        """``(W, G)`` at breakpoint ``k``: stiction magnitude there and the others' push, N."""
        above, below, tol = self.above, self.below, self._tol
        lower = _core.net_force(float(above[k]), float(below[k]), tol)
        upper = _core.net_force(float(above[k + 1]), float(below[k + 1]), tol)
        push = 0.5 * (lower + upper)
        return float(below[k + 1] - below[k]), (push if abs(push) > tol else 0.0)

    def contact(self, k: int) -> int:
        """The lowest index of the touching contacts at breakpoint ``k``."""
        contacts = self._contacts
        return int(_core.lowest_contact(contacts._table, contacts.speeds, contacts.forces,
                                        self.first, k))


class _CompliantLandscape:
    """Force-speed map of compliant contacts: saturation limits ``v_i +- k f_i`` as
    breakpoints, the force linear between them (``base_F[j] + slope[j] (V - base_x[j])``
    in interval ``j``). Breakpoints hold no stiction; ``G[k]`` is the force there."""

    __slots__ = ("x", "G", "first", "base_x", "base_F", "slope", "total", "args")
    kind = "saturation"

    def __init__(self, plant: Plant, speeds: np.ndarray) -> None:
        x, at_x, first, slope, total = compliant_breakpoints(speeds, plant.contacts.forces,
                                                             plant.compliance)
        self.x, self.G, self.first, self.slope, self.total = x, at_x, first, slope, total
        self.base_x = np.concatenate(([x[0]], x))
        self.base_F = np.concatenate(([total], at_x))
        self.base_F[-1] = -total
        K = x.size
        land = np.zeros((5, K + 1))            # the kernel's table (toolkit._compiled.core)
        land[0, :K], land[1], land[2], land[3], land[4, :K] = x, self.base_F, slope, \
            self.base_x, at_x
        land.setflags(write=False)             # (read-only like ContactSet._table: one kernel)
        self.args = (False, K, land, first.astype(np.int64), _EMPTY, _EMPTY, total)

    @property
    def xs(self) -> list[float]:
        return self.x.tolist()

    def force(self, j: int, V: float) -> tuple[float, float]:
        """Force (N) at ``V`` inside interval ``j``, and its slope ``dF/dV`` (N s/m)."""
        slope = float(self.slope[j])
        base = float(self.base_F[j])
        return (base if slope == 0 else base + slope * (V - float(self.base_x[j])), slope)

    def stiction(self, k: int) -> tuple[float, float]:
        """``(0, G)``: no stiction at a saturation limit, the force there, N."""
        return 0.0, float(self.G[k])

    def contact(self, k: int) -> int:
        """The lowest index of the contacts saturating at breakpoint ``k``."""
        return int(self.first[k])


_Landscape = _CoulombLandscape | _CompliantLandscape


# The exact method's own cache (a Plant holds no solver state): per plant, the landscape of
# each distinct command, so repeated simulations of one plant skip rebuilding them. Keyed
# weakly: a plant's entry goes with the plant.
_LANDSCAPES: weakref.WeakKeyDictionary[Plant, dict[bytes | None, _Landscape]] = (
    weakref.WeakKeyDictionary())


def clear_cache(plant: Plant) -> None:
    """Forget the landscapes cached for ``plant``: its next run pays what a new plant would
    (benchmarks time runs from scratch this way)."""
    _LANDSCAPES.pop(plant, None)


def _build_landscape(plant: Plant, speeds: np.ndarray | None) -> _Landscape:
    """The landscape of contact speeds ``speeds`` (m/s; ``None``: the plant's own constant
    contact speeds)."""
    if plant.compliance > 0:
        return _CompliantLandscape(plant, plant.contacts.speeds if speeds is None else speeds)
    contacts = plant.contacts
    return _CoulombLandscape(contacts if speeds is None else contacts.with_speeds(speeds))


def _landscape(plant: Plant, a: float) -> _Landscape:
    """The landscape of the contact speeds commanded at time ``a`` (s), kept in this module's
    cache (one entry per plant and distinct command)."""
    cache = _LANDSCAPES.get(plant)
    if cache is None:
        cache = _LANDSCAPES[plant] = {}
    constant = plant.commands is None and plant.motors is None
    speeds = None if constant else plant.command(a)
    key = None if constant else speeds.tobytes()
    land = cache.get(key)
    if land is None:
        land = cache[key] = _build_landscape(plant, speeds)
    return land
