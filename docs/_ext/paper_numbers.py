"""The numbers of the validation page, computed by the toolkit when the site is built.

Each value is a formatted string under a name; the page writes ``{{ name }}`` (a MyST
substitution) where the number goes, so no number of the comparison with the paper is typed
in: the designs' sweeps, the bootstraps and the prediction checks give them at every build.
``python docs/_ext/paper_numbers.py`` prints them.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from itertools import combinations
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
DESIGNS = ROOT / "designs"


def _sweep(name: str):
    from toolkit.scenes.spec import load_scene
    from toolkit.scenes.study import sweep_scene

    return sweep_scene(load_scene(DESIGNS / f"{name}.toml"))


def _boot(result, statistic: str):
    from toolkit.sweeps import bootstrap

    return bootstrap(result, statistic, resamples=1000, seed=0)


def paper_table() -> dict[str, str]:
    """The rows of the table against the paper: the designs' sweeps and their bootstraps."""
    import toolkit as tk

    out: dict[str, str] = {}
    for key, design in (("ideal", "median_law"), ("nonideal", "median_law_nonideal")):
        boot = _boot(_sweep(design), "slope")
        out[f"slope_{key}"], out[f"slope_{key}_se"] = f"{boot.value:.3f}", f"{boot.std:.3f}"
        if key == "nonideal":
            out["slope_short"] = f"{(1.065 - boot.value) / boot.std:.1f}"
    out["slope_population"] = f"{tk.experiments.ideal_median_law_slope(10):.4f}"
    mean_run = _sweep("mean_median")
    mean = mean_run.summary
    out["mean_median_slope"] = f"{mean['slope_median']:.3f}"
    out["mean_median_slope_se"] = f"{_boot(mean_run, 'slope_median').std:.3f}"
    out["mean_median_range"] = f"{mean['median_range']:.3f}"
    # the mean is held: its range is zero but for rounding (below 1e-12 m/s printed as 0)
    out["mean_median_mean_range"] = f"{mean['mean_range']:.0e}" if abs(mean["mean_range"]) >= 1e-12 else "0"
    held = _sweep("median_held").summary
    out["median_held_mean_range"] = f"{held['mean_range']:.3f}"
    out["median_held_speed_range"] = f"{held['speed_range']:.3g}"
    outliers = _sweep("outliers")
    p = outliers.summary["unaffected_fraction"]
    out["outliers_unaffected"] = f"{100 * p:.0f}"
    out["outliers_unaffected_se"] = f"{100 * np.sqrt(p * (1 - p) / outliers.runs):.0f}"
    out["outliers_runs"] = f"{outliers.runs}"
    out["outliers_rule"] = f"{100 * outliers.summary['rule_agreement']:.0f}"
    out["outliers_threshold"] = f"{outliers.summary['threshold_amplitude']:.3f}"
    residual = _sweep("residual_friction")
    out["reduction"] = f"{100 * residual.summary['reduction']:.1f}"
    out["reduction_se"] = f"{100 * residual.summary['mu_ratio_std'] / np.sqrt(residual.runs):.2f}"
    out["reduction_runs"] = f"{residual.runs}"
    out["mu_ratio_sd"] = f"{residual.summary['mu_ratio_std']:.3f}"
    P = tk.PARAMETERS
    out["bearing_drag"] = f"{P['bearing_drag'].value:.2f}"
    # the carousel's F_tot (ten wheels of 0.2 N): the bearing's friction as a share of it
    out["bearing_friction_share"] = f"{100 * P['bearing_friction'].value / 2.0:.0f}"
    return out


def viscosity() -> dict[str, str]:
    """The viscosity constant of ten contacts, ideal and in the loop, and the friction fraction."""
    from toolkit.predictions import (Apparatus, FrictionFractionProblem, ViscosityProblem,
                                     friction_fraction_check, viscosity_check)

    out: dict[str, str] = {}
    for mode in ("ideal", "loop"):
        check = viscosity_check(ViscosityProblem(Apparatus.carousel(), mode))
        for fit in check.fits:
            name = f"{mode}_{fit.definition}"
            out[f"k_{name}"], out[f"k_{name}_predicted"] = f"{fit.k_fit:.3f}", f"{fit.k_predicted:.3f}"
            out[f"r2_{name}"] = f"{fit.r2:.3f}"
            out[f"row_{name}"] = f"{fit.k_fit:.4f} / {fit.k_predicted:.4f} = {fit.ratio:.4f} ({fit.r2:.4f})"
        out["viscosity_runs"] = f"{fit.runs}"
        check = friction_fraction_check(FrictionFractionProblem(Apparatus.carousel(), mode))
        fraction = np.max(np.abs(check.mu_ratio - check.n / 5))
        finite = np.isfinite(check.dT_predicted)
        transition = np.max(np.abs(check.dT[finite] / check.dT_predicted[finite] - 1))
        out[f"fraction_{mode}_error"] = f"{fraction:.1g}"
        out[f"dt_{mode}_error"] = f"{100 * transition:.2g}"
    return out


