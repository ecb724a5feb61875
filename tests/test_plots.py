"""Tests of toolkit.plots: the artists drawn carry the numbers of the results they show.

Every figure is drawn with the Agg backend from small real results built through the public
API; the assertions read the drawn lines, patches and texts back. Tolerances: the plotted
data are the results' own arrays passed through numpy once, so they agree to rounding
(``atol=1e-12`` m/s); closed forms are checked at ``rtol=1e-12``.
"""

from __future__ import annotations

import dataclasses

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

import toolkit as tk
from toolkit import plots
from toolkit.analysis.precision import MethodSetting, work_precision_curves

VMAX = 0.35                      # docs/physics.md section 5
MOTORS = tk.Motors(lag=0.01, speed_limits=(-VMAX, VMAX))
SCENE = "plot_scene"


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def carousel(speeds, motors=MOTORS) -> tk.Plant:
    return tk.Plant(tk.ContactSet(speeds, np.full(len(speeds), 0.2)), mass=1.0, motors=motors)


def exact_check(plant: tk.Plant, result: tk.ScheduleResult, v0: float) -> tk.SimulationResult:
    return tk.simulate(dataclasses.replace(plant, commands=result.as_commands()),
                       float(result.times[-1]), v0=v0, t_eval=result.times)


@pytest.fixture(scope="module")
def braking():
    plant = carousel([0.3] * 10)
    result = tk.design_schedule(plant, tk.Braking(0.0), v0=0.3)
    return plant, result, exact_check(plant, result, 0.3)


@pytest.fixture(scope="module")
def tracking():
    plant = carousel(np.zeros(10))
    t = np.linspace(0.0, 0.3, 31)
    result = tk.design_schedule(plant, tk.SpeedTrajectory(t, 0.1 * np.sin(2 * np.pi * t)), v0=0.0)
    return plant, result, exact_check(plant, result, 0.0)


def by_gid(ax, gid):
    return [a for a in (*ax.lines, *ax.patches, *ax.texts) if a.get_gid() == gid]


def notes(ax) -> list[str]:
    return [text.get_text() for text in by_gid(ax, "note")]


# -- schedule ---------------------------------------------------------------------------------
def test_schedule_draws_the_target_on_top_and_titles_the_scene(tracking):
    plant, result, check = tracking
    top, bottom = plots.plot_schedule(result, check, plant=plant, title=SCENE)
    (target,) = by_gid(top, "target")
    others = [line for line in top.lines if line is not target and len(line.get_xdata())]
    assert others and all(target.get_zorder() > line.get_zorder() for line in others)
    assert top.get_title().startswith(SCENE)
    assert top.figure is bottom.figure


def test_schedule_error_panel_is_the_exact_tracking_error_against_its_bounds(tracking):
    plant, result, check = tracking
    _, bottom = plots.plot_schedule(result, check, plant=plant, title=SCENE)
    (error,) = by_gid(bottom, "error")
    np.testing.assert_allclose(error.get_xdata(), result.times, rtol=0, atol=0)
    np.testing.assert_allclose(error.get_ydata(), np.abs(result.exact_body_speed - result.reference),
                               rtol=0, atol=1e-12)
    # Certified: |V_pred - target| + prediction_bound bounds the exact error at every time.
    (certified,) = by_gid(bottom, "certified")
    assert np.all(np.asarray(error.get_ydata()) <= np.asarray(certified.get_ydata()) + 1e-12)
    # The tracking lower bound is a horizontal line at its value, and the exact sup error
    # (between controller times too) does not go below it (the certificate).
    (lower,) = by_gid(bottom, "lower bound")
    np.testing.assert_allclose(lower.get_ydata(), [result.lower_bound] * 2, rtol=0, atol=0)
    (dense,) = by_gid(bottom, "dense error")
    assert np.max(dense.get_ydata()) >= result.lower_bound - 1e-12
    assert bottom.get_yscale() == "log"


def test_fast_braking_target_is_the_minimum_time_curve(braking):
    plant, result, check = braking
    top, bottom = plots.plot_schedule(result, check, plant=plant, title=SCENE)
    (target,) = by_gid(top, "target")
    t, V = np.asarray(target.get_xdata()), np.asarray(target.get_ydata())
    # Not the goal from t = 0: the body holds v0 for the first period, then brakes; it
    # reaches the goal at the closed-form minimum time and stays there.
    assert V[0] == 0.3 and V[1] == 0.3 and t[1] == pytest.approx(result.period, rel=1e-12)
    assert np.all(np.diff(V) <= 0)
    assert t[np.argmax(V <= 0.0)] == pytest.approx(result.minimum_time, rel=1e-12, abs=0)
    # No schedule is closer to the goal than this curve (comparison principle): the exact
    # error at the controller times is above it (up to the certificate's rounding).
    (error,) = by_gid(bottom, "error")
    curve_at = np.interp(result.times, t, V)
    assert np.all(np.asarray(error.get_ydata()) >= curve_at - 1e-9)


