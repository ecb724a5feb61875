"""The active-contact model: the net Coulomb force of contacts that move at their own speeds.

``F(V) = sum_i f_i sign(v_i - V) = F_tot (1 - 2 CDF_w(V))``, a non-increasing staircase whose
zero set is the weighted median of the speeds (docs/physics.md section 3). Two models share
one interface (:class:`ContactModel`): :class:`ContactSet` (N discrete contacts) and
:class:`ContactDistribution` (a continuous patch); :func:`weighted_median` gives the
equilibrium of many sets at once. How the force is evaluated and what a tie returns:
docs/methods.md."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from .._compiled import compiled, kernels
from ..errors import as_float, as_float_array, check_nonnegative
from ..errors import ParameterError, ParameterTypeError, parameter_message
from ..laws import tie_tolerance

__all__ = ["ContactModel", "ContactSet", "ContactDistribution", "Staircase", "unequal_loads",
           "weighted_median"]

#: Largest set whose staircase the compiled kernel sorts (by insertion; NumPy's sort above).
_SMALL = 64


@runtime_checkable
class ContactModel(Protocol):
    """What every contact model offers (discrete sets and continuous distributions)."""

    @property
    def total_force(self) -> float:
        """Sum of the friction magnitudes ``F_tot``, N."""

    def force(self, V: Any) -> np.ndarray:
        """Net force at body speeds ``V`` (m/s), N."""

    def force_bounds(self, V: Any) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper end of the set-valued net force at ``V``, N."""

    def cdf(self, V: Any) -> np.ndarray:
        """Force-weighted cumulative distribution of contact speeds at ``V``."""

    def equilibrium(self) -> tuple[float, float]:
        """The equilibrium set ``{V : 0 in F(V)}`` as ``(lo, hi)``, m/s."""


@dataclass(frozen=True)
class Staircase:
    """The force-speed staircase of a :class:`ContactSet`, ready to draw or integrate.

    Attributes
    ----------
    levels : ndarray of shape (K,), m/s
        The distinct contact speeds with positive magnitude, ascending.
    steps : ndarray of shape (K,), N
        Total magnitude ``W_k`` at each level; ``F`` drops by ``2 W_k`` across level ``k``.
    plateaus : ndarray of shape (K + 1,), N
        The constant force on each open interval: ``plateaus[0]`` below ``levels[0]``
        (``+F_tot``), ``plateaus[k]`` between ``levels[k-1]`` and ``levels[k]``,
        ``plateaus[K]`` above the last level (``-F_tot``).
    """

    levels: np.ndarray
    steps: np.ndarray
    plateaus: np.ndarray


def _as_query(V: Any, owner: str) -> np.ndarray:
    """Body speeds as a float array of any shape; +-inf allowed, NaN and non-numbers refused."""
    try:                                   # (a ragged nested list fails in iscomplexobj)
        if V is None or isinstance(V, (str, bytes)) or np.iscomplexobj(V):
            raise TypeError
        array = np.asarray(V, dtype=float)
    except (TypeError, ValueError):
        raise ParameterTypeError(parameter_message("V", owner, "be real numbers (m/s)", V)) from None
    if np.any(np.isnan(array)):
        raise ParameterError(parameter_message("V", owner, "not contain NaN", V))
    return array


