"""The scene keys are declared once: the parser, the command line and the reference page follow
the declaration (:mod:`toolkit.scenes.spec`, :mod:`toolkit.scenes.reference`)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from toolkit.errors import SceneError
from toolkit.scenes.reference import render
from toolkit.scenes.spec import (SCENE_KEYS, SECTIONS, ControlSpec, EstimationSpec, MotorsSpec, ReportSpec,
                                 SensorsSpec, TargetSpec, loads_scene)

ROOT = Path(__file__).resolve().parents[1]
MINIMAL = "[contacts]\nspeeds = [0.1, 0.2, 0.3]\n"


def _blocks(text: str) -> dict[str, str]:
    """The page cut at its section headings: section name -> its text."""
    parts = re.split(r"^``\[(\w+)\]``\n-+\n", text, flags=re.M)
    return dict(zip(parts[1::2], parts[2::2]))


def test_every_declared_key_kind_bound_and_rule_is_on_the_page_under_its_section():
    blocks = _blocks(render())
    assert list(blocks) == ["scene", *SECTIONS]
    for k in SCENE_KEYS:
        assert f"* - ``{k.name}``" in blocks["scene"]
    for name, section in SECTIONS.items():
        block = blocks[name]
        rows = dict(re.findall(r"^   \* - ``([\w.]+)``\n((?:     -.*\n)+)", block, flags=re.M))
        expected = [k.name for k in section.declared()]
        expected += [f"{k.name}.{sub.name}" for k in section.declared() for sub in k.keys]
        assert sorted(rows) == sorted(expected), name
        for k in section.declared():
            if k.limit is not None:
                assert k.limit.rule[3:] in rows[k.name], (name, k.name)
            if k.flag is not None:
                assert f"``{k.flag}``" in rows[k.name], (name, k.name)
        for kind in section.kinds():
            assert f"- ``{kind}``: " in block, (name, kind)
        for rule in section.rules():
            assert rule in block, (name, rule)


def test_sections_without_required_keys_parse_to_their_declared_defaults():
    # No literal default in the parser: an empty section is the declaration's defaults.
    for section in (MotorsSpec, SensorsSpec, ReportSpec, EstimationSpec):
        spec = section.parse({})
        for k in section.declared():
            assert getattr(spec, k.name) == k.default, (section.SECTION, k.name)
    spec = ControlSpec.parse({"controller": "speed_hold", "reference": 0.1, "slope": 20.0})
    assert spec.params == {"reference": 0.1, "slope": 20.0}
    assert (spec.param("kp"), spec.param("ki")) == (ControlSpec.key("kp").default, ControlSpec.key("ki").default)
    assert TargetSpec.key("margin").default == 0


@pytest.mark.parametrize(("text", "message"), [
    # a key of another kind is named as such, for every section with kinds
    (MINIMAL + '[target]\nkind = "viscosity"\nslope = 1.0\ncenter = 0.0\nband = 0.1\nfraction = 0.5\n',
     "The [target] key 'fraction' belongs to kind = 'friction_fraction'; kind = 'viscosity' does not take it."),
    (MINIMAL + '[estimation]\nscenario = "simulation"\ncruise = 0.1\n',
     "The [estimation] key 'cruise' belongs to scenario = 'brake'; scenario = 'simulation' does not take it."),
    (MINIMAL + '[control]\ncontroller = "viscosity"\nslope = 1.0\nkp = 0.5\n',
     "The [control] key 'kp' belongs to controller = 'speed_hold'; controller = 'viscosity' does not take it."),
    ("[planar]\nbody = 'legs'\nmass = 1.0\nradius = 0.1\n",
     "The [planar] key 'radius' belongs to body = 'disc'; body = 'legs' does not take it."),
    # the rules between keys, with the declared units
    ("[contacts]\nrandom = { n = 3, low = 0.0, high = 1.0 }\nspeeds = [0.1]\n",
     "In [contacts] give only one of 'speeds', 'random'; got ['speeds', 'random']."),
    ("[contacts]\nforces = 1.0\n", "The [contacts] section needs one of 'speeds' (m/s), 'random'."),
    (MINIMAL + "[body]\ninertia = 1.0\n", "In [body] 'inertia' needs 'contact_radius' (m)."),
    (MINIMAL + "[sensors]\nwheel_radius = 0.05\n",
     "In [sensors] 'wheel_radius' and 'wheel_counts_per_rev' go together."),
    (MINIMAL + "[report]\ncurve_points = 1.5\n", "The 'report.curve_points' value in the scene must be an integer. "
     "Got 1.5 instead."),
    (MINIMAL + "[report]\ncurve_pionts = 5\n", "Unknown key 'curve_pionts' in [report]. Did you mean 'curve_points'?"),
])
def test_messages_follow_the_declaration(text, message):
    with pytest.raises(SceneError) as info:
        loads_scene(text)
    assert str(info.value) == message


def _copy_with(tmp_path: Path, old: str, new: str) -> Path:
    """A copy of the package whose scene declaration has ``old`` replaced by ``new`` (once)."""
    root = tmp_path / "src"
    shutil.copytree(ROOT / "toolkit", root / "toolkit", ignore=shutil.ignore_patterns("__pycache__", "*.nb?"))
    spec = root / "toolkit" / "scenes" / "spec.py"
    text = spec.read_text(encoding="utf-8")
    assert text.count(old) == 1, old
    spec.write_text(text.replace(old, new), encoding="utf-8")
    return root


_PROBE = """
from toolkit.scenes.reference import render
from toolkit.scenes.spec import loads_scene
from toolkit.cli import parser
row = render().split("* - ``curve_points``", 1)[1].split("* - ", 1)[0]
print(row.split("\\n")[2].strip())
print(loads_scene("[contacts]\\nspeeds = [0.1]\\n[report]\\n").report.curve_points)
print(parser().parse_args(["curve", "x.toml"]).points)
"""


@pytest.mark.parametrize("default", [801, 1601])
def test_a_default_changed_in_its_declaration_changes_the_page_the_parser_and_the_cli(tmp_path, default):
    # The one declaration of report.curve_points, edited in a copy of the package: the page's
    # row, the parsed default and the default of 'curve --points' all follow (801: the copy
    # itself, unedited, as the control).
    declaration = "curve_points: int = key(801,"
    root = _copy_with(tmp_path, declaration, declaration.replace("801", str(default)))
    done = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, check=True,
                          cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(root)})
    assert done.stdout.split() == ["-", f"``{default}``", str(default), str(default)]


def test_the_sphinx_extension_writes_the_page_and_sphinx_reads_it(tmp_path):
    pytest.importorskip("sphinx")
    source = tmp_path / "docs"
    source.mkdir()
    (source / "conf.py").write_text(f"import sys\nsys.path.insert(0, {str(ROOT / 'docs' / '_ext')!r})\n"
                                    "extensions = ['scene_reference']\nproject = 'probe'\n")
    (source / "index.rst").write_text("Probe\n=====\n\n.. toctree::\n\n   reference/scenes\n")
    done = subprocess.run([sys.executable, "-m", "sphinx", "-W", "-q", "-b", "dummy", str(source),
                           str(tmp_path / "out")], capture_output=True, text=True, cwd=ROOT,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr
    assert (source / "reference" / "scenes.rst").read_text(encoding="utf-8") == render()
