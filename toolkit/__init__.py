"""Active Contacts Toolkit: controllable friction from contacts that move at their own speeds.

The public API is what this module exports; everything else is private. Importing it loads
numpy and scipy only: casadi, cvxpy, filterpy and matplotlib are imported by the stages
that need them.
"""

from __future__ import annotations

from .contacts import ContactDistribution, ContactModel, ContactSet, Staircase
from .errors import (
    ParameterError,
    ParameterTypeError,
    SceneError,
    SceneFileNotFoundError,
    SolverError,
    ToolkitError,
)
from .plant import Motors, PiecewiseConstant, Plant
from .plots import plot_force_curve, plot_precision, plot_simulation
from .scene import Scene, dumps_scene, load_scene
from .sensors import Encoder
from .simulation import Budget, Event, SimulationResult, Status, simulate
from .study import ForceCurve, StudyResult, force_curve, run_study

__version__ = "0.1.0"

__all__ = [
    # contact model
    "ContactDistribution", "ContactModel", "ContactSet", "Staircase", "ForceCurve", "force_curve",
    # plant and simulation
    "Plant", "Motors", "PiecewiseConstant", "simulate", "SimulationResult", "Status", "Budget", "Event",
    # sensors
    "Encoder",
    # plots (matplotlib is imported when one is drawn)
    "plot_force_curve", "plot_simulation", "plot_precision",
    # scenes and studies
    "Scene", "load_scene", "dumps_scene", "StudyResult", "run_study",
    # errors
    "ParameterError", "ParameterTypeError", "SceneError", "SceneFileNotFoundError", "SolverError",
    "ToolkitError",
    "__version__",
]
