"""Planar active contacts for locomotion planners (imported explicitly: ``import toolkit.planar``).

Legs and contact patches that slip in the plane: the force and torque they put on a body for
a body twist (:class:`PlanarContactSet`), continuous contact regions by quadrature with an
error bound (:mod:`~toolkit.planar.regions`), the certified equilibrium twist
(:mod:`~toolkit.planar.equilibrium`), the simulation of a planar body through slip and stick
(:mod:`~toolkit.planar.simulation`, also through :func:`toolkit.simulate`), gaits
(:mod:`~toolkit.planar.gaits`) and leg-velocity allocation (:mod:`~toolkit.planar.allocation`).
The 1-D toolkit is the special case where everything lies on a line (docs/planar.md).
Importing this package loads numpy and scipy only; cvxpy and casadi are imported by the
methods that use them.
"""

from __future__ import annotations

from .contacts import LineReduction, PlanarContactSet, WrenchSet, geometric_median, limit_factors, wrench_batch
from .equilibrium import EquilibriumStatus, PlanarEquilibrium, solve_equilibrium, weiszfeld
from .regions import (CurveRegion, DiscRegion, Quadrature, RegionWrench, RingRegion, disc_force_torque,
                      ring_force_torque, terminal_ratio)
from .simulation import PLANAR_METHODS, PlanarPlant, PlanarSimulationResult, simulate_planar
from .gaits import (AveragedModel, CycleMotion, Gait, GaitComparison, averaged_model, compare_averaged,
                    dynamic_cycles, force_twist_map, quasi_static_cycle, serpenoid, tripod_gait)
from .precision import PlanarPrecisionReport, PlanarPrecisionRow, precision_report
from .plots import plot_planar_precision, plot_sliding_disc
from ._warmup import warm_up
from .allocation import (PlanarAllocationResult, PlanarAllocationStatus, allocate_resistance, allocate_twist,
                         infeasibility_margin)

__all__ = [
    "PlanarContactSet", "WrenchSet", "LineReduction", "limit_factors", "wrench_batch",
    "PlanarEquilibrium", "EquilibriumStatus", "solve_equilibrium", "geometric_median", "weiszfeld",
    "DiscRegion", "RingRegion", "CurveRegion", "Quadrature", "RegionWrench", "disc_force_torque",
    "ring_force_torque", "terminal_ratio",
    "PlanarPlant", "PlanarSimulationResult", "simulate_planar", "PLANAR_METHODS",
    "Gait", "CycleMotion", "AveragedModel", "GaitComparison", "tripod_gait", "serpenoid",
    "force_twist_map", "quasi_static_cycle", "dynamic_cycles", "averaged_model", "compare_averaged",
    "allocate_twist", "allocate_resistance", "infeasibility_margin", "PlanarAllocationResult",
    "PlanarAllocationStatus", "precision_report", "PlanarPrecisionReport", "PlanarPrecisionRow",
    "plot_sliding_disc", "plot_planar_precision", "warm_up",
]
