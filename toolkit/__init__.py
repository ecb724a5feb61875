"""Active Contacts Toolkit: controllable friction from contacts that move at their own speeds.

The public API is what this module exports; everything else is private. Importing it loads
numpy and scipy only: casadi, cvxpy, filterpy and matplotlib are imported by the stages
that need them.
"""

from __future__ import annotations

import importlib
from typing import Any

#: The public API: each name and the module it comes from, imported at its first use, so
#: that ``import toolkit`` (and the command line's start) loads only what is used.
_EXPORTS: dict[str, str] = {
    "AllocationResult": ".allocation", "AllocationStatus": ".allocation", "EquilibriumSpeed": ".allocation",
    "ForceCurve": ".allocation", "FrictionFraction": ".allocation", "Projection": ".allocation",
    "Viscosity": ".allocation", "allocate": ".allocation", "evaluate_errors": ".allocation",
    "ContactDistribution": ".model", "ContactModel": ".model", "ContactSet": ".model", "Encoder": ".model",
    "Motors": ".model", "PiecewiseConstant": ".model", "Plant": ".model", "Staircase": ".model",
    "OutputError": ".errors", "ParameterError": ".errors", "ParameterTypeError": ".errors",
    "SceneError": ".errors", "SceneFileNotFoundError": ".errors", "SolverError": ".errors",
    "ToolkitError": ".errors",
    "plot_force_curve": ".plots", "plot_mean_median": ".plots", "plot_median_law": ".plots",
    "plot_outliers": ".plots", "plot_precision": ".plots", "plot_ratio_histogram": ".plots",
    "plot_schedule": ".plots", "plot_simulation": ".plots", "plot_summary_comparison": ".plots",
    "plot_sweep": ".plots", "plot_viscosity_check": ".plots", "plot_friction_fraction_check": ".plots",
    "MAX_SCENE_BYTES": ".scenes.spec", "Scene": ".scenes.spec", "dumps_scene": ".scenes.spec",
    "load_scene": ".scenes.spec",
    "Clip": ".scenes.build", "SceneObjects": ".scenes.build", "build_scene": ".scenes.build",
    "copy_designs": ".scenes.designs", "design_names": ".scenes.designs", "load_design": ".scenes.designs",
    "Braking": ".schedule", "ScheduleResult": ".schedule", "ScheduleStatus": ".schedule",
    "SpeedTrajectory": ".schedule", "braking_time": ".schedule", "design_schedule": ".schedule",
    "CAROUSEL": ".model.carousel", "CarouselHardware": ".model.carousel",
    "carousel_startup_plant": ".model.carousel",
    "PARAMETERS": ".model.parameters", "Origin": ".model.parameters", "Parameter": ".model.parameters",
    "parameter": ".model.parameters",
    "PrecisionReport": ".analysis.precision", "PrecisionRow": ".analysis.precision",
    "precision_report": ".analysis.precision",
    "ClosedLoopResult": ".loop.closed_loop", "simulate_closed_loop": ".loop.closed_loop",
    "ForceDrive": ".controllers", "FrictionBrake": ".controllers", "OpenLoop": ".controllers",
    "SpeedHold": ".controllers", "VirtualViscosity": ".controllers",
    "BatchResult": ".simulation", "Budget": ".simulation", "Event": ".simulation",
    "ExactState": ".simulation", "ExactStep": ".simulation", "SimulationResult": ".simulation",
    "SimulationStatus": ".simulation", "advance": ".simulation", "simulate": ".simulation",
    "simulate_batch": ".simulation",
    "StabilityCase": ".analysis.stability", "StabilityReport": ".analysis.stability",
    "stability_suite": ".analysis.stability",
    "Shortfall": ".shortfall",
    "CurveSamples": ".scenes.study", "CurveStep": ".scenes.study", "StudyResult": ".scenes.study",
    "force_curve": ".scenes.study", "run_study": ".scenes.study",
    "SweepResult": ".sweeps", "sweep": ".sweeps",
    "MeanMedian": ".experiments", "MedianLaw": ".experiments", "Outliers": ".experiments",
    "ResidualFriction": ".experiments",
    "EncoderRecord": ".model.sensors", "EncoderSample": ".model.sensors", "Sensors": ".model.sensors",
    "measure": ".model.sensors", "record_simulation": ".model.sensors",
    "CentralDifference": ".estimation", "EstimationResult": ".estimation", "Estimator": ".estimation",
    "EstimatorModel": ".estimation", "KalmanEstimator": ".estimation", "RTSSmoother": ".estimation",
    "UnscentedEstimator": ".estimation", "WheelDifference": ".estimation", "chi2_band": ".estimation",
    "AdaptiveKalman": ".estimation", "AdaptiveWindow": ".estimation", "AlphaBetaTracker": ".estimation",
    "ModelPrior": ".estimation", "NominalKalman": ".estimation", "build_estimator": ".estimation",
    "BrakeScenario": ".analysis.scenarios", "carousel_brake_scenario": ".analysis.scenarios",
    "ROBUSTNESS_CASES": ".analysis.robustness", "loop_robustness": ".analysis.robustness",
    "robustness_table": ".analysis.robustness",
    "TrueWorld": ".model.truth", "WorldTruth": ".model.truth", "realize": ".model.truth",
    "read_record_csv": ".model.record_io", "write_record_csv": ".model.record_io",
}
_SUBMODULES = ("sweeps",)

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


def __getattr__(name: str) -> Any:
    """Import a public name (or the ``sweeps`` module) at its first use (PEP 562)."""
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
