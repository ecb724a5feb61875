"""Reliability and honest results: the public names, and the shortfalls of the
work-precision report.

The other guarantees are tested where their code lives (see the list in
``test_every_reliability_guarantee_has_a_test`` below).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import toolkit as tk
from toolkit.analysis.precision import (ERROR_LEVEL, MethodSetting, PrecisionReport, PrecisionRow, exact_speedup,
                               precision_report, precision_shortfalls)
from toolkit.simulation import Budget, SimulationStatus

ROOT = Path(__file__).resolve().parents[1]


# -- exports ---------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["Shortfall", "Clip", "OutputError", "MAX_SCENE_BYTES", "CurveStep",
                                  "Budget", "SimulationStatus", "StudyResult"])
def test_reliability_names_are_public(name: str) -> None:
    assert name in tk.__all__ and getattr(tk, name) is not None


def test_public_api_has_no_duplicates_and_every_name_resolves() -> None:
    assert len(tk.__all__) == len(set(tk.__all__))
    for name in tk.__all__:
        getattr(tk, name)


def test_exported_objects_are_the_ones_the_toolkit_uses(tmp_path: Path) -> None:
    from toolkit import shortfall
    from toolkit.scenes import _io, build as scene_build, spec as scene, study

    assert tk.Shortfall is study.Shortfall is shortfall.Shortfall and tk.Clip is scene_build.Clip
    assert tk.MAX_SCENE_BYTES == scene.MAX_SCENE_BYTES == 1 << 20
    # OutputError is one of the toolkit's errors (errors.py), an OSError, and what the output
    # check raises for an --out that is an existing file
    assert tk.OutputError is _io.OutputError and issubclass(tk.OutputError, (tk.ToolkitError, OSError))
    afile = tmp_path / "file"
    afile.write_text("x")
    with pytest.raises(tk.OutputError, match="exists and is not a folder"):
        _io.check_output_dir(afile)
    # Budget carries the memory cap, validated like the other limits
    assert tk.Budget().max_samples == 2**18
    with pytest.raises(tk.ParameterError, match="'max_samples' parameter of Budget"):
        tk.Budget(max_samples=1)


# -- precision: its request and shortfalls ---------------------------------------------------
def _row(method: str, max_error: float, status: SimulationStatus = SimulationStatus.SUCCESS,
         wall: float = 1e-3, setting: str = "") -> PrecisionRow:
    return PrecisionRow(method=method, setting=setting, max_error=max_error, final_error=max_error,
                        wall_time=wall, n_steps=1, n_evaluations=1, n_events=0, status=status,
                        message=status.value, chattering=False, step_collapse=None, creep=False,
                        stalled=status is not SimulationStatus.SUCCESS, reversals=0, min_step=None)


def _report(*rows: PrecisionRow) -> PrecisionReport:
    return PrecisionReport(rows=rows, t_end=5.0, v0=0.0, repeats=1)


def test_a_report_that_meets_its_request_has_no_shortfall() -> None:
    report = _report(_row("exact", 3e-17), _row("casadi", 5e-7, setting="tanh"),
                     _row("rk45", 2e-3, SimulationStatus.WALL_TIME, setting="sign"))
    # a budget-stopped reference is what the report shows, not a shortfall
    assert precision_shortfalls(report) == []
    assert report.to_dict()["shortfalls"] == []


def test_no_reference_at_the_level_is_a_shortfall_by_the_closest_error() -> None:
    report = _report(_row("exact", 3e-17), _row("moreau", 4e-3, setting="h=0.01"),
                     _row("radau", 2e-5, setting="tanh"),
                     _row("rk45", 1e-9, SimulationStatus.WALL_TIME, setting="sign"))
    assert exact_speedup(report).reference is None
    (shortfall,) = precision_shortfalls(report)
    assert shortfall.stage == "precision" and shortfall.unit == "m/s"
    assert "no reference method reached max_error <= 1e-06 m/s" in shortfall.what
    assert "radau tanh" in shortfall.what        # the closest finished run, not the stopped rk45
    # amount: the closest finished error minus the level (identity; rtol 1e-15: one rounding)
    assert shortfall.amount == pytest.approx(2e-5 - ERROR_LEVEL, rel=1e-15, abs=0)
    assert report.to_dict()["shortfalls"] == [shortfall.to_dict()]


def test_no_finished_reference_is_a_shortfall_without_an_amount() -> None:
    report = _report(_row("exact", 0.0), _row("rk45", 1e-3, SimulationStatus.MAX_STEPS))
    (shortfall,) = precision_shortfalls(report)
    assert "none finished" in shortfall.what and math.isnan(shortfall.amount)


def test_an_inexact_exact_method_is_a_shortfall() -> None:
    report = _report(_row("exact", 3e-6), _row("casadi", 5e-7))
    (shortfall,) = precision_shortfalls(report)
    assert "exact method's error 3e-06 m/s" in shortfall.what
    assert shortfall.amount == pytest.approx(3e-6 - ERROR_LEVEL, rel=1e-15, abs=0)
    # no independent reference (NaN): stated by the report, not a shortfall
    assert precision_shortfalls(_report(_row("exact", math.nan), _row("casadi", 5e-7))) == []
    # no exact row: no speedup was asked for
    assert precision_shortfalls(_report(_row("casadi", 5e-2))) == []


def test_real_report_shortfall_is_its_closest_rows_error() -> None:
    # A real run: moreau with 10 ms steps cannot reach 1e-6 m/s on the carousel startup (its
    # error is O(h)); the shortfall's amount is that row's measured error minus the level.
    plant = tk.carousel_startup_plant(0)
    settings = [MethodSetting("exact"), MethodSetting("moreau", {"step": 1e-2}, Budget(wall_time=5.0))]
    report = precision_report(plant, 1.0, repeats=1, settings=settings)
    moreau = report.row("moreau")
    assert moreau.status is SimulationStatus.SUCCESS and moreau.max_error > ERROR_LEVEL
    (shortfall,) = precision_shortfalls(report)
    assert shortfall.amount == pytest.approx(moreau.max_error - ERROR_LEVEL, rel=1e-15, abs=0)
    # and with a reference that does reach the level, none
    settings.append(MethodSetting("casadi", {"friction": "tanh", "epsilon": 1e-8, "rtol": 1e-10,
                                             "atol": 1e-12}))
    report = precision_report(plant, 1.0, repeats=1, settings=settings)
    assert report.row("casadi").max_error <= ERROR_LEVEL
    assert precision_shortfalls(report) == []


def test_precision_command_exits_3_on_a_shortfall(monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    from toolkit import cli

    short = _report(_row("exact", 3e-17), _row("moreau", 4e-3, setting="h=0.01"))
    monkeypatch.setattr("toolkit.analysis.precision.precision_report", lambda *args, **kwargs: short)
    code = cli.main(["precision", str(ROOT / "designs" / "startup11.toml"), "--repeats", "1"])
    err = capsys.readouterr().err
    assert code == 3
    assert err.count("\n") == 1 and "shortfall: precision: no reference method reached" in err


# -- every reliability guarantee has a test ----------------------------------------------------
#: Guarantee -> tests that check it (each failed before the change that made it pass).
RELIABILITY_TESTS = {
    "1 memory and time bounded in every method at t_end = 1e9": [
        "tests/test_memory_bounds.py::test_method_at_1e9_returns_a_budget_status_under_1_gib",
        "tests/test_memory_bounds.py::test_decimated_record_is_the_full_record_thinned",
        "tests/test_memory_bounds.py::test_moreau_budget_stop_in_a_huge_segment_is_prompt",
        "tests/test_memory_bounds.py::test_casadi_stopped_run_returns_its_completed_blocks",
        "tests/test_stability.py::test_every_method_has_a_1e9_horizon_case"],
    "2 exit codes that tell the truth": [
        "tests/test_cli.py::test_exit_codes_are_listed_in_help",
        "tests/test_cli.py::test_projected_friction_fraction_exits_3_with_the_distance",
        "tests/test_cli.py::test_strict_refuses_a_projection_before_any_work",
        "tests/test_cli.py::test_unreachable_tracking_target_is_not_optimal",
        "tests/test_cli.py::test_budget_stop_exits_3",
        "tests/test_cli.py::test_speeds_beyond_the_motor_limits_are_refused_or_clipped",
        "tests/test_cli.py::test_run_succeeds_on_every_design",
        "tests/test_scene.py::test_speeds_beyond_the_motor_limits_are_refused",
        "tests/test_scene.py::test_clip_true_clips_speeds_and_commands_and_round_trips",
        "tests/test_reliability.py::test_no_reference_at_the_level_is_a_shortfall_by_the_closest_error"],
    "3 all-or-nothing outputs": [
        "tests/test_report.py::test_a_failed_write_leaves_the_previous_outputs_exactly",
        "tests/test_report.py::test_a_failed_write_into_a_new_folder_leaves_nothing",
        "tests/test_report.py::test_files_and_folder_get_the_usual_modes",
        "tests/test_report.py::test_an_output_that_is_a_file_is_refused_before_the_study_runs"],
    "4 scene file edge cases": [
        "tests/test_scene.py::test_non_utf8_scene", "tests/test_scene.py::test_directory_as_scene",
        "tests/test_scene.py::test_empty_scene", "tests/test_scene.py::test_scene_larger_than_the_cap",
        "tests/test_scene.py::test_symlink_loop"],
    "5 plots": [
        "tests/test_plots.py::test_schedule_draws_the_target_on_top_and_titles_the_scene",
        "tests/test_plots.py::test_schedule_error_panel_is_the_exact_tracking_error_against_its_bounds",
        "tests/test_plots.py::test_fast_braking_target_is_the_minimum_time_curve",
        "tests/test_plots.py::test_precision_plot_draws_a_named_line_per_family",
        "tests/test_plots.py::test_simulation_shades_the_zero_force_band_and_keeps_the_status_out_of_the_title",
        "tests/test_plots.py::test_simulation_thins_many_contacts_and_notes_a_stopped_run",
        "tests/test_cli.py::test_curve_text_lists_every_step_even_narrow_ones"],
    "6 README and docs true on a fresh clone": [
        "tests/test_readme.py::test_every_link_stays_inside_the_repository",
        "tests/test_readme.py::test_force_speed_curves_notebook_shows_the_allocator_and_dt_to_1e_12",
        # every scene key documented with its unit and meaning: the generated reference page
        "tests/test_scene_reference.py::test_every_declared_key_kind_bound_and_rule_is_on_the_page_under_its_section",
        "tests/test_readme.py::test_exit_codes_documented_are_the_clis"],
}


def test_every_reliability_guarantee_has_a_test() -> None:
    # Each listed test exists (a renamed or deleted test fails here, not silently).
    for row, tests in RELIABILITY_TESTS.items():
        assert tests, row
        for node in tests:
            path, name = node.split("::")
            text = (ROOT / path).read_text(encoding="utf-8")
            assert f"def {name}(" in text, node


def test_precision_reads_step_collapse_from_every_step_whatever_max_samples() -> None:
    # The untimed own-steps run keeps every step even when the setting's budget has a small
    # memory cap: min_step equals that of a run keeping every step (second computation,
    # exact equality: the same deterministic steps).
    plant = tk.carousel_startup_plant(0)
    tight = Budget(wall_time=10.0, max_steps=20_000, max_samples=100)   # the step budget decides
    options = {"friction": "sign", "rtol": 1e-6, "atol": 1e-9}
    report = precision_report(plant, 5.0, repeats=1, settings=[
        MethodSetting("exact"), MethodSetting("rk45", options, tight)])
    row = report.row("rk45")
    every = tk.simulate(plant, 5.0, method="rk45", budget=Budget(wall_time=10.0, max_steps=20_000,
                                                                 max_samples=20_001), **options)
    assert "decimated" not in every.message and every.t.size > 100
    steps = np.diff(every.t)
    assert row.step_collapse is not None
    assert row.min_step == float(np.min(steps[steps > 0]))
