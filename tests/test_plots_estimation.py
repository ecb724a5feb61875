"""Plots of the estimation study and of the closed loop draw the computed data (no more)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from toolkit import plots  # noqa: E402
from toolkit.scenes.spec import load_scene  # noqa: E402
from toolkit.scenes.study import control_scene, estimate_scene  # noqa: E402

ROOT = Path(__file__).parents[1]


def test_estimation_plot_draws_truth_and_every_estimator():
    study = estimate_scene(load_scene(ROOT / "designs" / "estimate.toml"))
    top, bottom = plots.plot_estimation(study, title="estimate")
    lines = {line.get_label(): line for line in top.get_lines()}
    np.testing.assert_array_equal(lines["truth V"].get_ydata(), study.record.truth_speed)
    for result in study.results:
        label = next(name for name in lines if name.startswith(plots._ESTIMATOR_STYLE[result.method]["label"]))
        np.testing.assert_array_equal(lines[label].get_ydata(), result.speed)
        # The legend carries the RMS error in mm/s, as scored.
        assert f"{result.rms_error * 1e3:.3g} mm/s" in label
    # The error panel is the filters': it spans 4 x their largest error (mm/s); estimate -
    # truth of each estimator within that span, exactly; the others are left out and named
    # in its legend (the alpha-beta tracker's error, tens of mm/s, among them).
    errors = {r.method: (r.speed - study.record.truth_speed) * 1e3 for r in study.results}
    limit = 4.0 * max(np.abs(errors[m]).max() for m in errors if m in plots._FILTERS)
    assert bottom.get_ylim() == (-limit, limit)
    drawn = {line.get_label(): line.get_ydata() for line in bottom.get_lines()}
    note = " ".join(label for label in drawn if label.startswith("not shown")).replace("\n", " ")
    left_out = [m for m in errors if m not in plots._FILTERS and np.abs(errors[m]).max() > limit]
    assert "alpha_beta" in left_out and {"kalman", "rts"} <= set(errors)
    for method, error in errors.items():
        name = plots._ESTIMATOR_STYLE[method]["label"]
        if method in left_out:
            assert name not in drawn and name in note, (name, note)
        else:
            np.testing.assert_allclose(drawn[name], error, rtol=0, atol=0)
    assert f"beyond +-{limit:.3g} mm/s" in note
    assert top.get_title() == "estimate: speed from encoder counts at 50 Hz"
    assert plots.figure_png((top, bottom))[:8] == b"\x89PNG\r\n\x1a\n"


def test_closed_loop_plot_draws_speed_estimate_and_commands():
    study = control_scene(load_scene(ROOT / "designs" / "closed_loop.toml"))
    top, bottom = plots.plot_closed_loop(study.loop, title="closed_loop", what="viscosity")
    lines = {line.get_label(): line for line in top.get_lines()}
    np.testing.assert_array_equal(lines["body speed V"].get_ydata(), study.loop.speed)
    np.testing.assert_array_equal(lines["estimate (controller input)"].get_ydata(), study.loop.estimate)
    drawn = [line for line in bottom.get_lines() if line.get_label().startswith("_")]
    assert len(drawn) == 10                    # every contact's command (10 <= MAX_LINES)
    plots.figure_png((top, bottom))