def gaps() -> dict[str, str]:
    """The paragraphs under the table (notebooks/gaps.ipynb at the paper's sizes)."""
    import toolkit as tk
    from toolkit.experiments import ResidualFriction, carousel_wheels
    from toolkit.sweeps import run_keys

    P = tk.PARAMETERS
    out: dict[str, str] = {}
    spread, k, seed = P["friction_spread"].value, P["compliance"], P["wheel_seed"].value
    slope = lambda **model: tk.sweep(tk.MedianLaw(**model), 660, seed=660).summary["slope"]  # noqa: E731
    low, high = (slope(compliance=c) for c in k.bounds)
    out["compliance_slope_low"], out["compliance_slope_high"] = f"{low:.2f}", f"{high:.2f}"
    means, sds = [], []
    for model in (dict(friction_spread=spread), dict(friction_spread=spread, compliance=k.bounds[1]),
                  dict(friction_spread=0.1)):
        s = [slope(wheel_seed=w, **model) for w in range(40)]
        means.append(np.mean(s))
        sds.append(np.std(s, ddof=1))
    out["carousels_mean_low"], out["carousels_mean_high"] = f"{min(means):.2f}", f"{max(means):.2f}"
    out["carousels_sd_low"], out["carousels_sd_high"] = f"{min(sds):.3f}", f"{max(sds):.3f}"
    scan = [np.mean([slope(wheel_seed=w, friction_spread=s) for w in range(8)])
            for s in (0.02, 0.05, 0.10, 0.20, 0.50)]
    out["spread_scan_low"], out["spread_scan_high"] = f"{min(scan):.3f}", f"{max(scan):.3f}"
    base = _boot(_sweep("median_law_nonideal"), "slope")
    bias, radius = base.map(lambda s: 1.065 / s - 1), base.map(lambda s: s / 1.065 - 1)
    carousel = dict(friction_spread=spread, compliance=k.value, settle_time=400.0)
    others = [1.065 / slope(wheel_seed=w, **carousel) - 1 for w in range(8)]
    lo, hi = bias.interval()
    for name, value in (("bias", bias.value), ("bias_se", bias.std), ("bias_low", lo), ("bias_high", hi),
                        ("bias_carousels_low", min(others)), ("bias_carousels_high", max(others))):
        out[name] = f"{100 * value:.1f}"
    out["bias_mm"] = f"{45 * bias.value:.1f}"
    out["speed_high"], out["speed_high_se"] = f"{-100 * radius.value:.1f}", f"{100 * radius.std:.1f}"
    out["radius_short_mm"] = f"{-266 * radius.value:.0f}"
    out["biased_speed"] = f"{0.35 * (1 + bias.value):.3f}"
    out["ten_turns"] = f"{2 * np.pi * 0.045 * 10:.3f}"
    out["ten_turns_biased"] = f"{2 * np.pi * 0.045 * 10 * (1 + bias.value):.3f}"
    rise = P["motor_speed_rise"]
    out["rise_slope"], out["rise_slope_low"], out["rise_slope_high"] = (
        f"{base.value * (1 + r):.3f}" for r in (rise.value, *rise.bounds))
    experiment = tk.MedianLaw(compliance=k.value, friction_spread=spread, wheel_seed=seed)
    seeds = run_keys(660, 0, 660)
    r = experiment.release_rise(seeds)[np.abs(experiment.draw(seeds)[1]) >= 0.1]
    out["release_unchanged"] = f"{100 * np.mean(np.abs(r) < 1e-12):.0f}"
    out["release_in_range"] = f"{100 * np.mean((r >= rise.bounds[0]) & (r <= rise.bounds[1])):.1f}"
    _, loads = carousel_wheels(np.random.default_rng(seed), 10, 0.2, spread)
    splits = [abs(2 * loads[list(c)].sum() - loads.sum()) / loads.sum() for c in combinations(range(10), 5)]
    one = tk.sweep(ResidualFriction(n=0, friction_spread=spread, wheel_seed=seed), 1, seed=0).summary["mu_ratio"]
    out["splits_low"], out["splits_high"], out["splits_first"] = (f"{min(splits):.3f}", f"{max(splits):.3f}",
                                                                  f"{one:.3f}")
    wheels = ResidualFriction(n=0, friction_spread=spread, wheel_seed=seed).contacts(run_keys(0, 0, 1))
    out["band_force"] = f"{float(wheels.force(0.2)):.3f}"
    out["bearing_friction"] = f"{P['bearing_friction'].value:.2f}"
    out["drag_force"] = f"{0.2 * P['bearing_drag'].value:.3f}"
    laws = []
    for model in (dict(bearing_friction=P["bearing_friction"].value), dict(bearing_drag=P["bearing_drag"].value)):
        n1, n5 = (tk.sweep(ResidualFriction(n=n, **model), 1, seed=0).summary for n in (1, 5))
        laws.append(n1["mu_ratio"] * n1["dT_median"] / (n5["mu_ratio"] * n5["dT_median"]) - 1)
    out["friction_law_longer"], out["drag_law_longer"] = (f"{100 * x:.0f}" for x in laws)
    return out


#: Every group of numbers, in the order they are computed.
GROUPS: tuple[Callable[[], dict[str, str]], ...] = (paper_table, viscosity, gaps)


def values(log: Callable[[str], None] = print) -> dict[str, str]:
    """Every number of the validation page under its name, formatted as the page prints it."""
    out: dict[str, str] = {}
    for group in GROUPS:
        start = time.perf_counter()
        out.update(group())
        log(f"paper_numbers: {group.__name__} in {time.perf_counter() - start:.1f} s")
    return out


def _config_inited(app, config) -> None:
    from sphinx.util import logging

    logger = logging.getLogger(__name__)
    config.myst_substitutions = {**config.myst_substitutions, **values(logger.info)}


def setup(app):
    app.connect("config-inited", _config_inited)
    return {"parallel_read_safe": True, "parallel_write_safe": True}


if __name__ == "__main__":
    for name, value in values().items():
        print(f"{name} = {value}")
