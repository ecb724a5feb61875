"""Outputs: all or nothing, the usual modes, shortfalls in result.json."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

import toolkit.scenes._io as io
from toolkit.cli import main
from toolkit.scenes.report import study_to_dict, to_json, write_study
from toolkit.scenes.spec import load_scene, loads_scene
from toolkit.shortfall import Shortfall
from toolkit.scenes.study import run_study

ROOT = Path(__file__).parents[1]
EQUAL = ROOT / "designs" / "equal.toml"          # writes result.json, force_curve.png, simulation.png


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative name -> bytes)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


def fail_on_third_file(monkeypatch):
    real, calls = io._write_file, []

    def write(path, data):
        calls.append(path.name)
        if len(calls) == 3:
            raise OSError(28, "No space left on device")
        real(path, data)

    monkeypatch.setattr(io, "_write_file", write)
    return calls


def test_a_failed_write_leaves_the_previous_outputs_exactly(tmp_path, monkeypatch, capsys):
    out = tmp_path / "out"
    assert main(["run", str(EQUAL), "--out", str(out)]) == 0
    before, around = snapshot(out), sorted(os.listdir(tmp_path))
    assert sorted(before) == ["force_curve.png", "result.json", "simulation.png"]
    calls = fail_on_third_file(monkeypatch)
    capsys.readouterr()
    assert main(["run", str(EQUAL), "--out", str(out)]) == 2
    assert len(calls) == 3
    assert "cannot write the output" in capsys.readouterr().err
    assert snapshot(out) == before                       # same names, same bytes
    assert sorted(os.listdir(tmp_path)) == around        # no temporary folder left beside it


def test_a_failed_write_into_a_new_folder_leaves_nothing(tmp_path, monkeypatch):
    fail_on_third_file(monkeypatch)
    assert main(["run", str(EQUAL), "--out", str(tmp_path / "new")]) == 2
    assert os.listdir(tmp_path) == []


def test_outputs_replace_the_folder_as_a_whole(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "schedule.csv").write_text("stale\n")         # a previous toolkit output, not rewritten
    written = write_study(run_study(load_scene(EQUAL)), out)
    assert sorted(p.name for p in written) == ["force_curve.png", "result.json", "simulation.png"]
    assert sorted(os.listdir(out)) == ["force_curve.png", "result.json", "simulation.png"]


def test_files_and_folder_get_the_usual_modes(tmp_path, umask_022):
    out = tmp_path / "deep" / "out"
    write_study(run_study(load_scene(EQUAL)), out)
    assert oct(out.stat().st_mode & 0o777) == oct(0o755)
    assert {oct(p.stat().st_mode & 0o777) for p in out.iterdir()} == {oct(0o644)}


def test_a_folder_with_foreign_files_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me\n")
    monkeypatch.setattr("toolkit.scenes.study.run_study", lambda *a, **k: pytest.fail("the study ran"))
    assert main(["run", str(EQUAL), "--out", str(out)]) == 2
    assert "holds files the toolkit did not write (notes.txt)" in capsys.readouterr().err
    assert snapshot(out) == {"notes.txt": b"keep me\n"}


def test_an_output_that_is_a_file_is_refused_before_the_study_runs(tmp_path, monkeypatch, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    monkeypatch.setattr("toolkit.scenes.study.run_study", lambda *a, **k: pytest.fail("the study ran"))
    assert main(["run", str(EQUAL), "--out", str(blocker)]) == 2
    err = capsys.readouterr().err
    assert err == f"active-contacts: error: cannot write the output: {str(blocker)!r} exists and is not a folder\n"
    assert blocker.read_text() == "x"


def test_an_unwritable_parent_is_refused_before_the_study_runs(tmp_path, monkeypatch, capsys):
    # os.access is patched: the tests may run as root, who may write anywhere.
    monkeypatch.setattr(io.os, "access", lambda path, mode: Path(path) != tmp_path)
    monkeypatch.setattr("toolkit.scenes.study.run_study", lambda *a, **k: pytest.fail("the study ran"))
    assert main(["run", str(EQUAL), "--out", str(tmp_path / "out")]) == 2
    assert f"the folder {str(tmp_path)!r} is not writable" in capsys.readouterr().err


def test_result_json_lists_the_shortfalls():
    scene = loads_scene('[contacts]\nspeeds = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n'
                        '[motors]\nspeed_limit = 0.35\n'
                        '[target]\nkind = "friction_fraction"\nfraction = 1.7\nband = 0.35\n')
    result = run_study(scene)
    # Requested -1.7 F_tot = -17 N over the band, realizable at most -F_tot = -10 N: 7 N away.
    assert result.shortfalls == (Shortfall(
        "allocation", "friction fraction 1.7 is not realizable: projected to 1 (distance 7 N)", 7.0, "N"),)
    data = json.loads(to_json(study_to_dict(result)))
    assert data["met"] is False
    assert data["shortfalls"] == [{"stage": "allocation", "what": "friction fraction 1.7 is not realizable: "
                                   "projected to 1 (distance 7 N)", "amount": 7.0, "unit": "N"}]
