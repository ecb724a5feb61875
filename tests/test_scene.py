"""Scene files: validation, refusals with suggestions, round trips, and lazy imports."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from toolkit import SceneError, SceneFileNotFoundError
from toolkit.scenes.spec import dumps_scene, load_scene, loads_scene
from toolkit.scenes.build import build_scene

DESIGNS = sorted((Path(__file__).parents[1] / "designs").glob("*.toml"))
MINIMAL = '[contacts]\nspeeds = [0.1, 0.2, 0.3]\n'


@pytest.mark.parametrize("path", DESIGNS, ids=lambda p: p.stem)
def test_every_design_loads_and_round_trips(path):
    scene = load_scene(path)
    again = loads_scene(dumps_scene(scene), name=scene.name)
    assert again == scene
    if scene.planar is not None:       # a planar scene: its plant, from the same spec
        assert build_scene(again).planar.spec == build_scene(scene).planar.spec
    elif scene.sweep is None:
        np.testing.assert_array_equal(build_scene(again).contacts.speeds, build_scene(scene).contacts.speeds)
    else:
        assert build_scene(again).sweep == build_scene(scene).sweep


def test_carousel_has_the_papers_hardware():
    scene = load_scene(Path(__file__).parents[1] / "designs" / "carousel.toml")
    contacts = build_scene(scene).contacts
    assert contacts.n == 10
    assert np.all(np.abs(contacts.speeds) <= 0.35)
    assert scene.motors.speed_limits == (-0.35, 0.35)
    # F_tot / m = 2 m/s^2 (docs/physics.md section 6): I / L^2 = 0.353780 / 0.266^2 = 5.000 kg;
    # rtol 1e-5 because the inertia is written with 6 significant digits.
    np.testing.assert_allclose(contacts.total_force / scene.body.moving_mass, 2.0, rtol=1e-5)


def test_carousel_design_states_the_models_carousel():
    # The shipped design and toolkit.model.carousel.CAROUSEL (what the reference scenarios and
    # predictions build on) state one carousel, to the last bit.
    from toolkit.model.carousel import CAROUSEL

    objects = build_scene(load_scene(Path(__file__).parents[1] / "designs" / "carousel.toml"))
    sensors = objects.sensors
    assert objects.contacts.n == CAROUSEL.n_wheels
    np.testing.assert_array_equal(objects.contacts.forces, CAROUSEL.wheel_force)
    assert objects.plant.mass == CAROUSEL.moving_mass         # the same arithmetic: I / L^2
    assert objects.motors == CAROUSEL.motors()
    assert sensors == CAROUSEL.sensors()


def test_random_contacts_are_reproducible():
    text = '[contacts]\nrandom = { n = 5, low = -0.3, high = 0.3, seed = 4 }\n'
    a, b = build_scene(loads_scene(text)).contacts, build_scene(loads_scene(text)).contacts
    np.testing.assert_array_equal(a.speeds, b.speeds)
    np.testing.assert_array_equal(a.speeds, np.random.default_rng(4).uniform(-0.3, 0.3, 5))


def test_mu_and_normal_loads_give_forces():
    scene = loads_scene('[contacts]\nspeeds = [0.1, 0.2]\nmu = 0.5\nnormal_loads = [2.0, 4.0]\n')
    np.testing.assert_array_equal(build_scene(scene).contacts.forces, [1.0, 2.0])


def test_missing_sections_mean_no_stage():
    scene = loads_scene(MINIMAL)
    assert scene.stages == ("curve",)
    assert scene.body is None and scene.simulation is None and scene.target is None


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("[contacts]\nspeds = [0.1]\n", "Did you mean 'speeds'?"),
        (MINIMAL + "[bodi]\nmass = 1.0\n", "Did you mean 'body'?"),
        (MINIMAL + "[body]\nmas = 1.0\n", "Did you mean 'mass'?"),
        (MINIMAL + "[motors]\nspeed_limit = -0.3\n", "'motors.speed_limit' value in the scene must be > 0"),
        ("[contacts]\nspeeds = [0.1, nan]\n", "'contacts.speeds[1]' value in the scene must be finite"),
        ("[contacts]\nspeeds = [0.1, 0.2]\nforces = [1.0, -1.0]\n", "must be >= 0"),
        ("[contacts]\nspeeds = [0.1, 0.2]\nforces = [1.0]\n", "same length as 'speeds'"),
        ("[contacts]\nspeeds = [0.1, 0.2]\nforces = 0.0\n", "positive sum"),
        ("[contacts]\nspeeds = []\n", "non-empty array"),
        ('[contacts]\nspeeds = "fast"\n', "array of numbers"),
        ("[contacts]\nspeeds = [true]\n", "be a number"),
        ("[body]\nmass = 1.0\n", "needs a [contacts] section"),
        (MINIMAL + "[body]\ninertia = 1.0\n", "'contact_radius'"),
        (MINIMAL + "[simulation]\nt_end = 1.0\n", "needs a [body] section"),
        (MINIMAL + "[target]\nkind = \"viscosty\"\n", "Did you mean 'viscosity'?"),
        (MINIMAL + "[target]\nkind = \"viscosity\"\nslope = 1.0\n", "needs the key 'center'"),
        (MINIMAL + "[estimator]\nkind = \"kalman\"\n", "Did you mean [estimation]?"),
        (MINIMAL + "[controller]\nkind = \"viscosity\"\n", "Did you mean [control]?"),
        ("[contacts\n", "not valid TOML"),
        (MINIMAL + "[body]\nmass = 1.0\nexternal_force = { times = [1.0, 0.5], values = [0, 1, 2] }\n",
         "strictly increasing"),
        (MINIMAL + '[body]\nmass = 1.0\n[schedule]\nkind = "brake"\nspeed = 0.0\n', "Did you mean 'braking'?"),
        (MINIMAL + '[body]\nmass = 1.0\n[schedule]\nkind = "track"\ntimes = [0.0]\n', "needs the key 'speeds'"),
        (MINIMAL + '[schedule]\nkind = "braking"\nspeed = 0.0\n', "needs a [body] section"),
        (MINIMAL + '[body]\nmass = 1.0\n[schedule]\nkind = "braking"\nspeed = 0.0\nperiod = 0\n',
         "'schedule.period' value in the scene must be > 0"),
        ("[contacts]\nrandom = { n = 100000000000, low = 0.0, high = 1.0 }\n", "<= 10000000"),
        (MINIMAL + "[report]\ncurve_points = 100000000000\n", "<= 1118481"),
        (MINIMAL + '[target]\nkind = "viscosity"\nslope = 1.0\ncenter = 0.0\nband = [0.1, 0.2, 0.3]\n',
         "In [target]: The 'band' parameter"),
        (MINIMAL + '[target]\nkind = "force_curve"\nspeeds = [0.2, 0.1]\nforces = [1.0, 0.0]\n', "In [target]:"),
        (MINIMAL + '[target]\nkind = "friction_fraction"\nfraction = 0.5\nband = 0.3\nmethod = "milpp"\n',
         "Did you mean 'milp'?"),
        (MINIMAL + '[target]\nkind = "friction_fraction"\nfraction = 0.5\nband = 0.3\nfixed = [5]\n',
         "indices below n = 3"),
        (MINIMAL + '[target]\nkind = "friction_fraction"\nfraction = 0.5\nband = 0.3\ndt = 0.1\n',
         "needs [motors] rate_limit"),
        (MINIMAL + '[body]\nmass = 1.0\n[schedule]\nkind = "track"\ntimes = [1.0, 0.0]\nspeeds = [0.0, 0.1]\n',
         "In [schedule]:"),
        (MINIMAL + '[body]\nmass = 1.0\n[simulation]\nt_end = 1.0\n'
                   'commands = { times = [0.5], values = [[0.0, 0.1, 0.2], [1.0, 2.0]] }\n',
         "one speed per contact (3)"),
        ('[scene]\nname = "../../tmp/x"\n' + MINIMAL, "plain name"),
    ],
)
def test_bad_scenes_are_refused_with_a_clear_message(text, fragment):
    with pytest.raises(SceneError) as info:
        build_scene(loads_scene(text))
    assert fragment in str(info.value)


def test_missing_file():
    with pytest.raises(SceneFileNotFoundError, match="does not exist"):
        build_scene(load_scene("designs/no-such-scene.toml"))
    with pytest.raises(FileNotFoundError):
        build_scene(load_scene("designs/no-such-scene.toml"))


def test_scene_is_frozen():
    scene = loads_scene(MINIMAL)
    with pytest.raises(AttributeError):
        scene.name = "other"  # type: ignore[misc]


LAZY = ("casadi", "cvxpy", "filterpy", "matplotlib", "pandas", "tqdm", "distributed")


def _modules_after_run(scene_text: str, tmp_path: Path) -> dict[str, bool]:
    path = tmp_path / "scene.toml"
    path.write_text(scene_text)
    code = (
        "import json, sys\n"
        "from toolkit.scenes.spec import load_scene\n"
        "from toolkit.scenes.study import run_study\n"
        "from toolkit.scenes.report import write_study\n"
        f"write_study(run_study(load_scene({str(path)!r})), {str(tmp_path / 'out')!r})\n"
        f"print(json.dumps({{m: m in sys.modules for m in {LAZY!r}}}))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(done.stdout)


def test_undeclared_stages_import_nothing_they_need(tmp_path):
    loaded = _modules_after_run(MINIMAL, tmp_path)
    assert loaded == dict.fromkeys(LAZY, False)


def test_declared_report_does_import_matplotlib(tmp_path):
    # The positive control: the same check sees matplotlib once plots are declared.
    loaded = _modules_after_run(MINIMAL + "[report]\nplots = true\n", tmp_path)
    assert loaded["matplotlib"] is True
    assert (loaded["casadi"], loaded["cvxpy"], loaded["filterpy"]) == (False, False, False)


def test_sweep_scene_loads_pandas_but_not_dask(tmp_path):
    # A sweep scene's stage imports pandas (its table) and nothing of the other stages; Dask
    # only for a cluster scheduler.
    path = tmp_path / "sweep.toml"
    path.write_text('[sweep]\nexperiment = "median_law"\nruns = 10\n')
    code = ("import json, sys\n"
            "from toolkit.cli import main\n"
            f"main(['sweep', {str(path)!r}, '--json'])\n"
            f"print(json.dumps({{m: m in sys.modules for m in {LAZY!r}}}), file=sys.stderr)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded = json.loads(done.stderr.strip().splitlines()[-1])
    assert loaded["pandas"] is True
    assert not any(loaded[m] for m in ("casadi", "cvxpy", "filterpy", "matplotlib", "distributed"))


SWEEP = '[scene]\nname = "ml"\n[sweep]\nexperiment = "median_law"\nruns = 30\nseed = 2\n'


def test_sweep_section_round_trip_and_objects():
    scene = loads_scene(SWEEP + 'friction_spread = 0.2\nwheel_seed = 1\nstatistics = ["slope"]\n')
    assert scene.stages == ("sweep",) and scene.contacts is None
    assert build_scene(scene).sweep.friction_spread == 0.2 and build_scene(scene).sweep.wheel_seed == 1
    assert loads_scene(dumps_scene(scene)) == scene
    with pytest.raises(TypeError):           # the spec is frozen, its parameters too
        scene.sweep.params["friction_spread"] = 0.5


@pytest.mark.parametrize(("extra", "match"), [
    ('friction_spread = -0.1\n', r"In \[sweep\]: The 'friction_spread' parameter of MedianLaw must be >= 0"),
    ('frction_spread = 0.1\n', "Did you mean 'friction_spread'"),
    ('statistics = ["slop"]\n', "Did you mean 'slope'"),
    ('runs = 0\n', "'sweep.runs'"),
    ('runs = 100000000\n', r"The 'sweep.runs' value in the scene must be an integer <= 10000000"),
    ('n = 100000000000\n', r"In \[sweep\]: The 'n' parameter of MedianLaw must be <= 10000"),
    ('name = "x"\n', "Unknown key 'name'"),
    ('[body]\nmass = 1.0\n', r"remove \[body\]"),
])
def test_sweep_section_errors(extra, match):
    with pytest.raises(SceneError, match=match):
        build_scene(loads_scene(SWEEP.replace("runs = 30\n", "") + extra if extra.startswith("runs") else SWEEP + extra))


def test_target_constraints_round_trip():
    text = MINIMAL + ('[motors]\nspeed_limit = 0.35\nrate_limit = 2.0\n'
                      '[target]\nkind = "viscosity"\nslope = 20.0\ncenter = 0.0\nband = 0.2\n'
                      'dt = 0.05\nfixed = [0]\nliftable = [1, 2]\nmethod = "milp"\n')
    scene = loads_scene(text)
    assert (scene.target.dt, scene.target.fixed, scene.target.liftable) == (0.05, (0,), (1, 2))
    assert loads_scene(dumps_scene(scene)) == scene


@pytest.mark.parametrize(
    ("text", "key", "rule"),
    [
        (MINIMAL + "[motors]\nlag = -0.1\n", "'motors.lag'", "The 'lag' parameter of Motors must be >= 0. Got -0.1"),
        (MINIMAL + "[body]\nmass = -1.0\n", "'body.mass'", "The 'mass' parameter of Plant must be > 0. Got -1.0"),
        (MINIMAL + "[sensors]\nwheel_counts_per_rev = 48\nwheel_radius = -0.045\n", "'sensors.wheel_radius'",
         "The 'radius' parameter of Encoder must be > 0. Got -0.045"),
        (MINIMAL + "[body]\nmass = 1.0\nexternal_force = { times = [0.5], values = [0.0, 1.0, 2.0] }\n",
         "'body.external_force.values'", "The 'values' parameter of PiecewiseConstant must have one more row"),
    ],
)
def test_constructor_rules_are_refused_under_the_scene_key(text, key, rule):
    # Each value is checked once, by the constructor that takes it; the scene names the key.
    with pytest.raises(SceneError) as info:
        build_scene(loads_scene(text))
    message = str(info.value)
    assert f"(scene key {key})" in message and rule in message


def test_loading_builds_nothing_and_each_build_is_fresh():
    path = Path(__file__).parents[1] / "designs" / "carousel.toml"
    scene = load_scene(path)
    assert not hasattr(scene, "objects")          # a parsed scene is specs only
    objects = build_scene(scene)
    again = build_scene(scene)                    # a run's own objects: never shared between runs
    assert again is not objects and again.contacts is not objects.contacts and again.scene is scene
    np.testing.assert_array_equal(again.contacts.speeds, objects.contacts.speeds)
    assert objects.plant.contacts is objects.contacts and objects.plant.motors is objects.motors
    assert set(objects.encoders) == {"wheel", "central"}
    # F_tot / m = 2 m/s^2 (docs/physics.md section 6), rtol 1e-5 as in the carousel test above.
    np.testing.assert_allclose(objects.contacts.total_force / objects.plant.mass, 2.0, rtol=1e-5)
    assert load_scene(path) == scene            # the built objects are not part of equality


# -- speed limits -------------------------------------------------------------------

LIMITED = "[motors]\nspeed_limit = 0.35\n"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[contacts]\nspeeds = [0.1, -0.5, 0.2]\n" + LIMITED,
         "The 'contacts.speeds' value in the scene must lie within the motors' speed limits [-0.35, 0.35] "
         "m/s (or set [motors] clip = true to clip it). Got -0.5 m/s (entry [1], beyond the limit -0.35 m/s) "
         "instead."),
        ("[contacts]\nrandom = { n = 5, low = 0.0, high = 1.0, seed = 0 }\n[motors]\nspeed_limits = [-0.1, 0.2]\n",
         None),
        (MINIMAL + LIMITED + "[body]\nmass = 1.0\n[simulation]\nt_end = 1.0\n"
                             "commands = { times = [0.5], values = [[0.0, 0.1, 0.2], [0.0, 0.4, 0.2]] }\n",
         "The 'simulation.commands' value in the scene must lie within the motors' speed limits [-0.35, "
         "0.35] m/s (or set [motors] clip = true to clip it). Got 0.4 m/s (entry [1, 1], beyond the limit "
         "0.35 m/s) instead."),
    ],
)
def test_speeds_beyond_the_motor_limits_are_refused(text, message):
    with pytest.raises(SceneError) as info:
        build_scene(loads_scene(text))
    if message is None:                         # random speeds: the largest draw above 0.2
        speeds = np.random.default_rng(0).uniform(0.0, 1.0, 5)
        message = (f"The 'contacts.random' value in the scene must lie within the motors' speed limits "
                   f"[-0.1, 0.2] m/s (or set [motors] clip = true to clip it). Got {speeds.max():g} m/s "
                   f"(entry [{speeds.argmax()}], beyond the limit 0.2 m/s) instead.")
    assert str(info.value) == message


def test_clip_true_clips_speeds_and_commands_and_round_trips():
    text = ("[contacts]\nspeeds = [0.1, -0.5, 0.2]\n" + LIMITED + "clip = true\n[body]\nmass = 1.0\n"
            "[simulation]\nt_end = 1.0\ncommands = { times = [0.5], values = [[0.0, 0.1, 0.2], [0.0, 0.4, 0.6]] }\n")
    scene = loads_scene(text)
    assert scene.motors.clip is True
    np.testing.assert_array_equal(build_scene(scene).contacts.speeds, [0.1, -0.35, 0.2])
    np.testing.assert_array_equal(build_scene(scene).plant.commands.values, [[0.0, 0.1, 0.2], [0.0, 0.35, 0.35]])
    clips = {clip.key: (clip.value, clip.limit, clip.count) for clip in build_scene(scene).clipped}
    assert clips == {"contacts.speeds": (-0.5, -0.35, 1), "simulation.commands": (0.6, 0.35, 2)}
    assert loads_scene(dumps_scene(scene), name=scene.name) == scene
    assert "clip = true" in dumps_scene(scene)


def test_simulation_budget_table_becomes_a_budget():
    from toolkit.simulation import Budget

    scene = loads_scene(MINIMAL + "[body]\nmass = 1.0\n[simulation]\nt_end = 1.0\n"
                                  "options = { budget = { wall_time = 2.5, max_steps = 7 } }\n")
    assert build_scene(scene).simulation_options == {"budget": Budget(wall_time=2.5, max_steps=7)}
    with pytest.raises(SceneError, match="Unknown key 'wall' in \\[simulation.options.budget\\]"):
        build_scene(loads_scene(MINIMAL + "[body]\nmass = 1.0\n[simulation]\nt_end = 1.0\noptions = { budget = { wall = 1 } }\n"))


# -- scene file edge cases: one line, exit 2, no traceback ---------------------------

def _cli_error(path: Path) -> str:
    done = subprocess.run([sys.executable, "-m", "toolkit.cli", "curve", str(path)], capture_output=True,
                          text=True, cwd=Path(__file__).parents[1])
    assert done.returncode == 2 and done.stdout == "" and "Traceback" not in done.stderr
    assert done.stderr.count("\n") == 1
    return done.stderr


def test_non_utf8_scene(tmp_path):
    path = tmp_path / "latin.toml"
    path.write_bytes(b"# caf\xe9\n" + MINIMAL.encode())
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert str(info.value) == f"The scene file {str(path)!r} is not UTF-8 text: byte 0xe9 at offset 5."
    assert "not UTF-8 text" in _cli_error(path)


def test_directory_as_scene(tmp_path):
    with pytest.raises(SceneError) as info:
        load_scene(tmp_path)
    assert str(info.value) == f"The scene path {str(tmp_path)!r} is a directory, not a scene file."
    assert "is a directory" in _cli_error(tmp_path)


def test_empty_scene(tmp_path):
    path = tmp_path / "empty.toml"
    path.write_text("\n  \n")
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert str(info.value) == (f"The scene file {str(path)!r} is empty; a scene needs at least a [contacts] "
                               "section.")
    assert "is empty" in _cli_error(path)


def test_scene_larger_than_the_cap(tmp_path):
    from toolkit.scenes.spec import MAX_SCENE_BYTES

    path = tmp_path / "huge.toml"
    path.write_bytes(MINIMAL.encode() + b"#" * (MAX_SCENE_BYTES + 1 - len(MINIMAL)))
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert MAX_SCENE_BYTES == 1048576
    assert str(info.value) == (f"The scene file {str(path)!r} is 1048577 bytes; scene files are limited to "
                               "1048576 bytes (1 MiB).")
    path.write_bytes(MINIMAL.encode() + b"#" * (MAX_SCENE_BYTES - len(MINIMAL)))   # exactly the cap: read
    assert load_scene(path).contacts.speeds == (0.1, 0.2, 0.3)
    path.write_bytes(b"#" * (5 << 20))
    assert "limited to 1048576 bytes (1 MiB)" in _cli_error(path)


def test_symlink_loop(tmp_path):
    a, b = tmp_path / "a.toml", tmp_path / "b.toml"
    a.symlink_to(b)
    b.symlink_to(a)
    with pytest.raises(SceneError) as info:
        load_scene(a)
    assert str(info.value) == f"The scene file {str(a)!r} is a symbolic link loop."
    assert "symbolic link loop" in _cli_error(a)


def test_unreadable_scene(tmp_path, monkeypatch):
    path = tmp_path / "locked.toml"
    path.write_text(MINIMAL)
    path.chmod(0)
    try:
        if os.geteuid() != 0:                   # root reads mode-0 files: patch open instead
            assert "Permission denied" in _cli_error(path)

        def refuse(*args, **kwargs):
            raise PermissionError(13, "Permission denied")

        monkeypatch.setattr("toolkit.scenes.spec.open", refuse, raising=False)
        with pytest.raises(SceneError) as info:
            load_scene(path)
        assert str(info.value) == f"The scene file {str(path)!r} cannot be read: Permission denied."
    finally:
        path.chmod(0o644)


HEAVY = ("filterpy", "control", "cvxpy", "casadi", "matplotlib")


def _imported_after(code: str) -> dict[str, bool]:
    script = code + f"\nimport json, sys\nprint(json.dumps({{m: m in sys.modules for m in {HEAVY!r}}}))\n"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True,
                          cwd=Path(__file__).parents[1])
    return json.loads(done.stdout.splitlines()[-1])


def test_loading_a_scene_imports_no_heavy_package_and_building_is_a_separate_call():
    load_all = ("from toolkit.scenes.spec import load_scene\n"
                "from toolkit.scenes.designs import design_names, load_design\n"
                "scenes = [load_design(name) for name in design_names()]\n")
    assert _imported_after(load_all) == dict.fromkeys(HEAVY, False)
    # Positive control: building the estimation scene makes its Kalman filter (filterpy),
    # and nothing else heavy; the check sees an import when there is one.
    built = _imported_after(load_all + "from toolkit.scenes.build import build_scene\n"
                            "build_scene(load_design('estimate'))\n")
    assert built == {**dict.fromkeys(HEAVY, False), "filterpy": True}
