"""The timing policy of toolkit._compiled: no reported time includes compilation.

Checked without a clock: a fresh process with an empty numba cache (every kernel compiles)
makes each timed report, and every kernel compile in it is recorded with whether it happened
inside :func:`toolkit._compiled.warm` (the untimed warm-up each report runs before its clock
starts). A compile outside every warm-up would be inside a reported time. How fast the
compiled code is belongs to ``python -m toolkit.bench``, not to these tests.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import toolkit
from toolkit import load_scene
from toolkit.scenes.study import run_study

ROOT = Path(toolkit.__file__).resolve().parents[1]
JIT = os.environ.get("NUMBA_DISABLE_JIT", "0") in ("", "0")

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not JIT, reason="nothing is compiled")]

#: Each timed report in turn, in one process: kernels compiled by an earlier report are
#: machine code for the later ones, which then compile only what is new to them.
_REPORTS = """
import json, sys
from toolkit import _compiled
record, depth = [], [0]
original = _compiled.warm
def warm(*args):
    depth[0] += 1
    try:
        return original(*args)
    finally:
        depth[0] -= 1
_compiled.warm = warm                       # (before any module binds the name)
report = [None]
_compiled.on_compile(lambda event, name, s: event == "end" and record.append([report[0], name, depth[0] > 0]))
from toolkit import load_scene
from toolkit.analysis.precision import MethodSetting, precision_report
from toolkit.experiments import MedianLaw
from toolkit.model.carousel import carousel_startup_plant
from toolkit.predictions import prediction_checks
from toolkit.scenes.study import control_scene, estimate_scene
from toolkit.sweeps import sweep
costs = {}
report[0] = "precision"
costs[report[0]] = precision_report(carousel_startup_plant(0), 5.0, settings=[MethodSetting("exact")],
                                    repeats=2).compile_time
report[0] = "estimate"
costs[report[0]] = estimate_scene(load_scene("designs/estimate.toml")).compile_time
report[0] = "closed loop"
costs[report[0]] = control_scene(load_scene("designs/closed_loop.toml")).compile_time
report[0] = "sweep"
costs[report[0]] = sweep(MedianLaw(), 2000, seed=3).compile_time
report[0] = "predict"
costs[report[0]] = prediction_checks(runs=40).compile_time
print(json.dumps({"compiles": record, "costs": costs}))
"""


def test_no_reported_time_includes_a_compile(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("ACTIVE_CONTACTS_COMPILE", "NUMBA_DISABLE_JIT")}
    env.update(PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(tmp_path / "cache"))    # an empty cache
    done = subprocess.run([sys.executable, "-c", _REPORTS], env=env, cwd=ROOT, check=True,
                          capture_output=True, text=True)
    data = json.loads(done.stdout.strip().splitlines()[-1])
    compiles = data["compiles"]
    assert compiles, "nothing compiled: the cache was not empty"
    outside = [(report, name) for report, name, inside in compiles if not inside]
    assert not outside, f"compiled inside a timed region: {outside}"
    # the one-time cost is reported apart (every report here ran a warm-up that compiled)
    assert all(cost > 0 for cost in data["costs"].values()), data["costs"]


def test_study_reports_the_one_time_cost_apart():
    # result.json's compile_time: what the warm-ups of the timed stages cost (> 0 when a
    # stage is timed), beside the stages' own wall times.
    from toolkit.scenes.report import study_to_dict

    data = study_to_dict(run_study(load_scene(ROOT / "designs" / "closed_loop.toml")))
    assert data["compile_time"] > 0 and data["control"]["compile_time"] > 0
    assert data["compile_time"] >= data["control"]["compile_time"]