@dataclass(frozen=True, eq=False)
class ContactSet:
    """A weighted set of active contacts: speeds ``v_i`` and friction magnitudes ``f_i``.

    Parameters
    ----------
    speeds : array_like of shape (n,), m/s
        Tangential ground speed of each contact. Finite; ``n >= 1``.
    forces : array_like of shape (n,), N, optional
        Coulomb friction magnitude ``f_i = mu_i N_i`` of each contact. Finite and ``>= 0``
        with a positive sum; a zero magnitude is a lifted contact. Defaults to 1 N each.

    Attributes
    ----------
    speeds, forces : ndarray of shape (n,)
        Read-only copies of the inputs, in the given order.

    Notes
    -----
    Construction sorts once, ``O(n log n)``; :meth:`force_bounds` and :meth:`cdf` on ``m``
    speeds then cost ``O(m log n)`` time and ``O(n + m)`` memory (binary search into prefix
    sums), :meth:`force` ``O(n + m)`` expected (a bucket index over the sorted speeds), never
    an ``n x m`` matrix.

    Examples
    --------
    >>> cs = ContactSet([-0.35] * 5 + [0.35] * 5)
    >>> cs.equilibrium()
    (-0.35, 0.35)
    >>> float(cs.force(0.1))
    0.0
    """

    speeds: np.ndarray
    forces: np.ndarray
    _table: np.ndarray = field(init=False, repr=False)
    _levels: np.ndarray = field(init=False, repr=False)
    _below: np.ndarray = field(init=False, repr=False)
    _above: np.ndarray = field(init=False, repr=False)
    _total: float = field(init=False, repr=False)
    _prefix_total: float = field(init=False, repr=False)

    def __init__(self, speeds: Any, forces: Any = None) -> None:
        speeds = as_float_array(speeds, "speeds", "ContactSet")
        if forces is None:
            forces = np.ones_like(speeds)
            forces.setflags(write=False)
        else:
            forces = as_float_array(forces, "forces", "ContactSet")
            check_nonnegative(forces, "forces", "ContactSet")
            if forces.shape != speeds.shape:
                raise ParameterError(parameter_message(
                    "forces", "ContactSet", f"have the same length as 'speeds' ({speeds.size})",
                    f"an array of length {forces.size}"))
        with np.errstate(over="ignore"):
            overflow = not np.isfinite(forces.sum())
        if overflow:
            raise ParameterError(parameter_message(
                "forces", "ContactSet", "have a finite sum (F_tot overflows)", f"max {forces.max()}"))
        self._derive(speeds, forces)

    def _derive(self, speeds: np.ndarray, forces: np.ndarray) -> None:
        """Store checked, read-only ``speeds`` and ``forces`` and build the staircase."""
        object.__setattr__(self, "speeds", speeds)
        object.__setattr__(self, "forces", forces)
        # below[k] = magnitude strictly below levels[k]; above[k] = magnitude at or above it.
        # One table, rows (levels + an inf pad, below, above): the exact simulator's kernel
        # takes the staircase as this one array (toolkit._compiled.core.ideal_piece). Once the
        # kernels are machine code, the kernel that builds it for many scenes builds it here
        # too (the same doubles, tested; a plant's flow builds one per step).
        core = compiled("core")
        if core is not None and speeds.ndim == 1 and speeds.size <= _SMALL:
            n = speeds.size
            land = np.empty((3, n + 1))
            K, total = core.contact_table(speeds.reshape(1, n), forces.reshape(1, n), np.empty(n, dtype=np.int64),
                                          land, np.empty(n + 1, dtype=np.int64))
        else:
            K = -1
        if K == 0 or (K < 0 and not np.any(forces > 0)):
            raise ParameterError(parameter_message(
                "forces", "ContactSet", "have a positive sum (some contact must touch)",
                forces.tolist() if forces.size <= 8 else "all zeros"))
        if K > 0:
            table = land[:, :K + 1].copy()
            table[0, K] = np.inf
        else:
            active = forces > 0
            levels, inverse = np.unique(speeds[active], return_inverse=True)
            steps = np.bincount(inverse, weights=forces[active], minlength=levels.size)
            K = levels.size
            table = np.empty((3, K + 1))
            table[0, :K] = levels
            table[0, K] = np.inf
            table[1, 0] = 0.0
            np.cumsum(steps, out=table[1, 1:])
            table[2, :K] = np.cumsum(steps[::-1])[::-1]
            table[2, K] = 0.0
            total = float(np.sum(steps))
        table.setflags(write=False)
        object.__setattr__(self, "_table", table)
        object.__setattr__(self, "_levels", table[0, :K])
        object.__setattr__(self, "_below", table[1])
        object.__setattr__(self, "_above", table[2])
        object.__setattr__(self, "_total", float(total))
        # F_tot as the prefix sums add it up (may differ from _total in the last bit).
        object.__setattr__(self, "_prefix_total", float(table[1, K]))

    # -- constructors ---------------------------------------------------------------------
    @classmethod
    def from_friction(cls, speeds: Any, mu: Any, normal_loads: Any) -> ContactSet:
        """Build from friction coefficients and normal loads, ``f_i = mu_i * N_i``.

        Parameters
        ----------
        speeds : array_like of shape (n,), m/s
        mu : float or array_like of shape (n,), dimensionless, ``>= 0``
        normal_loads : float or array_like of shape (n,), N, ``>= 0``
        """
        speeds = as_float_array(speeds, "speeds", "ContactSet.from_friction")
        mu_a = as_float_array(mu, "mu", "ContactSet.from_friction")
        load = as_float_array(normal_loads, "normal_loads", "ContactSet.from_friction")
        check_nonnegative(mu_a, "mu", "ContactSet.from_friction")
        check_nonnegative(load, "normal_loads", "ContactSet.from_friction")
        for name, array in (("mu", mu_a), ("normal_loads", load)):
            if array.size not in (1, speeds.size):
                raise ParameterError(parameter_message(
                    name, "ContactSet.from_friction",
                    f"be a scalar or have the length of 'speeds' ({speeds.size})",
                    f"an array of length {array.size}"))
        return cls(speeds, np.broadcast_to(mu_a * load, speeds.shape))

    def with_speeds(self, speeds: Any) -> ContactSet:
        """Return the same contacts (same magnitudes) moved to new speeds, m/s.

        The magnitudes were checked when this set was built: only ``speeds`` is (finite
        numbers, one per contact).
        """
        speeds = as_float_array(speeds, "speeds", "ContactSet.with_speeds")
        if speeds.shape != self.forces.shape:
            raise ParameterError(parameter_message(
                "speeds", "ContactSet.with_speeds", f"have one speed per contact ({self.forces.size})",
                f"an array of length {speeds.size}"))
        moved = object.__new__(type(self))
        moved._derive(speeds, self.forces)
        return moved

    # -- basic properties -------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of contacts (lifted ones included)."""
        return int(self.speeds.size)

    def __len__(self) -> int:
        return self.n

    @property
    def total_force(self) -> float:
        """``F_tot = sum f_i``, N: the force far below every contact speed."""
        return self._total

    @property
    def tie_tolerance(self) -> float:
        """Net forces smaller than this (N) are reported as exactly 0.

        ``4 (K + 1) eps F_tot`` for ``K`` distinct speeds: a bound on the rounding error of
        the prefix sums from which every force is computed.
        """
        return tie_tolerance(self._levels.size, self._total)

    def staircase(self) -> Staircase:
        """The staircase (levels, step magnitudes, plateau forces); see :class:`Staircase`."""
        plateaus = self._snap(self._above - self._below)
        return Staircase(self._levels.copy(), np.diff(self._below), plateaus)

    def __repr__(self) -> str:
        return (f"ContactSet(n={self.n}, total_force={self._total:.6g} N, "
                f"speeds in [{self.speeds.min():.6g}, {self.speeds.max():.6g}] m/s)")

    # -- evaluation ---------------------------------------------------------------------------
    def _snap(self, force: np.ndarray) -> np.ndarray:
        return np.where(np.abs(force) <= self.tie_tolerance, 0.0, force)

    def _parts(self, V: Any, owner: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        query = _as_query(V, owner)
        left = np.searchsorted(self._levels, query, side="left")
        right = np.searchsorted(self._levels, query, side="right")
        below = self._below[left]            # magnitude of contacts with v_i < V
        above = self._above[right]           # magnitude of contacts with v_i > V
        at = self._below[right] - below      # magnitude of contacts with v_i == V
        return below, above, at

    def force(self, V: Any) -> np.ndarray:
        """Net force ``F(V) = sum f_i sign(v_i - V)`` at body speeds ``V``.

        Parameters
        ----------
        V : float or array_like of any shape, m/s
            Body speeds; ``+-inf`` allowed, NaN refused.

        Returns
        -------
        ndarray of the shape of ``V``, N
            Exactly at a contact speed the midpoint of :meth:`force_bounds` (contacts at
            ``V`` contribute 0, i.e. ``sign(0) = 0``). Values below :attr:`tie_tolerance`
            in magnitude are exactly 0.
        """
        query = _as_query(V, "ContactSet.force")
        flat = np.ascontiguousarray(query.ravel()).view()
        flat.setflags(write=False)                 # one kind of array: one compiled kernel
        out = np.empty(flat.size)
        # The kernel (toolkit._compiled.core.coulomb_force, compiled once a process has run
        # enough through it): a bucket index over the levels, O(1) per speed expected.
        kernels("core", 2 * flat.size).coulomb_force(self._levels, self._below, self._above,
                                                     self.tie_tolerance, flat, out)
        return out.reshape(query.shape)

    def force_bounds(self, V: Any) -> tuple[np.ndarray, np.ndarray]:
        """The set-valued net force at ``V`` as ``(lower, upper)``, N.

        Equal away from contact speeds; at ``V == v_i`` the interval spans the stiction
        forces ``[-W, +W]`` of the contacts at that speed (total magnitude ``W``).
        """
        below, above, at = self._parts(V, "ContactSet.force_bounds")
        return self._snap(above - below - at), self._snap(above - below + at)

    def cdf(self, V: Any) -> np.ndarray:
        """Force-weighted CDF of the speeds, ``sum_{v_i <= V} f_i / F_tot`` (right-continuous)."""
        query = _as_query(V, "ContactSet.cdf")
        right = np.searchsorted(self._levels, query, side="right")
        return self._below[right] / self._total

    def equilibrium(self) -> tuple[float, float]:
        """The equilibrium set ``{V : 0 in F(V)}``: the weighted median of the speeds.

        Returns
        -------
        (lo, hi) : tuple of float, m/s
            ``lo == hi`` for a single point (odd equal-weight sets); ``lo < hi`` for a
            zero-force band (even equal-weight sets: ``[v_(N/2), v_(N/2+1)]``), inside
            which the net force is exactly zero and the body coasts.
        """
        # The one weighted median (toolkit._compiled.core.staircase_median) on this staircase.
        lo, hi = kernels("core", self._levels.size).staircase_median(
            self._levels, self._below, self._above, self._levels.size, self.tie_tolerance)
        return float(lo), float(hi)

    def zero_force_band(self) -> tuple[float, float] | None:
        """The open band where ``F == 0`` exactly, as ``(lo, hi)``, or ``None`` if there is none."""
        lo, hi = self.equilibrium()
        return (lo, hi) if hi > lo else None


@dataclass(frozen=True, eq=False)
class ContactDistribution:
    """A continuous density of contact speed over a contact patch.

    ``F(V) = F_tot (1 - 2 CDF(V))`` with ``CDF`` the cumulative distribution of the
    force-weighted contact speed. The force is single-valued everywhere (no atoms).

    Parameters
    ----------
    distribution : frozen ``scipy.stats`` continuous distribution
        The distribution of contact speed (m/s), e.g. ``scipy.stats.uniform(-0.35, 0.7)``.
    total_force : float, N
        ``F_tot``, positive.

    See Also
    --------
    ContactDistribution.from_histogram : a tabulated density.
    """

    distribution: Any
    total_force: float
    _edges: np.ndarray | None = field(default=None, init=False, repr=False)
    _cumulative: np.ndarray | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        dist = self.distribution
        if not all(hasattr(dist, name) for name in ("cdf", "ppf", "pdf", "support")):
            raise ParameterTypeError(parameter_message(
                "distribution", "ContactDistribution",
                "be a frozen scipy.stats continuous distribution", dist))
        object.__setattr__(self, "total_force", as_float(
            self.total_force, "total_force", "ContactDistribution", low=0.0, low_open=True))

    @classmethod
    def from_histogram(cls, edges: Any, weights: Any, total_force: float) -> ContactDistribution:
        """A piecewise-uniform density tabulated over speed bins.

        Parameters
        ----------
        edges : array_like of shape (k + 1,), m/s
            Strictly increasing bin edges.
        weights : array_like of shape (k,)
            Non-negative relative weight of each bin (normalized internally); a zero bin
            is a gap in the patch and can make the equilibrium an interval.
        total_force : float, N
        """
        from scipy import stats

        edges_a = as_float_array(edges, "edges", "ContactDistribution.from_histogram")
        weights_a = as_float_array(weights, "weights", "ContactDistribution.from_histogram")
        check_nonnegative(weights_a, "weights", "ContactDistribution.from_histogram")
        if edges_a.size != weights_a.size + 1:
            raise ParameterError(parameter_message(
                "edges", "ContactDistribution.from_histogram",
                f"have one more entry than 'weights' ({weights_a.size + 1})",
                f"an array of length {edges_a.size}"))
        if np.any(np.diff(edges_a) <= 0):
            raise ParameterError(parameter_message(
                "edges", "ContactDistribution.from_histogram", "be strictly increasing",
                edges_a.tolist()))
        if not weights_a.sum() > 0:
            raise ParameterError(parameter_message(
                "weights", "ContactDistribution.from_histogram", "have a positive sum",
                weights_a.tolist()))
        cumulative = np.concatenate(([0.0], np.cumsum(weights_a))) / weights_a.sum()
        patch = cls(stats.rv_histogram((weights_a, edges_a), density=False), total_force)
        object.__setattr__(patch, "_edges", edges_a)
        object.__setattr__(patch, "_cumulative", cumulative)
        return patch

    def force(self, V: Any) -> np.ndarray:
        """Net force ``F_tot (1 - 2 CDF(V))`` at body speeds ``V`` (m/s), N."""
        return self.total_force * (1.0 - 2.0 * self.cdf(V))

    def force_bounds(self, V: Any) -> tuple[np.ndarray, np.ndarray]:
        """``(F(V), F(V))``: a continuous patch has no stiction interval."""
        force = self.force(V)
        return force, force.copy()

    def cdf(self, V: Any) -> np.ndarray:
        """CDF of the contact-speed distribution at ``V`` (m/s)."""
        return np.asarray(self.distribution.cdf(_as_query(V, "ContactDistribution.cdf")), dtype=float)

    def density(self, V: Any) -> np.ndarray:
        """Density of contact speed at ``V``, 1/(m/s); ``-dF/dV = 2 F_tot density``."""
        return np.asarray(self.distribution.pdf(_as_query(V, "ContactDistribution.density")), dtype=float)

    def equilibrium(self) -> tuple[float, float]:
        """The median set ``{V : CDF(V) = 1/2}`` as ``(lo, hi)``, m/s.

        Exact for a histogram (a run of empty bins at CDF 1/2 gives an interval). For a
        ``scipy.stats`` distribution the point ``ppf(1/2)``: such densities are positive
        around their median, so the set is a point.
        """
        if self._edges is None:
            point = float(self.distribution.ppf(0.5))
            return point, point
        edges, cum = self._edges, self._cumulative
        tol = tie_tolerance(edges.size - 1, 1.0)          # (a prefix sum of probabilities)
        flat = np.flatnonzero(np.abs(cum - 0.5) <= tol)
        if flat.size:
            return float(edges[flat[0]]), float(edges[flat[-1]])
        j = int(np.searchsorted(cum, 0.5)) - 1           # bin j holds the median
        share = (0.5 - cum[j]) / (cum[j + 1] - cum[j])
        point = float(edges[j] + share * (edges[j + 1] - edges[j]))
        return point, point


def weighted_median(speeds: Any, forces: Any, outside: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """The weighted median of contact speeds, ``{V : -F in F_c(V)}``, as ``(lo, hi)``.

    The equilibrium set of :meth:`ContactSet.equilibrium` (the same staircase, the same tie
    tolerance ``4 (K + 1) eps F_tot``; docs/physics.md section 3) for many sets of speeds at
    once, optionally under an outside force ``F``, which enters as one more contact of
    magnitude ``|F|`` at ``sign(F) inf``.

    Parameters
    ----------
    speeds : array_like of shape (..., n), m/s
        Contact speeds; each row along the last axis is one set. ``+-inf`` allowed.
    forces : array_like of shape (n,), N
        Friction magnitudes ``f_i >= 0`` (the weights), shared by every row.
    outside : float or array_like of shape (...), N, optional
        Outside force on the body for each row (default none).

    Returns
    -------
    lo, hi : ndarray of shape (...), m/s
        ``lo == hi`` for a point, ``lo < hi`` for a zero-force band; ``+-inf`` when ``|F|``
        exceeds the total friction (``|F| = F_tot``: a band to ``+-inf``). A row whose
        magnitudes (outside force included) are all zero gives its slowest speed twice.
    """
    owner = "weighted_median"
    v = np.asarray(speeds, dtype=float)
    if v.ndim == 0:
        raise ParameterError(parameter_message("speeds", owner, "have at least one axis (..., n)", speeds))
    if np.isnan(v).any():
        raise ParameterError(parameter_message("speeds", owner, "hold no NaN", "an array with NaN"))
    f = as_float_array(forces, "forces", owner)
    check_nonnegative(f, "forces", owner)
    if f.shape != v.shape[-1:]:
        raise ParameterError(parameter_message(
            "forces", owner, f"have one magnitude per contact ({v.shape[-1]})", f"shape {f.shape}"))
    lead = v.shape[:-1]
    if outside is None:
        F = np.zeros(lead)
    else:
        try:
            F = np.broadcast_to(np.asarray(outside, dtype=float), lead)
        except ValueError:
            raise ParameterError(parameter_message(
                "outside", owner, f"broadcast to the rows' shape {lead}", np.shape(outside))) from None
        if not np.all(np.isfinite(F)):
            raise ParameterError(parameter_message("outside", owner, "be finite", outside))
    rows = np.ascontiguousarray(v.reshape(-1, v.shape[-1]))
    out = np.empty((rows.shape[0], 2))
    kernels("core", rows.size + rows.shape[0]).median_edges(
        rows, np.ascontiguousarray(f), np.ascontiguousarray(np.reshape(F, -1), dtype=float), out)
    return out[:, 0].reshape(lead), out[:, 1].reshape(lead)


def unequal_loads(mean: Any, spread: float, size: int, rng: np.random.Generator | None = None, *,
                  normals: Any = None) -> np.ndarray:
    """Friction magnitudes of contacts that differ at random (unequal wheels), N.

    Each ``f_i`` is lognormal with mean ``mean`` and relative standard deviation ``spread``:
    ``f_i = mean exp(sigma z_i - sigma^2 / 2)``, ``sigma^2 = ln(1 + spread^2)``, ``z_i``
    standard normal from ``rng``, or the ``normals`` given (always positive, unlike a clipped
    normal). ``spread = 0`` gives ``mean`` exactly and draws nothing.

    Parameters
    ----------
    mean : float or ndarray of shape (size,), N
        Mean load of each contact.
    spread : float
        Relative standard deviation, ``>= 0``.
    size : int
    rng : numpy.random.Generator, optional
        Draws the ``z_i`` (when ``normals`` is not given).
    normals : array_like of shape (..., size), optional
        The ``z_i`` already drawn, e.g. many carousels at once (one row each).

    Returns
    -------
    ndarray of shape (size,) (or that of ``normals``), N
    """
    spread = as_float(spread, "spread", "unequal_loads", low=0.0)
    mean = np.broadcast_to(np.asarray(mean, dtype=float), (size,))
    if spread == 0.0:
        return mean.copy()
    sigma = float(np.sqrt(np.log1p(spread * spread)))
    z = rng.standard_normal(size) if normals is None else np.asarray(normals, dtype=float)
    return mean * np.exp(sigma * z - 0.5 * sigma * sigma)