def test_fast_braking_with_ideal_motors_is_the_straight_line_of_full_deceleration():
    motors = tk.Motors(speed_limits=(-VMAX, VMAX))
    plant = carousel([0.3] * 10, motors=motors)
    result = tk.design_schedule(plant, tk.Braking(0.0), v0=0.3)
    top, _ = plots.plot_schedule(result, plant=plant)
    (target,) = by_gid(top, "target")
    t, V = np.asarray(target.get_xdata()), np.asarray(target.get_ydata())
    # Ideal motors, no hold: V*(t) = v0 - (F_tot / m) t with F_tot / m = 2 m/s^2 until 0.15 s.
    braking = t <= 0.15
    np.testing.assert_allclose(V[braking], 0.3 - 2.0 * t[braking], rtol=0, atol=1e-12)


def test_fast_braking_without_the_plant_shows_the_goal_from_the_minimum_time(braking):
    _, result, _ = braking
    top, _ = plots.plot_schedule(result)
    (target,) = by_gid(top, "target")
    assert target.get_xdata()[0] == result.minimum_time
    np.testing.assert_array_equal(target.get_ydata(), [0.0, 0.0])


def test_figure_png_renders_both_panels(braking):
    plant, result, check = braking
    png = plots.figure_png(plots.plot_schedule(result, check, plant=plant, title=SCENE))
    assert png[:8] == b"\x89PNG\r\n\x1a\n"


# -- simulation -------------------------------------------------------------------------------
def test_simulation_shades_the_zero_force_band_and_keeps_the_status_out_of_the_title():
    plant = tk.carousel_startup_plant(0, n=10)             # even N: a zero-force band
    result = tk.simulate(plant, 1.0, v0=0.0)
    ax = plots.plot_simulation(result, plant=plant, title=SCENE)
    lo, hi = plant.equilibrium()
    assert hi > lo
    (band,) = by_gid(ax, "equilibrium")
    box = band.get_bbox()                                  # x in axes, y in data coordinates
    assert (box.y0, box.y1) == pytest.approx((lo, hi), rel=0, abs=1e-15)
    assert ax.get_title().startswith(SCENE)
    assert result.status.value not in ax.get_title()
    assert notes(ax) == []                                 # success: no status note, no thinning


def test_simulation_draws_a_point_equilibrium_as_a_line():
    plant = tk.carousel_startup_plant(0, n=11)             # odd N: a single point
    result = tk.simulate(plant, 1.0, v0=0.0)
    ax = plots.plot_simulation(result, plant=plant)
    lo, hi = plant.equilibrium()
    assert lo == hi
    (line,) = by_gid(ax, "equilibrium")
    np.testing.assert_array_equal(line.get_ydata(), [lo, lo])


def test_simulation_thins_many_contacts_and_notes_a_stopped_run():
    rng = np.random.default_rng(1)
    n = 2001
    plant = tk.Plant(tk.ContactSet(rng.uniform(-VMAX, VMAX, n), np.full(n, 2.0 / n)), mass=1.0)
    result = tk.simulate(plant, 0.5, method="rk45", friction="sign",
                         budget=tk.Budget(max_steps=200))
    assert not result.success
    ax = plots.plot_simulation(result, plant=plant, title=SCENE)
    assert f"showing {plots.MAX_LINES} of {n} contact speeds" in notes(ax)
    grey = [line for line in ax.lines if line.get_color() == "0.6" and len(line.get_xdata())]
    assert len(grey) == plots.MAX_LINES
    assert any(result.status.value in text for text in notes(ax))
    assert result.status.value not in ax.get_title()


# -- work-precision ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def precision_curves():
    plant = tk.carousel_startup_plant(0, n=11)
    settings = [MethodSetting("exact"),
                MethodSetting("rk45", {"friction": "sign", "rtol": 1e-6, "atol": 1e-9},
                              tk.Budget(max_steps=200)),          # stopped by its budget
                MethodSetting("moreau", {"step": 1e-3}), MethodSetting("moreau", {"step": 1e-4}),
                *(MethodSetting("lsoda", {"friction": "tanh", "epsilon": eps, "rtol": rtol,
                                          "atol": 1e-3 * rtol})
                  for eps in (1e-3, 1e-5) for rtol in (1e-4, 1e-8))]
    return work_precision_curves(tk.precision_report(plant, 1.0, repeats=1, settings=settings))


