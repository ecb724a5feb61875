"""Active Contacts Toolkit: controllable friction from contacts that move at their own speeds.

The public API is what this module exports; everything else is private. Importing it loads
numpy and scipy only: casadi, cvxpy, filterpy and matplotlib are imported by the stages
that need them.
"""

from __future__ import annotations

from .allocation import (
    AllocationResult,
    AllocationStatus,
    EquilibriumSpeed,
    ForceCurve,
    FrictionFraction,
    Projection,
    Viscosity,
    allocate,
    evaluate_errors,
)
from .model import ContactDistribution, ContactModel, ContactSet, Encoder, Motors, PiecewiseConstant, Plant, Staircase
from .errors import (
    OutputError,
    ParameterError,
    ParameterTypeError,
    SceneError,
    SceneFileNotFoundError,
    SolverError,
    ToolkitError,
)
from .plots import (plot_force_curve, plot_mean_median, plot_median_law, plot_outliers, plot_precision,
                    plot_ratio_histogram, plot_schedule, plot_simulation, plot_summary_comparison, plot_sweep,
                    plot_viscosity_check, plot_friction_fraction_check)
from .scenes.spec import MAX_SCENE_BYTES, Scene, dumps_scene, load_scene
from .scenes.build import Clip, SceneObjects, build_scene
from .scenes.designs import copy_designs, design_names, load_design
from .schedule import Braking, ScheduleResult, ScheduleStatus, SpeedTrajectory, braking_time, design_schedule
from .model.carousel import CAROUSEL, CarouselHardware, carousel_startup_plant
from .model.parameters import PARAMETERS, Origin, Parameter, parameter
from .analysis.precision import PrecisionReport, PrecisionRow, precision_report
from .loop.closed_loop import ClosedLoopResult, simulate_closed_loop
from .controllers import ForceDrive, FrictionBrake, OpenLoop, SpeedHold, VirtualViscosity
from .simulation import (BatchResult, Budget, Event, ExactState, ExactStep, SimulationResult,
                         SimulationStatus, advance, simulate, simulate_batch)
from .analysis.stability import StabilityCase, StabilityReport, stability_suite
from .shortfall import Shortfall
from .scenes.study import CurveSamples, CurveStep, StudyResult, force_curve, run_study
from . import sweeps
from .sweeps import SweepResult, sweep
from .experiments import MeanMedian, MedianLaw, Outliers, ResidualFriction

# sensors and estimation (filterpy is imported only where a filter is built)
from .model.sensors import EncoderRecord, EncoderSample, Sensors, measure, record_simulation
from .estimation import (CentralDifference, EstimationResult, Estimator, EstimatorModel, KalmanEstimator,
                         RTSSmoother, UnscentedEstimator, WheelDifference, chi2_band, AdaptiveKalman, AdaptiveWindow,
                         AlphaBetaTracker, ModelPrior, NominalKalman, build_estimator)
from .analysis.scenarios import BrakeScenario, carousel_brake_scenario
from .analysis.robustness import ROBUSTNESS_CASES, loop_robustness, robustness_table
from .model.truth import TrueWorld, WorldTruth, realize
from .model.record_io import read_record_csv, write_record_csv

__version__ = "0.1.0"

__all__ = [
    # contact model
    "ContactDistribution", "ContactModel", "ContactSet", "Staircase", "CurveSamples", "CurveStep",
    "force_curve",
    # plant and simulation
    "Plant", "Motors", "PiecewiseConstant", "CAROUSEL", "CarouselHardware",
    "simulate", "SimulationResult", "SimulationStatus", "Budget", "Event",
    "simulate_batch", "BatchResult", "advance", "ExactState", "ExactStep",
    # work-precision report and stability suite
    "precision_report", "PrecisionReport", "PrecisionRow", "carousel_startup_plant",
    # the non-ideal carousel's parameters and where each value comes from
    "PARAMETERS", "Parameter", "Origin", "parameter",
    "stability_suite", "StabilityReport", "StabilityCase",
    # allocation (inverse design)
    "allocate", "evaluate_errors", "AllocationResult", "AllocationStatus", "Projection",
    "ForceCurve", "Viscosity", "FrictionFraction", "EquilibriumSpeed",
    # schedules (time-varying designs)
    "design_schedule", "ScheduleResult", "ScheduleStatus", "SpeedTrajectory", "Braking", "braking_time",
    # sensors and estimation
    # closed loop and controllers
    "simulate_closed_loop", "ClosedLoopResult", "OpenLoop", "VirtualViscosity", "SpeedHold",
    "FrictionBrake", "ForceDrive",
    "Encoder", "Sensors", "EncoderRecord", "EncoderSample", "measure", "record_simulation",
    "Estimator", "EstimationResult", "EstimatorModel", "CentralDifference", "WheelDifference",
    "KalmanEstimator", "RTSSmoother", "UnscentedEstimator", "chi2_band", "carousel_brake_scenario",
    "AdaptiveKalman", "NominalKalman", "AdaptiveWindow", "AlphaBetaTracker", "ModelPrior", "build_estimator",
    "WorldTruth", "TrueWorld", "realize", "read_record_csv", "write_record_csv",
    "ROBUSTNESS_CASES", "robustness_table", "loop_robustness",
    # sweeps (pandas is imported with the first sweep; dask only for a cluster)
    "sweep", "SweepResult", "MedianLaw", "MeanMedian", "Outliers", "ResidualFriction",
    # plots (matplotlib is imported when one is drawn)
    "plot_force_curve", "plot_simulation", "plot_schedule", "plot_precision", "plot_median_law",
    "plot_ratio_histogram", "plot_mean_median", "plot_outliers", "plot_summary_comparison", "plot_sweep",
    "plot_viscosity_check", "plot_friction_fraction_check",
    # scenes and studies
    "Scene", "load_scene", "dumps_scene", "MAX_SCENE_BYTES", "build_scene", "SceneObjects", "StudyResult",
    "run_study", "Shortfall", "design_names", "load_design", "copy_designs",
    "Clip",
    # errors
    "ParameterError", "ParameterTypeError", "SceneError", "SceneFileNotFoundError", "SolverError",
    "OutputError", "ToolkitError",
    "__version__",
]
