"""The package as a user installs it: a wheel in a fresh virtual environment, used from a
folder outside the repository (the designs ship inside it; nothing reads the source tree)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(args: list[str], cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    return subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)


@pytest.mark.slow
def test_wheel_installed_in_a_fresh_environment_works_outside_the_repository(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    dist = tmp_path / "dist"
    built = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(dist), str(ROOT)],
                 tmp_path, env)
    assert built.returncode == 0, built.stderr
    wheels = list(dist.glob("active_contacts-*.whl"))
    assert len(wheels) == 1

    venv = tmp_path / "venv"
    assert _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], tmp_path, env).returncode == 0
    python = venv / "bin" / "python"
    installed = _run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--quiet",
                      str(wheels[0])], tmp_path, env)
    assert installed.returncode == 0, installed.stderr
    # The dependencies (numpy, scipy, ...) come from the test environment's site-packages, added
    # as a plain path: its editable install of the toolkit (a finder run by a .pth file there)
    # is not activated, so `toolkit` can only come from the wheel.
    purelib = _run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                   tmp_path, env).stdout.strip()
    (Path(purelib) / "test-dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    where = _run([str(python), "-c", "import toolkit; print(toolkit.__file__)"], elsewhere, env)
    assert where.returncode == 0, where.stderr
    assert Path(where.stdout.strip()).is_relative_to(venv) and not Path(where.stdout.strip()).is_relative_to(ROOT)

    cli = str(venv / "bin" / "active-contacts")
    listed = _run([cli, "designs", "--json"], elsewhere, env)
    assert listed.returncode == 0, listed.stderr
    names = json.loads(listed.stdout)["designs"]
    assert "carousel" in names and "estimate" in names
    copied = _run([cli, "designs", "--copy", "mydesigns"], elsewhere, env)
    assert copied.returncode == 0, copied.stderr
    assert sorted(p.stem for p in (elsewhere / "mydesigns").glob("*.toml")) == sorted(names)

    run = _run([cli, "run", "mydesigns/carousel.toml", "--out", "out", "--json"], elsewhere, env)
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["met"] is True and (elsewhere / "out" / "result.json").exists()

    scenario = _run([str(python), "-c", "import toolkit as tk\n"
                     "s = tk.carousel_brake_scenario(t_end=1.0, brake_time=0.5)\n"
                     "print(s.record.n_samples)"], elsewhere, env)
    assert scenario.returncode == 0, scenario.stderr
    assert scenario.stdout.strip() == "51"                 # 1 s at 50 Hz, both ends included
