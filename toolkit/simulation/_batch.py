"""Many constant-speed scenes at once: the exact method's own kernel, in parallel over scenes.

Each scene is a body from ``V(0) = v0`` on its own contacts (constant speeds, ideal motors)
with its own mass, drag and constant external force. Each runs through the very event loop of
single runs (:func:`toolkit._compiled.core.ideal_piece`, on the staircase built as
:class:`~toolkit.model.ContactSet` builds it), so each final speed and event count is the
single run's; :func:`toolkit._compiled.core.batch` spreads the scenes over the cores
(``numba.prange``). Python only validates the inputs and assembles the result.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._compiled import budget_clock
from .._compiled import kernels, parallel
from ..errors import as_float, as_float_array, check_nonnegative
from ..errors import ParameterError, parameter_message
from ._result import SimulationStatus, status_message

__all__ = ["BatchResult", "simulate_batch"]

_OWNER = "simulate_batch"


@dataclass(frozen=True, eq=False)
class BatchResult:
    """Final state of every scene of :func:`simulate_batch`.

    Attributes
    ----------
    final_speeds : ndarray of shape (scenes,), m/s
        Body speed at ``t_end``.
    n_events : ndarray of shape (scenes,), int
        Events of each scene (crossings and sticks, counted as the exact method does).
    stuck : ndarray of shape (scenes,), bool
        True where the body ends stuck at a contact speed (sliding mode).
    status : SimulationStatus
    message : str
    wall_time : float, s
    probe_speeds : ndarray of shape (scenes,) or None, m/s
        Body speed at ``t_probe`` when asked for (NaN for scenes stopped early).
    """

    final_speeds: np.ndarray
    n_events: np.ndarray
    stuck: np.ndarray
    status: SimulationStatus
    message: str
    wall_time: float
    probe_speeds: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in ("final_speeds", "n_events", "stuck", "probe_speeds"):
            if getattr(self, name) is None:
                continue
            array = np.array(getattr(self, name))
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @property
    def success(self) -> bool:
        """True when every scene reached ``t_end``."""
        return self.status is SimulationStatus.SUCCESS

    def to_dict(self) -> dict[str, Any]:
        """JSON-able: ``final_speeds``, ``n_events``, ``stuck`` (lists), ``status`` (name),
        ``message``, ``wall_time``."""
        return {"final_speeds": self.final_speeds.tolist(), "n_events": self.n_events.tolist(),
                "stuck": self.stuck.tolist(), "status": self.status.name,
                "message": self.message, "wall_time": self.wall_time}

    @property
    def n_scenes(self) -> int:
        """Number of scenes."""
        return int(self.final_speeds.size)


def _per_scene(value: Any, name: str, scenes: int, low: float | None,
               low_open: bool = False) -> np.ndarray:
    if np.ndim(value) == 0:
        scalar = as_float(value, name, _OWNER, low=low, low_open=low_open)
        return np.full(scenes, scalar)
    array = as_float_array(value, name, _OWNER)
    if array.size != scenes:
        raise ParameterError(parameter_message(
            name, _OWNER, f"be a scalar or have one entry per scene ({scenes})",
            f"an array of length {array.size}"))
    if low is not None and (np.any(array <= low) if low_open else np.any(array < low)):
        raise ParameterError(parameter_message(
            name, _OWNER, f"be {'>' if low_open else '>='} {low:g}", array.min().item()))
    return array


def _frozen(array: np.ndarray) -> np.ndarray:
    """A read-only C-contiguous view: the kernel sees one kind of array whatever the caller
    passed (one compiled specialization)."""
    view = np.ascontiguousarray(array, dtype=float).view()
    view.setflags(write=False)
    return view


def simulate_batch(speeds: Any, forces: Any, mass: Any, t_end: float, *, v0: Any = 0.0,
                   damping: Any = 0.0, external: Any = 0.0,
                   t_probe: float | None = None) -> BatchResult:
    """Simulate many scenes of constant contact speeds exactly, vectorized over scenes.

    Parameters
    ----------
    speeds : array_like of shape (scenes, N), m/s
        Contact speeds of each scene (finite).
    forces : array_like of shape (scenes, N), N, or None
        Friction magnitudes ``f_i >= 0`` with a positive sum per scene; ``None`` = 1 N each.
    mass : float or array_like of shape (scenes,), kg
        Moving inertia, ``> 0``.
    t_end : float, s
        Horizon, ``> 0``.
    v0 : float or array_like of shape (scenes,), m/s
        Initial body speeds.
    damping : float or array_like of shape (scenes,), N s/m
        Bearing drag ``c >= 0``.
    external : float or array_like of shape (scenes,), N
        Constant external force on the body.
    t_probe : float, s, optional
        Also report each body speed at this time in ``[0, t_end]`` (``probe_speeds``), from
        the run's own closed-form segments: no second run (e.g. a settled check).

    Returns
    -------
    BatchResult
        Final speeds and event counts are those of the single-run exact method
        (``simulate(..., method="exact")`` of a :class:`~toolkit.model.Plant` with that
        scene's contacts, mass, damping and external force): the same kernel runs each.

    Examples
    --------
    >>> result = simulate_batch([[-1.0, 0.5, 2.0], [0.0, 1.0, 3.0]], None, 1.0, 5.0)
    >>> result.final_speeds.tolist()
    [0.5, 1.0]
    """
    started = budget_clock()
    v = as_float_array(speeds, "speeds", _OWNER, ndim=2)
    S, N = v.shape
    if forces is None:
        f = np.ones_like(v)
    else:
        f = as_float_array(forces, "forces", _OWNER, ndim=2)
        check_nonnegative(f, "forces", _OWNER)
        if f.shape != v.shape:
            raise ParameterError(parameter_message(
                "forces", _OWNER, f"have the shape of 'speeds' {v.shape}", f"shape {f.shape}"))
    m = _per_scene(mass, "mass", S, 0.0, low_open=True)
    c = _per_scene(damping, "damping", S, 0.0)
    E = _per_scene(external, "external", S, None)
    V0 = _per_scene(v0, "v0", S, None)
    t_end = as_float(t_end, "t_end", _OWNER, low=0.0, low_open=True)
    probe = -1.0
    if t_probe is not None:
        probe = as_float(t_probe, "t_probe", _OWNER, low=0.0, high=t_end)

    v, f, m, c, E, V0 = (_frozen(x) for x in (v, f, m, c, E, V0))
    total = np.sum(f, axis=1)
    if np.any(total <= 0):
        bad = int(np.flatnonzero(total <= 0)[0])
        raise ParameterError(parameter_message(
            "forces", _OWNER, "have a positive sum in every scene", f"scene {bad} with sum 0"))
    V = np.empty(S)
    events = np.empty(S, dtype=np.int64)
    stuck = np.empty(S, dtype=bool)
    codes = np.empty(S, dtype=np.int64)
    at_probe = np.empty(S)
    # One scene is about 20 interpreted rounds of work per contact (toolkit._compiled), on
    # the cores left idle (toolkit._compiled.parallel).
    work = 20 * S * N
    with parallel(work):
        kernels("core", work).batch(v, f, m, c, E, V0, t_end, probe, V, events, stuck, codes,
                                    at_probe)
    failed = codes != 0
    status = SimulationStatus.SUCCESS if not failed.any() else SimulationStatus.MAX_STEPS
    detail = f"{S} scenes, {int(events.sum())} events"
    if failed.any():
        detail += (f"; {int(failed.sum())} scenes stopped early "
                   f"(first: scene {int(np.argmax(failed))})")
    return BatchResult(V, events, stuck, status, status_message(status, detail),
                       budget_clock() - started, at_probe if t_probe is not None else None)
