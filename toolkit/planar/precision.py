"""Work-precision report of the planar simulation: each method's error against the exact one.

For a plant with a closed form (:func:`toolkit.planar.simulation.simulate_planar`,
``method="exact"``: a passive disc, annulus or ring, or a 1-D line), run Moreau-Jean at
several steps and the regularized law at several widths, measure ``max(|V - V_exact|,
R |omega - omega_exact|)`` over common times, and the run time (the faster of two runs):
error against cost, as :mod:`toolkit.analysis.precision` does in 1-D. Pure numerics: no files,
no matplotlib.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

import dataclasses

from ..errors import ParameterError, as_int, parameter_message
from .simulation import PlanarPlant, PlanarSimulationResult, simulate_planar

__all__ = ["PlanarPrecisionRow", "PlanarPrecisionReport", "precision_report"]


@dataclass(frozen=True)
class PlanarPrecisionRow:
    """One method at one setting.

    Attributes
    ----------
    method, setting : str
    max_error : float, m/s
        ``max(|V - V_exact|, L |omega - omega_exact|)`` over the report's times (``L`` the
        plant's largest contact distance from the centre of mass).
    stop_error : float, s
        ``|stop time - exact stop time|`` (``inf`` when the run did not come to rest).
    wall_time : float, s
        The faster of two runs.
    steps : int
    status : str
        The run's :class:`~toolkit.simulation.SimulationStatus` name.
    """

    method: str
    setting: str
    max_error: float
    stop_error: float
    wall_time: float
    steps: int
    status: str

    def to_dict(self) -> dict[str, Any]:
        """JSON form (``inf`` as the string ``"inf"``)."""
        return {k: ("inf" if isinstance(v, float) and math.isinf(v) else v)
                for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class PlanarPrecisionReport:
    """Rows against the exact reference run on ``times``."""

    rows: tuple[PlanarPrecisionRow, ...]
    reference: PlanarSimulationResult
    times: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        """JSON form: the reference's method, setting and wall time, and the rows."""
        return {"reference": {"method": self.reference.method, "setting": self.reference.setting,
                              "wall_time": self.reference.wall_time, "stop_time": self.reference.stop_time},
                "rows": [row.to_dict() for row in self.rows]}


def _arm(plant: PlanarPlant) -> float:
    return plant.contacts_at(0.0).arm or 1.0


def precision_report(plant: PlanarPlant, t_end: float, *, v0: Any = 0.0, omega0: float = 0.0,
                     steps: tuple[float, ...] = (4e-3, 2e-3, 1e-3),
                     resolutions: tuple[int, ...] | None = None,
                     epsilons: tuple[float, ...] = (1e-2, 1e-3), points: int = 201) -> PlanarPrecisionReport:
    """Moreau-Jean (``steps``, s, each with the matching entry of ``resolutions``: the
    region's quadrature, whose error the stepping error cannot go below) and the regularized
    law (``epsilons``, m/s; Radau at rtol 1e-8, at the plant's own resolution) against the
    exact method on ``points`` uniform times over ``[0, t_end]``."""
    points = as_int(points, "points", "precision_report", low=2)
    if resolutions is not None and len(resolutions) != len(steps):
        raise ParameterError(parameter_message("resolutions", "precision_report",
                                               f"have one entry per step ({len(steps)})", list(resolutions)))
    times = np.linspace(0.0, t_end, points)
    try:
        reference = simulate_planar(plant, t_end, v0=v0, omega0=omega0, method="exact", t_eval=times)
    except ParameterError as error:
        if error.parameter != "method":
            raise
        raise ParameterError(parameter_message(
            "plant", "precision_report", "have a closed form for the exact reference (contacts and "
            "motion on one line through the centre of mass, or a passive uniform disc or ring "
            "centred on it, without outside force or drag)",
            f"a plant on {type(plant.contacts).__name__}")) from None
    L = _arm(plant)
    rows = []
    runs = [("moreau", {"step": h}, None if resolutions is None else resolutions[k])
            for k, h in enumerate(steps)] + [("smooth", {"epsilon": e}, None) for e in epsilons]
    for method, options, resolution in runs:
        target = plant if resolution is None else dataclasses.replace(plant, resolution=resolution)
        best = None
        for _ in range(2):
            run = simulate_planar(target, t_end, v0=v0, omega0=omega0, method=method, t_eval=times, **options)
            if best is None or run.wall_time < best.wall_time:
                best = run
        run = best
        k = run.t.size
        dv = np.hypot(*(run.velocity - reference.velocity[:k]).T)
        dw = np.abs(run.omega - reference.omega[:k]) * L
        error = float(np.max(np.maximum(dv, dw))) if k == times.size else math.inf
        if reference.stop_time is None:
            stop_error = math.nan
        elif run.stop_time is not None:
            stop_error = abs(run.stop_time - reference.stop_time)
        else:
            # A method that never comes to rest exactly: when it is slower than 1e-9 m/s.
            rest = np.flatnonzero(np.maximum(run.speed, np.abs(run.omega) * L) <= 1e-9)
            stop_error = abs(run.t[rest[0]] - reference.stop_time) if rest.size else math.inf
        setting = run.setting if resolution is None else f"{run.setting} resolution={resolution}"
        rows.append(PlanarPrecisionRow(method, setting, error, float(stop_error), run.wall_time,
                                       run.steps, run.status.name))
    return PlanarPrecisionReport(tuple(rows), reference, times)
