"""A first run on an empty kernel cache says that it compiles (stderr only), and what it cost;
a run that loads the kernels from the cache says nothing; ``warm`` compiles them ahead."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import toolkit

ROOT = Path(toolkit.__file__).resolve().parents[1]
JIT = os.environ.get("NUMBA_DISABLE_JIT", "0") in ("", "0")

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not JIT, reason="nothing is compiled")]


def _run(cache: Path | None, *args: str) -> subprocess.CompletedProcess[str]:
    """The command line in a fresh process, on the kernel cache ``cache`` (None: the default)."""
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_DISABLE_JIT", "NUMBA_CACHE_DIR")}
    env.update(PYTHONPATH=str(ROOT), ACTIVE_CONTACTS_COMPILE="eager")
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = str(cache)
    return subprocess.run([sys.executable, "-m", "toolkit.cli", *args], capture_output=True, text=True,
                          cwd=ROOT, env=env)


def test_a_cold_run_announces_its_compile_on_stderr_only(tmp_path):
    cache = tmp_path / "cache"
    first = _run(cache, "curve", "designs/equal.toml", "--json")
    assert first.returncode == 0, first.stderr
    lines = first.stderr.splitlines()
    assert lines[0].startswith("active-contacts: compiling kernels (first run only"), lines
    assert lines[-1].startswith("active-contacts: compiled ") and "kernels in" in lines[-1], lines
    assert "compil" not in first.stdout
    json.loads(first.stdout)                               # stdout stays machine-readable
    again = _run(cache, "curve", "designs/equal.toml", "--json")
    assert again.returncode == 0 and again.stderr == "", again.stderr     # loaded: silent
    assert json.loads(again.stdout) == json.loads(first.stdout)


def test_warm_compiles_what_every_design_runs(tmp_path):
    # After `warm` (on the suite's own cache: whatever it lacks, warm compiles), the first run
    # of a shipped design compiles nothing (no notice at all).
    warm = _run(None, "warm", "--json")
    assert warm.returncode == 0, warm.stderr
    data = json.loads(warm.stdout)
    assert data["compile_time"] >= 0 and "carousel" in data["designs"]
    # One notice, whatever it compiles and in how many processes (none from the workers).
    assert warm.stderr.startswith("active-contacts: warm: compiling the kernels of every shipped design in ")
    assert warm.stderr.count("\n") == 1, warm.stderr
    for design in ("carousel", "closed_loop", "estimate"):
        run = _run(None, "run", f"designs/{design}.toml", "--out", str(tmp_path / design), "--json")
        assert run.returncode in (0, 3), run.stderr
        assert "compiling kernels" not in run.stderr, (design, run.stderr)
