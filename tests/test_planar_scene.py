"""Planar scenes: [planar] parsed, built and run by 'active-contacts run'; 1-D scenes never
load the planar package."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import toolkit
from toolkit.cli import main
from toolkit.errors import SceneError
from toolkit.planar import terminal_ratio
from toolkit.scenes.build import build_scene
from toolkit.scenes.spec import dumps_scene, load_scene, loads_scene
from toolkit.scenes.study import planar_scene

ROOT = Path(toolkit.__file__).resolve().parents[1]
DISC = ROOT / "designs" / "sliding_disc.toml"
LEGS = """
[scene]
name = "tripod"
[planar]
body = "legs"
positions = [[0.1, 0.06], [-0.1, 0.06], [0.0, -0.06]]
velocities = [[0.1, 0.0], [0.1, 0.0], [0.12, 0.01]]
forces = [1.0, 1.0, 1.5]
mass = 0.5
inertia = 0.002
t_end = 0.5
method = "moreau"
step = 0.005
"""


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT)
    return env


@pytest.mark.slow
def test_cli_prints_the_terminal_ratio_of_the_sliding_disc(tmp_path):
    out = subprocess.run([sys.executable, "-m", "toolkit.cli", "run", str(DISC), "--json", "--out",
                          str(tmp_path / "disc")], capture_output=True, text=True, cwd=ROOT, env=_env())
    assert out.returncode == 0, out.stderr
    planar = json.loads(out.stdout)["planar"]
    # Published 0.653 (three digits: within half a unit of the last one) and the closed-form
    # fixed point (Brent to 1e-15; the reduced ODE converges to it to about 1e-13).
    assert abs(planar["terminal_ratio"] - 0.653) <= 5e-4
    assert abs(planar["terminal_ratio"] - terminal_ratio()) <= 1e-9
    assert planar["published_ratio"] == 0.653 and "Farkas" in planar["published_source"]
    assert planar["shortfalls"] == [] and planar["stop_time"] < planar["t_end"]
    rows = planar["precision"]["rows"]
    moreau = [r["max_error"] for r in rows if r["method"] == "moreau"]
    assert moreau == sorted(moreau, reverse=True)        # refined together: the error falls


def test_a_legs_scene_runs_and_reports_its_equilibrium(tmp_path):
    path = tmp_path / "tripod.toml"
    path.write_text(LEGS)
    scene = load_scene(path)
    assert loads_scene(dumps_scene(scene), name=scene.name) == scene
    result = planar_scene(build_scene(scene))
    eq = result.equilibrium
    assert eq.certified and result.terminal_ratio is None
    data = result.to_dict()
    assert data["equilibrium"]["status"] in ("OPTIMAL", "SEGMENT") and data["shortfalls"] == []
    # After 0.5 s a 0.5 kg body on 3.5 N of friction has settled on the equilibrium twist
    # (in the body frame: the contacts turn with the body). Moreau-Jean takes the contacts at
    # the step's starting heading: a first-order lag of |V| omega h ~ 0.11 * 0.12 * 0.005 =
    # 7e-5 m/s in the steady state, hence atol 2e-4.
    sim = result.simulation
    c, s = np.cos(sim.heading[-1]), np.sin(sim.heading[-1])
    body = np.array([[c, s], [-s, c]]) @ sim.velocity[-1]
    np.testing.assert_allclose([*body, sim.omega[-1]], eq.twist, rtol=0, atol=2e-4)


@pytest.mark.parametrize("text,message", [
    ("[planar]\nbody = 'disk'\nmass = 1.0\n", "Did you mean 'disc'"),
    ("[planar]\nbody = 'disc'\nmass = 1.0\nradius = 0.1\nmu = 0.2\nradious = 2\n", "Unknown key 'radious'"),
    ("[planar]\nbody = 'disc'\nmass = 1.0\nmu = 0.2\n", "needs the key 'radius'"),
    ("[planar]\nbody = 'disc'\nmass = 1.0\nradius = 0.1\nmu = 0.2\n[contacts]\nspeeds = [0.1]\n",
     r"remove \[contacts\]"),
    ("[planar]\nbody = 'disc'\nmass = -1.0\nradius = 0.1\nmu = 0.2\n", "'planar.mass' value in the scene must be > 0"),
    ("[planar]\nbody = 'disc'\nmass = 1.0\nradius = 0.1\nmu = 0.2\nmethod = 'smooth'\n", "'epsilon'"),
    ("[planar]\nbody = 'disc'\nmass = 1.0\nradius = 0.1\nmu = 0.2\nv0 = [2.0]\n", r"2-vector.*scene key 'planar.v0'"),
    ("[planar]\nbody = 'disc'\nmass = 1.0\nradius = 0.1\nmu = 0.2\nomega0 = 1e200\n",
     r"rim speeds <= 1e\+100.*scene key 'planar.omega0'"),
    # Legs off a line have no closed form: 'exact' refused when built, by its scene key.
    ("[planar]\nbody = 'legs'\nmass = 1.0\ninertia = 0.01\npositions = [[0.1, 0.0], [-0.1, 0.0], [0.0, 0.1]]\n"
     "velocities = [[0.1, 0.0], [0.0, 0.1], [0.0, 0.0]]\nforces = [1.0, 2.0, 1.5]\nmethod = 'exact'\n",
     r"be 'exact' only for a plant with a closed form.*scene key 'planar.method'"),
])
def test_bad_planar_sections_are_refused(text, message):
    with pytest.raises(SceneError, match=message):
        build_scene(loads_scene(text))


@pytest.mark.slow
def test_precision_on_a_planar_scene_is_its_work_precision_report(tmp_path, capsys):
    # 'active-contacts precision' on the disc prints and writes the planar report; its errors
    # are the library's own (toolkit.planar.precision_report with the scene's settings: a
    # second call, bit for bit, since the runs are deterministic; only wall times differ).
    from toolkit.planar import precision_report

    assert main(["precision", str(DISC), "--json", "--out", str(tmp_path / "p")]) == 0
    data = json.loads(capsys.readouterr().out)
    objects = build_scene(load_scene(DISC)).planar
    settings = objects.spec.precision
    direct = precision_report(objects.plant, objects.spec.t_end, v0=objects.v0, omega0=objects.omega0,
                              steps=tuple(settings["steps"]), resolutions=tuple(settings["resolutions"]),
                              epsilons=tuple(settings["epsilons"]))
    assert [(r["method"], r["setting"], r["max_error"]) for r in data["rows"]] == \
        [(r.method, r.setting, r.max_error) for r in direct.rows]
    assert sorted(p.name for p in (tmp_path / "p").iterdir()) == ["precision.json", "precision.png"]
    # A leg set has no closed form to measure against: refused in one line (exit 2).
    legs = tmp_path / "tripod.toml"
    legs.write_text(LEGS)
    assert main(["precision", str(legs)]) == 2
    err = capsys.readouterr().err
    assert "closed form" in err and len(err.strip().splitlines()) == 1


def test_other_commands_refuse_a_planar_scene(capsys):
    assert main(["curve", str(DISC), "--json"]) == 2
    err = capsys.readouterr().err
    assert "planar scene" in err and "active-contacts run" in err and len(err.strip().splitlines()) == 1


def test_one_dimensional_scenes_never_load_the_planar_package(tmp_path):
    code = ("import sys, toolkit\n"
            "from toolkit.cli import main\n"
            f"assert main(['run', {str(ROOT / 'designs' / 'five_five.toml')!r}, '--out', {str(tmp_path / 'o')!r}]) == 0\n"
            "print([m for m in sys.modules if m.startswith('toolkit.planar')])\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                         env=_env(), check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]"


def test_docs_planar_sections_cited_in_the_code_exist():
    import re
    import subprocess as sp

    doc = (ROOT / "docs" / "planar.md").read_text()
    sections = set(re.findall(r"^## (\d+)\.", doc, flags=re.M))
    files = sp.run(["git", "ls-files", "--", "toolkit", "tests", "notebooks"], cwd=ROOT, capture_output=True,
                   text=True, check=True).stdout.split()
    cite = re.compile(r"docs/planar\.md`?,?\s+sections?\s+(\d+)")
    seen = 0
    for name in files:
        path = ROOT / name
        if path.suffix in (".py", ".toml", ".ipynb") and path.is_file():
            for match in cite.finditer(path.read_text(encoding="utf-8")):
                seen += 1
                assert match.group(1) in sections, f"{name} cites docs/planar.md section {match.group(1)}"
    assert seen >= 15
