"""The command line: exit codes, JSON output, error lines without tracebacks, written files."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from toolkit import ContactSet, __version__
from toolkit.cli import main
from toolkit.scenes.spec import load_scene
from toolkit.scenes.build import build_scene

ROOT = Path(__file__).parents[1]
DESIGNS = sorted((ROOT / "designs").glob("*.toml"))


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "toolkit.cli", *args], capture_output=True,
                          text=True, cwd=ROOT)


#: The designs whose run takes more than a few seconds (make test-quick leaves them out).
_SLOW_DESIGNS = {"sliding_disc"}


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.stem in _SLOW_DESIGNS else p
                                  for p in DESIGNS], ids=lambda p: p.stem)
def test_run_succeeds_on_every_design(path, tmp_path, capsys):
    assert main(["run", str(path), "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "wrote" in out
    scene = load_scene(path)
    if scene.planar is not None:         # a planar scene: its one stage
        summary = json.loads((tmp_path / "planar.json").read_text())
        assert summary["planar"]["shortfalls"] == [] and summary["planar"]["status"] == "SUCCESS"
        assert (tmp_path / "planar.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        return
    if scene.sweep is not None:          # a sweep scene: its one stage, the sweep
        summary = json.loads((tmp_path / "sweep.json").read_text())
        assert summary["shortfalls"] == [] and summary["runs"] == scene.sweep.runs
        assert len((tmp_path / "results.csv").read_text().splitlines()) == scene.sweep.runs + 1
        assert (tmp_path / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        return
    result = json.loads((tmp_path / "result.json").read_text())
    # The request was met: no shortfall (carousel's schedule is VERIFIED or OPTIMAL, a success).
    assert result["met"] is True and result["shortfalls"] == []
    assert capsys.readouterr().err == ""
    scene = load_scene(path)
    contacts = ContactSet(result["contacts"]["speeds"], result["contacts"]["forces"])
    assert result["curve"]["equilibrium"] == list(contacts.equilibrium())
    if scene.target is None:
        np.testing.assert_array_equal(contacts.speeds, build_scene(scene).contacts.speeds)
    if scene.report is not None and scene.report.plots:
        assert (tmp_path / "force_curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_curve_json_has_the_documented_keys(capsys):
    assert main(["curve", str(ROOT / "designs" / "five_five.toml"), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data) == {"speeds", "force", "equilibrium", "total_force", "steps"}
    assert data["equilibrium"] == [-0.35, 0.35]
    # The whole staircase: two steps of 10 N, exactly.
    assert data["steps"] == [{"speed": -0.35, "force_below": 10.0, "force_above": 0.0},
                             {"speed": 0.35, "force_below": 0.0, "force_above": -10.0}]
    assert data["total_force"] == 10.0
    speeds, force = np.array(data["speeds"]), np.array(data["force"])
    # Closed form of the five-against-five curve: +10 below -0.35, 0 inside, -10 above 0.35.
    np.testing.assert_array_equal(force[(speeds > -0.35) & (speeds < 0.35)], 0.0)
    np.testing.assert_array_equal(force[speeds < -0.35], 10.0)
    np.testing.assert_array_equal(force[speeds > 0.35], -10.0)


def test_version_and_help():
    done = cli("--version")
    assert done.returncode == 0 and __version__ in done.stdout
    done = cli("--help")
    assert done.returncode == 0 and "run" in done.stdout and "curve" in done.stdout


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["run", "designs/nope.toml"], "does not exist"),
        (["curve", "designs/nope.toml", "--json"], "does not exist"),
        (["curve", "designs/carousel.toml", "--points", "1"], "--points"),
        (["fly"], "invalid choice"),
        (["warm", "--processes", "3"], "argument --processes: invalid choice: 3 (choose from 1, 2)"),
    ],
)
def test_user_errors_exit_2_with_one_line_and_no_traceback(args, fragment):
    done = cli(*args)
    assert done.returncode == 2
    assert fragment in done.stderr
    assert "Traceback" not in done.stderr
    assert done.stdout == ""


def test_bad_scene_writes_nothing(tmp_path):
    scene = tmp_path / "bad.toml"
    scene.write_text("[contacts]\nspeeds = [0.1, 0.2]\nforcez = 1.0\n")
    out = tmp_path / "out"
    done = cli("run", str(scene), "--out", str(out))
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "Did you mean 'forces'?" in done.stderr
    assert not out.exists()


def test_allocate_json_reproduces_the_papers_split(capsys):
    # braking.toml asks for mu/mu0 = 0.4 on 10 equal contacts: 3 at +v_max, 7 at -v_max.
    assert main(["allocate", str(ROOT / "designs" / "braking.toml"), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert {"speeds", "error_sup", "error_l1", "bound", "gap", "method", "status", "wall_time"} <= set(data)
    assert sorted(data["speeds"]) == [-0.35] * 7 + [0.35] * 3
    assert data["error_sup"] == 0.0 and data["gap"] == 0.0


def test_run_on_braking_checks_the_transition_time(tmp_path, capsys):
    # dT = m 2 v_max / (F_tot mu/mu0) = 5 * 0.7 / (10 * 0.4) = 0.875 s (docs/physics.md section 6).
    assert main(["run", str(ROOT / "designs" / "braking.toml"), "--out", str(tmp_path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    t, V = np.array(data["simulation"]["t"]), np.array(data["simulation"]["V"])
    arrival = t[np.argmax(V <= -0.35)]
    np.testing.assert_allclose(arrival, 0.875, rtol=1e-12)


def test_allocate_without_target_is_a_user_error():
    done = cli("allocate", "designs/equal.toml")
    assert done.returncode == 2 and "no [target]" in done.stderr and "Traceback" not in done.stderr


@pytest.mark.slow
def test_precision_json_rows(tmp_path):
    done = cli("precision", "designs/odd7.toml", "--json", "--repeats", "1", "--out", str(tmp_path))
    assert done.returncode == 0, done.stderr
    rows = json.loads(done.stdout)["rows"]
    assert {"method", "setting", "max_error", "final_error", "wall_time", "status"} <= set(rows[0])
    exact = [r for r in rows if r["method"] == "exact"]
    assert exact and all(r["max_error"] <= 1e-12 for r in exact)
    assert {r["method"] for r in rows} >= {"exact", "rk45", "radau", "moreau", "casadi"}
    assert (tmp_path / "precision.png").read_bytes()[:4] == b"\x89PNG"
    # The speedup summary is the identity reference / exact over the rows it names.
    speedup = json.loads(done.stdout)["speedup"]
    by_label = {f"{r['method']} {r['setting']}".strip(): r for r in rows}
    reference, exact = by_label[speedup["reference"]], by_label[speedup["exact"]]
    assert reference["max_error"] <= speedup["error_level"] == 1e-6
    assert speedup["ratio"] == pytest.approx(reference["wall_time"] / exact["wall_time"], rel=1e-15)


def test_stability_quick_json():
    done = cli("stability", "--quick", "--json")
    assert done.returncode == 0, done.stderr
    cases = json.loads(done.stdout)["cases"]
    assert cases and all({"name", "method", "finished", "finite", "events", "wall_time", "ok"} <= set(c)
                         for c in cases)
    assert all(c["ok"] and c["finished"] and c["finite"] for c in cases)


def test_schedule_writes_csv_and_json_verified_by_exact_simulation(tmp_path):
    done = cli("schedule", "designs/brake_schedule.toml", "--out", str(tmp_path), "--json")
    assert done.returncode == 0, done.stderr
    data = json.loads(done.stdout)
    rows = (tmp_path / "schedule.csv").read_text().splitlines()
    assert rows[0].split(",") == ["time_s"] + [f"speed_{i}_mps" for i in range(10)]
    table = np.array([[float(x) for x in row.split(",")] for row in rows[1:]])
    np.testing.assert_array_equal(table[:, 0], data["times"])
    np.testing.assert_array_equal(table[:, 1:], data["speeds"])
    assert np.all(np.abs(table[:, 1:]) <= 0.35)                       # motor limits, exactly
    assert json.loads((tmp_path / "schedule.json").read_text())["times"] == data["times"]
    # The exact nonsmooth simulation stays within the design's certified prediction bound.
    check = data["exact_check"]
    assert check["within_bound"] and check["max_deviation"] <= check["prediction_bound"]
    # Closed-form minimum braking time 0.17 s (one pinned period + m V0 / F_tot = 0.15 s; the
    # lag's Lambert-W term is below the 20 ms grid): arrival on the grid point at or after it.
    assert data["minimum_time"] == pytest.approx(0.17, abs=0.005)
    assert data["arrival_time"] <= data["minimum_time"] + 0.02 + 1e-12


def test_schedule_without_section_is_a_user_error():
    done = cli("schedule", "designs/equal.toml")
    assert done.returncode == 2 and "no [schedule]" in done.stderr and "Traceback" not in done.stderr


def test_output_folder_that_is_a_file_is_a_user_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    done = cli("run", "designs/equal.toml", "--out", str(blocker / "sub"))
    assert done.returncode == 2 and "cannot write the output" in done.stderr and "Traceback" not in done.stderr


@pytest.mark.slow
def test_precision_plot_with_motors_where_exact_is_the_reference(tmp_path):
    # random10 has motors: no rational-arithmetic reference, so the exact row has no
    # independent error (null in JSON) and is drawn as the reference line (regression test).
    done = cli("precision", "designs/random10.toml", "--json", "--repeats", "1", "--out", str(tmp_path))
    assert done.returncode == 0, done.stderr
    exact = [r for r in json.loads(done.stdout)["rows"] if r["method"] == "exact"]
    assert exact[0]["max_error"] is None and exact[0]["status"] == "SUCCESS"
    assert (tmp_path / "precision.png").read_bytes()[:4] == b"\x89PNG"


# -- exit codes that tell the truth --------------------------------------------------

TEN_AT_REST = "[contacts]\nspeeds = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\nforces = 1.0\n"
FRACTION_17 = (TEN_AT_REST + "[motors]\nspeed_limit = 0.35\n"
               '[target]\nkind = "friction_fraction"\nfraction = 1.7\nband = 0.35\n')
TRACK_2 = ("[contacts]\nspeeds = [0.0, 0.0, 0.0, 0.0]\nforces = 1.0\n[body]\nmass = 1.0\n"
           "[motors]\nspeed_limit = 0.35\n"
           '[schedule]\nkind = "track"\ntimes = [0.0, 0.5, 1.0]\nspeeds = [0.0, 2.0, 2.0]\n')
BUDGET = ("[contacts]\nspeeds = [0.1, -0.2, 0.3]\n[body]\nmass = 1.0\n"
          '[simulation]\nt_end = 1e9\nmethod = "rk45"\noptions = { budget = { max_steps = 200 } }\n')
FAST = "[contacts]\nspeeds = [0.5, 0.1, -0.2]\n[body]\nmass = 1.0\n[motors]\nspeed_limit = 0.35\n"


def scene_file(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_exit_codes_are_listed_in_help():
    done = cli("--help")
    assert done.returncode == 0
    for line in ("  0    the request was met", "  2    user error", "  3    finished but missed the request"):
        assert line in done.stdout


def test_projected_friction_fraction_exits_3_with_the_distance(tmp_path):
    out = tmp_path / "out"
    done = cli("run", str(scene_file(tmp_path, FRACTION_17)), "--out", str(out))
    assert done.returncode == 3
    # -1.7 F_tot = -17 N requested, -F_tot = -10 N realizable: 7 N away.
    assert done.stderr == ("active-contacts: shortfall: allocation: friction fraction 1.7 is not "
                           "realizable: projected to 1 (distance 7 N)\n")
    assert "sup error 0 N (from the projected target, 7 N from the request)" in done.stdout
    assert json.loads((out / "result.json").read_text())["shortfalls"][0]["amount"] == 7.0
    done = cli("allocate", str(scene_file(tmp_path, FRACTION_17)))
    assert done.returncode == 3 and "distance 7 N" in done.stderr


def test_strict_refuses_a_projection_before_any_work(tmp_path):
    out = tmp_path / "out"
    for command in (["run", "--out", str(out)], ["allocate"]):
        done = cli(command[0], str(scene_file(tmp_path, FRACTION_17)), "--strict", *command[1:])
        assert done.returncode == 2 and "Traceback" not in done.stderr
        assert done.stderr.startswith("active-contacts: error: --strict: allocation: the target is not "
                                      "realizable: The 'target' parameter of allocate must stay within "
                                      "+-F_tot = +-10 N (strict=True). Got -17.0 instead.")
    assert not out.exists()


def test_unreachable_tracking_target_is_not_optimal(tmp_path):
    out = tmp_path / "out"
    done = cli("schedule", str(scene_file(tmp_path, TRACK_2)), "--out", str(out), "--json")
    assert done.returncode == 3
    data = json.loads(done.stdout)
    # The body cannot pass the contacts' 0.35 m/s: the exact error is 2 - 0.35 = 1.65 m/s, and
    # the best achievable error reported is the schedule's certified lower bound.
    np.testing.assert_allclose(data["exact_tracking_error"], 1.65, rtol=1e-12, atol=0)
    (shortfall,) = data["shortfalls"]
    assert shortfall["amount"] == data["lower_bound"] <= data["exact_tracking_error"]
    assert shortfall["what"] == (f"unreachable: best achievable error {data['lower_bound']:.3g} m/s, because "
                                 "the target exceeds the speed limit 0.35 m/s (target speed 2 m/s)")
    done = cli("schedule", str(scene_file(tmp_path, TRACK_2)), "--out", str(out))
    assert done.returncode == 3
    assert done.stdout.splitlines()[2].startswith("unreachable: best achievable error 1.65 m/s")
    assert "optimal" not in done.stdout
    done = cli("schedule", str(scene_file(tmp_path, TRACK_2)), "--out", str(tmp_path / "o2"), "--strict")
    assert done.returncode == 2
    assert "--strict: schedule: unreachable: the target speed 2 m/s exceeds the speed limit 0.35 m/s" in done.stderr
    assert not (tmp_path / "o2").exists()


def test_budget_stop_exits_3(tmp_path):
    out = tmp_path / "out"
    done = cli("run", str(scene_file(tmp_path, BUDGET)), "--out", str(out), "--json")
    assert done.returncode == 3
    data = json.loads(done.stdout)
    t_last = data["simulation"]["t"][-1]
    assert data["simulation"]["status"] == "stopped: step budget exhausted"
    assert data["shortfalls"] == [{"stage": "simulation", "unit": "s", "amount": 1e9 - t_last,
                                   "what": f"stopped: step budget exhausted at t = {t_last:.6g} s of "
                                           f"t_end = 1e+09 s ({1e9 - t_last:.6g} s not simulated)"}]
    assert done.stderr.startswith("active-contacts: shortfall: simulation: stopped: step budget exhausted")


def test_speeds_beyond_the_motor_limits_are_refused_or_clipped(tmp_path):
    done = cli("run", str(scene_file(tmp_path, FAST)), "--out", str(tmp_path / "a"))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr == ("active-contacts: error: The 'contacts.speeds' value in the scene must lie within "
                           "the motors' speed limits [-0.35, 0.35] m/s (or set [motors] clip = true to clip "
                           "it). Got 0.5 m/s (entry [0], beyond the limit 0.35 m/s) instead.\n")
    clipped = scene_file(tmp_path, FAST + "clip = true\n", "clipped.toml")
    done = cli("run", str(clipped), "--out", str(tmp_path / "b"), "--json")
    assert done.returncode == 3
    data = json.loads(done.stdout)
    assert data["contacts"]["speeds"] == [0.35, 0.1, -0.2]
    (shortfall,) = data["shortfalls"]
    assert shortfall["what"] == ("1 speed(s) in 'contacts.speeds' beyond the motors' speed limit clipped: "
                                 "0.5 m/s to 0.35 m/s (excess 0.15 m/s)")
    np.testing.assert_allclose(shortfall["amount"], 0.15, rtol=1e-12, atol=0)   # 0.5 - 0.35 in floats
    done = cli("run", str(clipped), "--out", str(tmp_path / "c"), "--strict")
    assert done.returncode == 2 and "--strict: scene: 1 speed(s) in 'contacts.speeds'" in done.stderr
    assert not (tmp_path / "c").exists()


def test_curve_text_lists_every_step_even_narrow_ones(tmp_path):
    # Steps 0.1 mm/s apart: a 41-row sample of the curve missed them.
    path = scene_file(tmp_path, "[contacts]\nspeeds = [0.0, 0.0001, 0.3]\nforces = [1.0, 2.0, 1.0]\n")
    done = cli("curve", str(path))
    assert done.returncode == 0
    assert done.stdout.splitlines() == [
        "F_tot = 4 N; equilibrium [0.0001, 0.0001] m/s",
        "3 steps; F is constant between them",
        "     V (m/s)  F below (N)  F above (N)",
        "           0            4            2",
        "      0.0001            2           -2",
        "         0.3           -2           -4",
    ]



# -- sweep -------------------------------------------------------------------------------------

def test_sweep_json_and_results_csv(tmp_path, capsys):
    import pandas as pd

    from toolkit import MedianLaw, sweep

    code = main(["sweep", str(ROOT / "designs" / "median_law.toml"), "--runs", "50", "--seed", "4",
                 "--json", "--out", str(tmp_path)])
    assert code == 0
    data = json.loads(capsys.readouterr().out)
    # The scene's statistics only, computed on the same runs as the library call (identity).
    expected = sweep(MedianLaw(), 50, seed=4)
    assert set(data["summary"]) == {"slope", "slope_stderr", "ratio_median", "settled_fraction"}
    assert data["summary"]["slope"] == expected.summary["slope"]
    assert (data["runs"], data["seed"], data["scheduler"]) == (50, 4, "local")
    table = pd.read_csv(tmp_path / "results.csv")
    np.testing.assert_array_equal(table["speed"], expected.table["speed"])    # %.17g round trip


@pytest.mark.wall_clock
def test_sweep_on_a_process_pool_matches_local(capsys):
    assert main(["sweep", str(ROOT / "designs" / "median_law.toml"), "--runs", "40", "--json"]) == 0
    local = json.loads(capsys.readouterr().out)
    assert main(["sweep", str(ROOT / "designs" / "median_law.toml"), "--runs", "40", "--json",
                 "--scheduler", "processes", "--workers", "2"]) == 0
    pooled = json.loads(capsys.readouterr().out)
    assert pooled["summary"] == local["summary"] and pooled["scheduler"] == "processes"


def test_sweep_user_errors(tmp_path, monkeypatch, capsys):
    # No [sweep], a sweep scene given to curve, --scheduler without dask installed, an
    # unreachable scheduler: one line on stderr, exit 2, nothing written.
    out = tmp_path / "out"
    assert main(["sweep", str(ROOT / "designs" / "carousel.toml"), "--out", str(out)]) == 2
    assert "has no [sweep] section" in capsys.readouterr().err
    assert main(["curve", str(ROOT / "designs" / "median_law.toml")]) == 2
    assert "is a sweep scene" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "distributed", None)
    assert main(["sweep", str(ROOT / "designs" / "median_law.toml"), "--runs", "5",
                 "--scheduler", "tcp://127.0.0.1:9", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "pip install 'active-contacts[dask]'" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
    # a scheduler that is neither 'processes' nor an address, and --workers without the pool
    for extra, message in ((["--scheduler", "Processes"], "Did you mean 'processes'"),
                           (["--scheduler", "threads"], "or a Dask scheduler address tcp://host:port"),
                           (["--workers", "3"], "'workers' parameter of sweep must be given only with")):
        assert main(["sweep", str(ROOT / "designs" / "median_law.toml"), "--runs", "5", *extra,
                     "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
        assert not out.exists()
    # an experiment size beyond the bounds: one line naming the parameter, no traceback
    big = tmp_path / "big.toml"
    big.write_text('[sweep]\nexperiment = "outliers"\nruns = 1\nrate = 1e9\nwindow = 1e9\n')
    assert main(["sweep", str(big)]) == 2
    err = capsys.readouterr().err
    assert "'window' parameter of Outliers" in err and len(err.strip().splitlines()) == 1


def test_sweep_json_writes_undefined_statistics_as_null(tmp_path, capsys):
    # No outlier amplitude (A = 0) moves the body: threshold_amplitude is undefined (NaN in
    # the summary) and null in JSON; defined statistics stay numbers.
    scene = tmp_path / "still.toml"
    scene.write_text('[sweep]\nexperiment = "outliers"\nruns = 2\namplitude = 0.0\nwindow = 0.5\n')
    assert main(["sweep", str(scene), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)["summary"]
    assert summary["threshold_amplitude"] is None and summary["unaffected_fraction"] == 1.0


def test_sweep_unsettled_runs_are_a_shortfall(tmp_path, capsys):
    # Observing each run for 0.01 s leaves most runs moving: exit 3 and the count on stderr.
    scene = tmp_path / "short.toml"
    scene.write_text('[sweep]\nexperiment = "median_law"\nruns = 20\nsettle_time = 0.01\n')
    assert main(["sweep", str(scene), "--out", str(tmp_path / "out")]) == 3
    err = capsys.readouterr().err
    assert "runs had not settled" in err
    assert (tmp_path / "out" / "results.csv").exists()


def test_report_figures_need_no_backend(tmp_path):
    # The command line writes its PNGs offscreen (plain Figures no backend manages): pyplot is
    # never imported, whatever MPLBACKEND says, and the files are PNGs.
    import os

    code = ("import sys\n"
            "from toolkit.cli import main\n"
            f"assert main(['run', 'designs/carousel.toml', '--out', {str(tmp_path / 'out')!r}]) == 0\n"
            "print('matplotlib.pyplot' in sys.modules, 'matplotlib' in sys.modules)\n")
    env = {**os.environ, "MPLBACKEND": "tkagg", "DISPLAY": ""}    # pyplot could not start it here
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split()[-2:] == ["False", "True"]
    for name in ("force_curve.png", "simulation.png", "schedule.png"):
        assert (tmp_path / "out" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_estimate_reads_a_record_for_a_scene_with_neither_estimation_nor_simulation(tmp_path):
    # A lab's scene names its hardware only ([body], [motors], [sensors]): `estimate --record`
    # estimates from the log with the default estimators; without --record it is refused
    # (nothing to simulate), naming the sections it needs.
    hardware = """[scene]
name = "rig"
[contacts]
speeds = [0.1, -0.1, 0.2]
forces = [1.0, 0.5, 2.0]
[body]
inertia = 0.353780
contact_radius = 0.266
[motors]
speed_limit = 0.35
lag = 0.0075
[sensors]
rate = 50.0
wheel_counts_per_rev = 3591.84
wheel_radius = 0.045
wheel_backlash = 0.0008
central_counts_per_rev = 8192
contact_radius = 0.266
"""
    recorded = tmp_path / "recorded.toml"
    recorded.write_text(hardware + "[simulation]\nt_end = 1.0\n")
    log = tmp_path / "log.csv"
    assert main(["estimate", str(recorded), "--save-record", str(log), "--out", str(tmp_path / "a")]) == 0
    rig = tmp_path / "rig.toml"
    rig.write_text(hardware)
    assert main(["estimate", str(rig), "--record", str(log), "--out", str(tmp_path / "b"), "--json"]) == 0
    done = cli("estimate", str(rig), "--out", str(tmp_path / "c"))
    assert done.returncode == 2 and len(done.stderr.splitlines()) == 1
    assert "[estimation]" in done.stderr and "[simulation]" in done.stderr
