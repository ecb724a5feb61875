"""The [estimation] and [control] scene sections, their study stages, and bad input."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from toolkit.cli import main
from toolkit.errors import SceneError
from toolkit.scenes.spec import dumps_scene, load_scene, loads_scene
from toolkit.scenes.study import control_scene, estimate_scene, run_study
from toolkit.scenes.build import build_scene

ROOT = Path(__file__).parents[1]
ESTIMATE = (ROOT / "designs" / "estimate.toml").read_text()
LOOP = (ROOT / "designs" / "closed_loop.toml").read_text()
#: The scene's head without [sensors], [estimation], [control], [report].
BASE = LOOP.split("[sensors]")[0]
SENSORS = "[sensors]" + LOOP.split("[sensors]")[1].split("[control]")[0]
#: The same carousel under virtual viscosity without drag (a constant staircase: no feedback).
VISCOSITY = LOOP.replace("damping = 2.0                 # N s/m, bearing drag\n", "").replace(
    LOOP[LOOP.index('controller = "speed_hold"'):LOOP.index("duration =")],
    'controller = "viscosity"\nslope = 40.0                  # N s/m\nreference = 0.1               # m/s\n')


def _with(text: str, old: str, new: str) -> str:
    assert old in text
    return text.replace(old, new)


def test_estimation_and_control_round_trip():
    for text in (ESTIMATE, LOOP, VISCOSITY, _with(LOOP, "kp = 0.5 ", "kp = 0.2 ")):
        scene = loads_scene(text)
        assert loads_scene(dumps_scene(scene)) == scene
    scene = loads_scene(ESTIMATE)
    assert scene.stages == ("curve", "sensors", "estimation", "report")
    assert scene.estimation.methods == ("central_difference", "wheel_difference", "foaw_end", "foaw_best",
                                        "alpha_beta", "kalman", "rts")


def _scene_reference(**kwargs):
    """``carousel_brake_scenario(seed=0, **kwargs)`` recorded as a scene records it: the
    encoders' grids where the scene's seed puts them."""
    from toolkit.analysis.scenarios import carousel_brake_scenario, grid_positions, record_world

    reference = carousel_brake_scenario(seed=0, **kwargs)
    _, record = record_world(reference.world, 10.0, seed=0, **grid_positions(reference.sensors, 0))
    return dataclasses.replace(reference, record=record)


def test_estimation_stage_is_the_carousel_brake_scenario():
    # Second method: the estimation package's own acceptance scenario (same plant, encoders
    # and seed) gives the same record and the same scores, exactly (same arithmetic).
    from toolkit.estimation import CentralDifference, KalmanEstimator, RTSSmoother

    study = estimate_scene(loads_scene(ESTIMATE))
    reference = _scene_reference()
    np.testing.assert_array_equal(study.record.central_counts, reference.record.central_counts)
    np.testing.assert_array_equal(study.record.wheel_counts, reference.record.wheel_counts)
    np.testing.assert_allclose(study.record.truth_speed, reference.record.truth_speed, rtol=0, atol=0)
    assert study.duration == 10.0
    rows = {row["name"]: row for row in study.rows()}
    for name, estimator in (("central_difference", CentralDifference(reference.sensors)),
                            ("kalman", KalmanEstimator(reference.model)), ("rts", RTSSmoother(reference.model))):
        expected = estimator.run(reference.record, speed_std=1e-4)   # the section's default prior
        assert rows[name]["rms"] == pytest.approx(expected.rms_error, rel=1e-15, abs=0)
        assert rows[name]["max_error"] == pytest.approx(expected.max_error, rel=1e-15, abs=0)
    # How the smoother compares with the filter on this record (better except in the brake
    # window, where both share an input error) is tested in test_estimation.py.
    # The first criterion on this record: the filter at most 1/10 of differencing.
    assert rows["kalman"]["rms"] <= rows["central_difference"]["rms"] / 10


def test_friction_spread_draws_the_true_forces_and_tells_the_model():
    scene = loads_scene(_with(ESTIMATE, "seed = 0", "seed = 3\nfriction_spread = 0.2"))
    objects = build_scene(scene).estimation
    forces = objects.plant.contacts.forces
    # Lognormal loads with mean f_i = 1 and relative std 0.2 (toolkit.model.unequal_loads),
    # z from default_rng([seed, 1]): the closed form of the draw (rtol 1e-15, rounding).
    z = np.random.default_rng([3, 1]).standard_normal(10)
    sigma2 = np.log1p(0.2**2)
    np.testing.assert_allclose(forces, np.exp(np.sqrt(sigma2) * z - 0.5 * sigma2), rtol=1e-15, atol=0)
    assert objects.model.friction_uncertainty == 0.2
    np.testing.assert_array_equal(objects.model.forces, np.ones(10))   # nominal, not the draw


def test_simulation_scenario_records_the_scene_simulation():
    text = _with(ESTIMATE, 'scenario = "brake"\nduration = 10.0               # s\nbrake_time = 5.0              # s\n'
                 'cruise = 0.2                  # m/s, centre of the contact speeds from rest\n'
                 'brake = -0.1                  # m/s, centre after brake_time\n'
                 'spread = 0.05                 # m/s, half-width of the contact speeds around the centre\n',
                 'scenario = "simulation"\n') + "[simulation]\nt_end = 2.0\nv0 = 0.1\n"
    result = run_study(loads_scene(text))
    study = result.estimation
    # The recorded truth is the study's own simulation at the samples (dense output).
    np.testing.assert_allclose(study.record.truth_speed, result.simulation.speed_at(study.record.times),
                               rtol=0, atol=1e-15)
    assert study.duration == 2.0 and result.met


def test_ideal_viscosity_loop_stops_on_the_staircase_edge():
    # From rest under the staircase (-0.125 .. 0.325 m/s, spacing 2 f / k = 0.05 m/s) the body
    # speeds up until it meets the zero-force band [0.075, 0.125] and sticks at its lower
    # edge, the contact at 0.075 m/s: the equilibrium set's closed form (weighted median).
    from toolkit import ContactSet
    from toolkit.controllers import VirtualViscosity

    scene = loads_scene(_with(_with(VISCOSITY, "sensors = true", "sensors = false"), 'estimator = "kalman"\n', ""))
    study = control_scene(scene)
    speeds = VirtualViscosity(40.0, 0.1).speeds(build_scene(scene).plant)
    lo, hi = ContactSet(speeds, np.ones(10)).equilibrium()
    assert (lo, hi) == pytest.approx((0.075, 0.125), rel=0, abs=1e-15)
    assert study.loop.speed[-1] == pytest.approx(lo, rel=0, abs=1e-12)   # exact engine, rounding
    assert study.estimator is None
    # The smoothed model creeps inside the band: its differences shrink with the width, none 0.
    check = study.cross_check
    assert check.converges and np.all(check.differences > 0) and np.all(np.diff(check.differences) < 0)


def test_cross_check_takes_any_sensors_and_truth():
    # It runs the ideal loop on the plant (the controller on the true speed): encoder jitter
    # and the true world's drift are the sensor law's and the loop's, not what it checks.
    text = _with(LOOP, "cross_check = true", "cross_check = true\njitter = 0.001\n"
                 "truth = {contact_drift = 0.01}")
    assert build_scene(loads_scene(text)).control is not None


def test_loop_with_sensors_holds_its_speed_and_cross_checks():
    result = run_study(loads_scene(LOOP))
    assert result.met and result.control.estimator == "kalman"
    check = result.control.cross_check
    assert check.converges and np.all(check.differences > 0)
    loop = result.control.loop
    # The integral drives the estimated error to 0: the true speed ends within the loop's own
    # largest estimation error of the reference.
    assert abs(loop.speed[-1] - 0.1) <= np.max(np.abs(loop.estimation_error))


def test_open_loop_replays_the_designed_schedule():
    text = (ROOT / "designs" / "brake_schedule.toml").read_text()
    scene = loads_scene(text + '\n[control]\ncontroller = "open_loop"\nduration = 1.0\nsensors = false\n')
    result = run_study(scene)
    schedule, loop = result.schedule, result.control.loop
    k = np.searchsorted(schedule.times, loop.times, side="right") - 1
    rows = np.clip(k, 0, schedule.speeds.shape[0] - 1)
    # OpenLoop plays row k on [times[k], times[k+1]): the loop's commands are those rows.
    np.testing.assert_array_equal(loop.commands, schedule.speeds[rows])


def test_budget_stop_is_a_shortfall(tmp_path, capsys):
    path = tmp_path / "loop.toml"
    path.write_text(_with(LOOP, "cross_check = true", "cross_check = true\nbudget = {max_steps = 1}"))
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 3
    err = capsys.readouterr().err
    assert "shortfall: control: the closed loop stopped: step budget exhausted" in err
    data = json.loads((tmp_path / "out" / "result.json").read_text())
    assert data["shortfalls"][0]["stage"] == "control" and data["shortfalls"][0]["unit"] == "s"
    assert data["control"]["cross_check"] is None      # not compared when stopped


BAD = [
    # non-positive resolutions and rates (the constructors' rules, under the scene keys)
    (_with(ESTIMATE, "rate = 50.0 ", "rate = 0.0 "), "'sensors.rate'", "must be > 0. Got 0.0"),
    (_with(ESTIMATE, "rate = 50.0 ", "rate = -50.0 "), "'sensors.rate'", "must be > 0. Got -50.0"),
    (_with(ESTIMATE, "central_counts_per_rev = 8192", "central_counts_per_rev = 0"),
     "'sensors.central_counts_per_rev'", "must be > 0. Got 0"),
    (_with(ESTIMATE, "wheel_counts_per_rev = 3591.84", "wheel_counts_per_rev = -3591.84"),
     "'sensors.wheel_counts_per_rev'", "must be > 0"),
    (_with(LOOP, "sensors = true", "sensors = false\nrate = 0.0").replace('estimator = "kalman"\n', ""),
     "'control.rate'", "must be > 0. Got 0.0"),
    # more samples than the simulation can honour: the run's length is named (the rate is the
    # hardware's), with the longest it may be, (1e7 - 1) / rate
    (_with(ESTIMATE, "rate = 50.0 ", "rate = 5e6 "), "'estimation.duration'",
     "must be at most 2 s at sensors.rate = 5e+06 Hz (the estimation record takes at most 10000000 samples)"),
    (_with(ESTIMATE, "duration = ", "duration = 1e12 #"), "'estimation.duration'",
     "must be at most 200000 s at sensors.rate = 50 Hz"),
    (_with(LOOP, "duration = 2.0 ", "duration = 1e12 "), "'control.duration'", "at most 200000 s at sensors.rate"),
    (_with(_with(LOOP, "sensors = true", "sensors = false\nrate = 1.0"), 'estimator = "kalman"\n', "")
     .replace("duration = 2.0 ", "duration = 1e300 "), "'control.duration'", "at most 1e+07 s at control.rate = 1 Hz"),
    # covariances that are not symmetric positive definite
    (_with(ESTIMATE, "seed = 0", "seed = 0\ninitial_covariance = [[1e-8, 1e-9], [0.0, 1e-4]]"),
     "'estimation.initial_covariance'", "must be symmetric"),
    (_with(ESTIMATE, "seed = 0", "seed = 0\ninitial_covariance = [[1e-8, 0.0], [0.0, -1e-4]]"),
     "'estimation.initial_covariance'", "must be positive definite"),
    (_with(ESTIMATE, "seed = 0", "seed = 0\ninitial_covariance = [[1e-8, 0.0, 0.0], [0.0, 1e-4, 0.0]]"),
     "'estimation.initial_covariance'", "have shape (2, 2)"),
    # an estimator or a controller without the sensors it needs
    (BASE + ESTIMATE.split("[estimation]")[1].join(["[estimation]", ""]), "[estimation]", "needs [sensors]"),
    (_with(ESTIMATE, "central_counts_per_rev = 8192\ncontact_radius = 0.266        # m\n", ""),
     "[estimation]", "needs sensors.central_counts_per_rev"),
    (BASE + "[control]" + LOOP.split("[control]")[1], "[control]", "needs [sensors]"),
    (BASE + '[control]\ncontroller = "viscosity"\nslope = 40.0\nestimator = "kalman"\n',
     "'control.estimator'", "be left out of an ideal loop"),
    (BASE + '[control]\ncontroller = "viscosity"\nslope = 40.0\ncount_noise = 1.0\n',
     "'control.count_noise'", "be left out of an ideal loop"),
    (_with(LOOP, "sensors = true", "sensors = true\nrate = 100.0"), "'control.rate'", "equal sensors.rate"),
    # NaN or inf anywhere
    (_with(ESTIMATE, "cruise = 0.2 ", "cruise = nan "), "'estimation.cruise'", "must be finite"),
    (_with(LOOP, "slope = 40.0 ", "slope = inf "), "'control.slope'", "must be finite"),
    (_with(LOOP, "v0 = 0.0 ", "v0 = -inf "), "'control.v0'", "must be finite"),
    (_with(ESTIMATE, "speed_std = 1e-4 ", "speed_std = 0.0 "), "'estimation.speed_std'", "must be > 0"),
    (_with(ESTIMATE, "seed = 0", "seed = 0\ninitial_covariance = [[nan, 0.0], [0.0, 1.0]]"),
     "'estimation.initial_covariance[0][0]'", "must be finite"),
    (_with(LOOP, "cross_check = true", "cross_check = true\nbudget = {wall_time = nan}"),
     "'control.budget.wall_time'", "wall_time"),
    # rules of the values themselves
    (_with(LOOP, "slope = 40.0 ", "slope = -40.0 "), "'control.slope'", "must be > 0. Got -40.0"),
    (_with(ESTIMATE, "spread = 0.05 ", "spread = 0.2 "), "'estimation.cruise'",
     "must keep cruise +- estimation.spread (0.2 m/s) within the motors' speed limits [-0.35, 0.35] m/s. Got 0.2"),
    (_with(ESTIMATE, "brake = -0.1 ", "brake = -0.32 "), "'estimation.brake'", "speed limits"),
    (_with(ESTIMATE, "brake_time = 5.0 ", "brake_time = 11.0 "), "'estimation.brake_time'", "<= estimation.duration"),
    (_with(ESTIMATE, '"kalman", "rts"]', '"kalman", "rst"]'), "'estimation.methods[6]'", "Did you mean 'rts'?"),
    (_with(VISCOSITY, 'controller = "viscosity"', 'controller = "viscous"'), "'control.controller'",
     "Did you mean 'viscosity'?"),
    (_with(LOOP, 'estimator = "kalman"', 'estimator = "rts"'), "'control.estimator'", "one of"),
    (_with(VISCOSITY, "speed_limit = 0.35 ", "").replace('controller = "viscosity"\nslope = 40.0',
                                                    'controller = "friction_brake"\nfraction = 0.4')
     .replace("reference = 0.1 ", "start = 0.1 "),
     "'motors.speed_limit'", "finite motor speed limits"),
    (BASE + '[control]\ncontroller = "open_loop"\n', "'control.controller'", "needs a [schedule]"),
    (_with(LOOP, "lag = 0.0075 ", "rate_limit = 5.0\nlag = 0.0075 "), "'control.cross_check'", "rate_limit"),
]


@pytest.mark.parametrize(("text", "key", "rule"), BAD, ids=[f"{i}-{b[1]}" for i, b in enumerate(BAD)])
def test_bad_input_is_refused_naming_key_rule_and_value(text, key, rule):
    with pytest.raises(SceneError) as caught:
        build_scene(loads_scene(text))
    message = str(caught.value)
    assert key in message and rule in message, message


@pytest.mark.parametrize("index", [0, 5, 6, 9, 12, 19])   # 6: estimation.duration = 1e12
def test_bad_input_exits_2_with_one_line_and_writes_nothing(index, tmp_path):
    text, key, _ = BAD[index]
    scene = tmp_path / "bad.toml"
    scene.write_text(text)
    out = tmp_path / "out"
    for command in (["run", str(scene), "--out", str(out)], ["estimate", str(scene), "--out", str(out)]):
        done = subprocess.run([sys.executable, "-m", "toolkit.cli", *command], capture_output=True,
                              text=True, cwd=ROOT)
        assert done.returncode == 2, done.stderr
        assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr
        assert key in done.stderr
        assert not out.exists()


LAZY = ("filterpy", "control")


def _modules_after_run(text: str, tmp_path: Path) -> dict[str, bool]:
    path = tmp_path / "scene.toml"
    path.write_text(text)
    code = ("import json, sys\n"
            "from toolkit.scenes.spec import load_scene\n"
            "from toolkit.scenes.study import run_study\n"
            "from toolkit.scenes.report import study_to_dict\n"
            f"study_to_dict(run_study(load_scene({str(path)!r})))\n"
            f"print(json.dumps({{m: m in sys.modules for m in {LAZY!r}}}))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    return json.loads(done.stdout)


@pytest.mark.slow
def test_without_control_never_imports_control_and_without_sensors_never_filterpy(tmp_path):
    ideal = BASE + '[control]\ncontroller = "viscosity"\nslope = 40.0\nduration = 0.5\n'
    assert _modules_after_run(ideal, tmp_path) == {"filterpy": False, "control": False}
    # Positive controls: the same check sees filterpy once [sensors] + [estimation] are
    # declared (still no control), and control once [control] asks for its cross check.
    estimate = _with(ESTIMATE, "duration = 10.0 ", "duration = 1.0 ").replace("brake_time = 5.0 ", "brake_time = 0.5 ")
    assert _modules_after_run(estimate, tmp_path) == {"filterpy": True, "control": False}
    assert _modules_after_run(_with(LOOP, "duration = 2.0 ", "duration = 0.5 "), tmp_path)["control"] is True


def test_estimate_cli_json_has_the_documented_keys(tmp_path, capsys):
    assert main(["estimate", str(ROOT / "designs" / "estimate.toml"), "--json", "--out", str(tmp_path)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["duration"] == 10.0
    names = [row["name"] for row in data["estimators"]]
    assert names == ["central_difference", "wheel_difference", "foaw_end", "foaw_best", "alpha_beta", "kalman",
                     "rts"]
    for row in data["estimators"]:
        assert {"name", "rms", "max_error", "nees_mean", "wall_time", "rms_phases", "nees_in_band", "nees_over_100",
                "nees_max"} <= set(row)
        assert row["rms"] <= row["max_error"]          # RMS never exceeds the largest error
        assert set(row["rms_phases"]) == {"startup", "cruise", "brake", "braked"}
        # The overall mean square is the samples' weighted mean of the phases' (every sample
        # lies in one phase): it lies between the smallest and the largest phase's.
        phases = [v for v in row["rms_phases"].values() if v is not None]
        assert min(phases) <= row["rms"] <= max(phases)
    kalman = names.index("kalman")
    # NEES in band: a share of samples, for the estimators with a covariance only.
    assert 0.0 <= data["estimators"][kalman]["nees_in_band"] <= 1.0
    # The share above 100 and the largest NEES: consistent with each other (no NEES above
    # 100 exactly when the largest is at most 100).
    row = data["estimators"][kalman]
    assert 0.0 <= row["nees_over_100"] <= 1.0 and (row["nees_over_100"] > 0) == (row["nees_max"] > 100)
    assert data["estimators"][names.index("central_difference")]["nees_in_band"] is None
    # The missed-count rate the kalman position was reported under: the shipped scene's
    # encoders are ideal and the nominal model holds, so none (0, std 0); the baselines
    # do not use it (null).
    assert data["estimators"][kalman]["missed_count_prob"] == 0.0
    assert data["estimators"][kalman]["missed_count_std"] == 0.0
    assert data["estimators"][names.index("foaw_end")]["missed_count_prob"] is None
    saved = json.loads((tmp_path / "estimate.json").read_text())
    assert saved["estimators"][kalman]["rms"] == data["estimators"][kalman]["rms"]
    assert (tmp_path / "estimate.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # Run again into the same folder: the toolkit's own output is replaced, not refused.
    assert main(["estimate", str(ROOT / "designs" / "estimate.toml"), "--json", "--out", str(tmp_path)]) == 0
    assert json.loads(capsys.readouterr().out)["estimators"][kalman]["rms"] == data["estimators"][kalman]["rms"]


def test_estimate_cli_records_the_scenes_own_run_on_a_scene_without_estimation(tmp_path, capsys):
    # designs/carousel.toml has [sensors] and [simulation] but no [estimation]: its own run
    # (t_end = 5 s) is recorded and scored, never a scenario of other contacts.
    assert main(["estimate", str(ROOT / "designs" / "carousel.toml"), "--json", "--out", str(tmp_path)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["duration"] == 5.0 and len(data["estimators"]) == 7


def test_estimate_cli_refuses_a_scene_with_no_run_to_record(tmp_path):
    # designs/closed_loop.toml declares a loop, no [estimation] and no [simulation]: refused
    # (it used to score a brake scenario on other contacts without saying so).
    done = subprocess.run([sys.executable, "-m", "toolkit.cli", "estimate", "designs/closed_loop.toml",
                           "--out", str(tmp_path / "out")], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.count("\n") == 1 and "no [estimation] section and no [simulation]" in done.stderr
    assert not (tmp_path / "out").exists()


def test_estimate_without_sensors_is_a_one_line_user_error(tmp_path):
    done = subprocess.run([sys.executable, "-m", "toolkit.cli", "estimate", "designs/odd7.toml", "--out",
                           str(tmp_path / "out")], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 2
    assert done.stderr == ("active-contacts: error: The scene 'odd7' has no [sensors] section "
                           "(the encoders to estimate from).\n")
    assert not (tmp_path / "out").exists()


def test_shipped_designs_declare_the_new_stages():
    assert load_scene(ROOT / "designs" / "estimate.toml").estimation is not None
    assert load_scene(ROOT / "designs" / "closed_loop.toml").control.cross_check is True


# -- truth and belief apart, recorded logs ---------------------------------------------

TRUTH = "\n[estimation.truth]\nfriction_spread = 0.2\ndrag = 0.5\n\n[estimation.model]\ndrag_range = [0.0, 2.0]\n"


def test_estimation_truth_is_the_scenarios_true_world_and_the_estimators_are_not_told():
    # Second method: carousel_brake_scenario with the same WorldTruth, prior and seed records
    # the same true world (counts equal bit for bit) and gives the same default filter.
    from toolkit import ModelPrior, WorldTruth, build_estimator

    study = estimate_scene(loads_scene(ESTIMATE + TRUTH))
    reference = _scene_reference(truth=WorldTruth(friction_spread=0.2, drag=0.5),
                                 prior=ModelPrior(drag_range=(0.0, 2.0)))
    np.testing.assert_array_equal(study.record.central_counts, reference.record.central_counts)
    np.testing.assert_array_equal(study.record.wheel_counts, reference.record.wheel_counts)
    assert study.plant.damping == 0.5 and not np.allclose(study.plant.contacts.forces, 1.0)
    objects = build_scene(loads_scene(ESTIMATE + TRUTH)).estimation
    assert objects.model.damping == 0.0 and np.all(objects.model.forces == 1.0)     # the scene, not the truth
    rows = {row["name"]: row for row in study.rows()}
    expected = build_estimator("kalman", reference.model, prior=reference.prior).run(reference.record,
                                                                                     speed_std=1e-4)
    assert rows["kalman"]["rms"] == pytest.approx(expected.rms_error, rel=1e-12, abs=0)
    assert rows["kalman"]["monitor"].startswith("left the nominal model")          # it saw the mismatch
    # With a truth the default told it is reported last (truth_told), from the true world.
    from toolkit.estimation import truth_told

    assert list(rows)[-1] == "truth_told" and "truth_told" not in [r["name"] for r in estimate_scene(
        loads_scene(ESTIMATE)).rows()]
    told = truth_told(reference.world).run(reference.record, speed_std=1e-4)
    assert rows["truth_told"]["rms"] == pytest.approx(told.rms_error, rel=1e-12, abs=0)
    assert rows["truth_told"]["nees_max"] == pytest.approx(told.nees_max, rel=1e-12, abs=0)
    # The first line on this record: at most 1/5 of the best practitioner baseline.
    best = min(rows[name]["rms"] for name in ("central_difference", "foaw_end", "foaw_best", "alpha_beta"))
    assert rows["kalman"]["rms"] <= best / 5


@pytest.mark.parametrize(("extra", "key", "rule"), [
    ("\n[estimation.truth]\ndrag = -1.0\n", "estimation.truth.drag", "must be >= 0"),
    ("\n[estimation.truth]\ndrgg = 1.0\n", "[estimation.truth]", "Did you mean 'drag'?"),
    ("\n[estimation.model]\ndrag_range = [2.0, 1.0]\n", "estimation.model.drag_range", "low <= high"),
    ("\n[estimation.model]\nmissed_count_mean = 0.05\n", "estimation.model.missed_count_mean", "<= 0.01"),
    ("\n[estimation.truth]\njitter = 1.0\n", "estimation.truth.jitter", "'jitter' parameter of Sensors"),
    ("\n[estimation.truth]\nfriction_spread = 0.1\n", "estimation.truth.friction_spread", "give one of the two"),
])
def test_bad_truth_and_model_keys_are_refused_naming_the_key(extra, key, rule):
    text = ESTIMATE + extra
    if "give one of the two" in rule:
        text = _with(text, "seed = 0", "seed = 0\nfriction_spread = 0.05")
    with pytest.raises(SceneError) as caught:
        study = build_scene(loads_scene(text))
        estimate_scene(study)                         # the jitter is the true sensors': checked at run
    assert key in str(caught.value) and rule in str(caught.value), str(caught.value)


def test_saved_record_round_trips_and_a_recorded_log_gives_the_same_estimates(tmp_path):
    saved = tmp_path / "record.csv"
    out1, out2 = tmp_path / "sim", tmp_path / "log"
    assert main(["estimate", str(ROOT / "designs" / "estimate.toml"), "--out", str(out1),
                 "--save-record", str(saved)]) == 0
    from toolkit import read_record_csv

    record = read_record_csv(saved)
    study = estimate_scene(load_scene(ROOT / "designs" / "estimate.toml"))
    for name in ("times", "central_counts", "wheel_counts", "commands", "truth_speed", "truth_position"):
        np.testing.assert_array_equal(getattr(record, name), getattr(study.record, name))   # bit for bit
    assert main(["estimate", str(ROOT / "designs" / "estimate.toml"), "--out", str(out2), "--record", str(saved)]) == 0
    sim, log = (json.loads((o / "estimate.json").read_text())["estimators"] for o in (out1, out2))
    assert [r["rms"] for r in sim] == [r["rms"] for r in log]        # the same arithmetic on the same counts
    header = (out2 / "estimate.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "time_s" and "kalman_speed_m_s" in header and "kalman_nis" in header


def test_a_log_without_truth_is_estimated_and_a_malformed_one_refused_with_its_line(tmp_path):
    from toolkit import read_record_csv

    study = estimate_scene(load_scene(ROOT / "designs" / "estimate.toml"))
    plain = tmp_path / "hardware.csv"
    from toolkit.model.record_io import record_csv_text
    from dataclasses import replace

    bare = replace(study.record, truth_speed=None, truth_position=None, truth_contact_speeds=None)
    plain.write_text(record_csv_text(bare))
    assert read_record_csv(plain).truth_speed is None
    done = subprocess.run([sys.executable, "-m", "toolkit.cli", "estimate", "designs/estimate.toml", "--json",
                           "--record", str(plain), "--out", str(tmp_path / "o")], capture_output=True, text=True,
                          cwd=ROOT)
    assert done.returncode == 0, done.stderr
    rows = {row["name"]: row for row in json.loads(done.stdout)["estimators"]}
    assert rows["kalman"]["rms"] is None and rows["kalman"]["nis_mean"] > 0 and rows["kalman"]["monitor"]
    lines = plain.read_text().splitlines()
    lines[9] = lines[9].replace(",", ",x", 1)
    plain.write_text("\n".join(lines) + "\n")
    done = subprocess.run([sys.executable, "-m", "toolkit.cli", "estimate", "designs/estimate.toml",
                           "--record", str(plain), "--out", str(tmp_path / "p")], capture_output=True, text=True,
                          cwd=ROOT)
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and "line 10" in done.stderr, done.stderr
    assert not (tmp_path / "p").exists()


def test_control_truth_runs_the_loop_on_the_true_world_with_the_scenes_estimator():
    text = _with(LOOP, "cross_check = true ", "cross_check = false") + (
        "\n[control.truth]\nfriction_spread = 0.2\n\n[control.model]\nfriction_spread = 0.3\n")
    text = _with(text, "duration = 2.0 ", "duration = 3.0 ")
    study = control_scene(loads_scene(text))
    nominal = control_scene(loads_scene(_with(_with(LOOP, "cross_check = true ", "cross_check = false"),
                                               "duration = 2.0 ", "duration = 3.0 ")))
    loop, ideal = study.loop, nominal.loop
    assert not np.allclose(loop.speed, ideal.speed)                   # another world: another motion
    # The closed-loop line: after the first second the in-loop estimate errs by at most
    # a tenth of what the central difference would (4.5 mm/s there, tests/test_closed_loop.py).
    late = loop.times >= 1.0
    error = float(np.sqrt(np.mean((loop.estimate[late] - loop.speed[late]) ** 2)))
    from toolkit import CentralDifference

    difference = CentralDifference(build_scene(loads_scene(text)).control.sensors).run(loop.record)
    central = float(np.sqrt(np.mean((difference.speed[late] - loop.speed[late]) ** 2)))
    assert error <= central / 10, (error, central)


def test_a_brake_between_samples_reaches_the_motors_then_and_the_record_one_sample_later():
    # Six 4 N wheels under a 2 kg body read at 20 Hz, braked at 4.0536 s: between the samples
    # at 4.05 and 4.10 s. The motors switch at 4.0536 s; the record carries only what the
    # device logs (times on the grid, counts, the commands sent at each sample), so the brake
    # command shows from 4.10 s, and nothing in it holds 4.0536.
    from toolkit.model.record_io import record_csv_text

    text = _with(ESTIMATE, "speeds = [0.15, 0.161, 0.172, 0.183, 0.194, 0.206, 0.217, 0.228, 0.239, 0.25]",
                 "speeds = [0.15, 0.17, 0.19, 0.21, 0.23, 0.25]")
    text = _with(text, "forces = 1.0", "forces = 4.0")
    text = _with(text, "inertia = 0.353780            # kg m^2: moving mass I / L^2 = 5.0 kg\n"
                       "contact_radius = 0.266        # m\n", "mass = 2.0\n")
    text = _with(text, "rate = 50.0", "rate = 20.0")
    text = _with(text, "brake_time = 5.0", "brake_time = 4.0536")
    study = estimate_scene(loads_scene(text))
    record = study.record
    np.testing.assert_array_equal(record.times, np.arange(201) / 20.0)     # the sample grid, exactly
    cruise, brake = 0.2 + np.linspace(-0.05, 0.05, 6), -0.1 + np.linspace(-0.05, 0.05, 6)
    k = 81                                                                  # t = 4.05 s
    np.testing.assert_array_equal(record.commands[: k + 1], np.tile(cruise, (k + 1, 1)))
    np.testing.assert_array_equal(record.commands[k + 1:], np.tile(brake, (201 - k - 1, 1)))
    # The motors got it at 4.0536 s: at 4.10 s each contact is the first-order lag's closed
    # form from there (tau = 7.5 ms; rtol 1e-12: the flow's exponentials, rounding only).
    settled = brake + (cruise - brake) * np.exp(-(4.10 - 4.0536) / 0.0075)
    np.testing.assert_allclose(record.truth_contact_speeds[k + 1], settled, rtol=1e-12, atol=0)
    # The brake completes within that sample: at 4.05 s the body rides the cruise set, at
    # 4.10 s it is within the braking set (24 N on 2 kg sheds 0.3 m/s in 25 ms).
    assert cruise[0] <= record.truth_speed[k] <= cruise[-1]
    assert brake[0] <= record.truth_speed[k + 1] <= brake[-1]
    csv = record_csv_text(record)
    header = csv.splitlines()[[line.startswith("time_s") for line in csv.splitlines()].index(True)]
    logged = header.split(",")[: 2 + 6 + 6]
    assert logged == (["time_s", "central_count"] + [f"wheel_count_{i}" for i in range(1, 7)]
                      + [f"command_{i}_m_s" for i in range(1, 7)])
    assert "4.0536" not in csv


def test_the_seed_moves_the_encoders_grid_phase():
    # A nominal scene (no noise, no truth) draws nothing but the grids' phase: its seed puts
    # the body and the wheels within one count of their grids (grid_positions, the seed's
    # grid stream), so two seeds give two records and two sets of estimates.
    from toolkit.analysis.scenarios import grid_positions

    studies = {seed: estimate_scene(loads_scene(_with(ESTIMATE, "seed = 0", f"seed = {seed}")))
               for seed in (0, 1)}
    for seed, study in studies.items():
        grid = grid_positions(build_scene(loads_scene(ESTIMATE)).estimation.sensors, seed)
        # The body starts at rest where the seed put it (the true position at t = 0, exactly).
        assert study.record.truth_position[0] == grid["central_position"]
        assert 0.0 < grid["central_position"] < study.record.central_resolution
    assert not np.array_equal(studies[0].record.central_counts, studies[1].record.central_counts)
    kalman = [next(r for r in study.results if r.method == "kalman").speed for study in studies.values()]
    assert not np.array_equal(*kalman)
    # The grid's phase does not move the truth: the body's speeds agree (the same run).
    np.testing.assert_array_equal(studies[0].record.truth_speed, studies[1].record.truth_speed)