def test_work_precision_curves_are_families_through_their_tolerances(precision_curves):
    # A family (method, integrator, friction law) and smoothing width per curve; its points
    # are its tolerance settings (every row of the report with a finite error, once).
    keys = [(curve.family, curve.smoothing) for curve in precision_curves]
    assert keys == [("exact", None), ("rk45 sign", None), ("moreau", None), ("lsoda tanh", 1e-3),
                    ("lsoda tanh", 1e-5)]
    sizes = {key: curve.wall_time.size for key, curve in zip(keys, precision_curves)}
    assert sizes == {("exact", None): 1, ("rk45 sign", None): 1, ("moreau", None): 2,
                     ("lsoda tanh", 1e-3): 2, ("lsoda tanh", 1e-5): 2}
    assert all(np.all(np.diff(curve.wall_time) >= 0) for curve in precision_curves)


def test_precision_plot_draws_a_named_line_per_family(precision_curves):
    from toolkit.analysis.precision import ERROR_LEVEL

    ax = plots.plot_precision(precision_curves, title=SCENE, error_level=ERROR_LEVEL)
    (level,) = by_gid(ax, "error level")
    np.testing.assert_array_equal(level.get_ydata(), [1e-6, 1e-6])
    labels = [text.get_text() for text in ax.get_legend().get_texts()]
    assert any(label.startswith("hollow: stopped by a budget or failed") for label in labels)
    assert "1e-6 m/s error level" in labels
    assert any(text.get_text() == "1e-6 m/s " for text in ax.texts)
    # The legend names each family once and each smoothing width once; no text on a point.
    assert [label for label in labels if not label.startswith(("hollow", "1e-6", "epsilon"))] == [
        "exact", "rk45 sign", "moreau", "lsoda tanh"]
    assert [label for label in labels if label.startswith("epsilon")] == [
        "epsilon = 0.001 m/s", "epsilon = 1e-05 m/s"]
    assert by_gid(ax, "setting label") == [] and len(ax.texts) == 1
    # One line per curve through its points (loose tolerance to tight, in run time), the
    # colour of its family: the two lsoda widths share one.
    lines = by_gid(ax, "family line")
    assert len(lines) == len(precision_curves)
    for line, curve in zip(lines, precision_curves):
        np.testing.assert_array_equal(line.get_xdata(), curve.wall_time)
        np.testing.assert_array_equal(line.get_ydata(), np.maximum(curve.max_error, 1e-17))
    assert lines[3].get_color() == lines[4].get_color() != lines[2].get_color()
    # The legend stands beside the axes (it covers no point).
    assert ax.get_legend().get_bbox_to_anchor().x0 > ax.get_window_extent().x1 - 1
    assert ax.get_title().startswith(SCENE)
    assert ax.get_xscale() == ax.get_yscale() == "log"


# -- force curve ------------------------------------------------------------------------------
def test_force_curve_title_names_the_scene():
    ax = plots.plot_force_curve(tk.force_curve(tk.ContactSet([0.0, 0.1, 0.2, 0.3])), title=SCENE)
    assert ax.get_title() == f"{SCENE}: force-speed curve"


def test_plots_keep_the_users_backend_and_files_need_none():
    # In a fresh interpreter whose user chose the svg backend: writing a PNG (offscreen)
    # never imports pyplot; drawing without ax uses the user's pyplot and backend, which no
    # plot function switches (they used to call matplotlib.use("Agg")).
    import os
    import subprocess
    import sys

    code = ("import sys, matplotlib\n"
            "matplotlib.use('svg')\n"
            "import toolkit as tk\n"
            "from toolkit import plots\n"
            "curve = tk.force_curve(tk.ContactSet([0.1, 0.2, 0.3]))\n"
            "png = plots.render_png(plots.plot_force_curve, curve)\n"
            "assert png[:8] == b'\\x89PNG\\r\\n\\x1a\\n'\n"
            "print('pyplot' in ' '.join(sys.modules))\n"
            "ax = tk.plot_force_curve(curve)\n"
            "import matplotlib.pyplot as plt\n"
            "print(matplotlib.get_backend(), len(plt.get_fignums()))\n")
    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    assert out.stdout.split() == ["False", "svg", "1"], out.stdout + out.stderr
