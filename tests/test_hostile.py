"""Hostile inputs a newcomer tried: each is refused with exit 2 and one line, no
traceback, nothing written; none is silently clipped or replaced."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from toolkit.scenes._io import claim_output_dir
from toolkit.errors import ParameterError, SceneError
from toolkit.scenes.build import build_scene
from toolkit.scenes.spec import load_scene, loads_scene

ROOT = Path(__file__).resolve().parents[1]
CAROUSEL = str(ROOT / "designs" / "carousel.toml")
SWEEP_MESSAGE = "is a sweep scene: its runs draw their own contacts"


def _cli(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "toolkit.cli", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=300)


def _refused(done: subprocess.CompletedProcess, *fragments: str) -> None:
    assert done.returncode == 2, (done.returncode, done.stderr)
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr
    for fragment in fragments:
        assert fragment in done.stderr, done.stderr


def _scene(tmp_path: Path, text: str) -> str:
    path = tmp_path / "hostile.toml"
    path.write_text(text)
    return str(path)


BASE = ('[contacts]\nspeeds = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\nforces = 1.0\n'
        '[body]\nmass = 5.0\n[motors]\nspeed_limit = 0.35\nlag = 0.0075\n'
        '[sensors]\nrate = 50.0\nwheel_counts_per_rev = 3591.84\nwheel_radius = 0.045\n'
        'central_counts_per_rev = 8192\ncontact_radius = 0.266\n')


def test_curve_points_flag_is_bounded_like_its_scene_key():
    # report.curve_points <= MAX_CURVE_POINTS (its two series within the 64 MiB output limit,
    # 1118481) in a scene; the flag has the same bound (toolkit.scenes.limits), both refused
    # before any work: the 1e8 and the former cap 1e7 (481 MB printed).
    for points in ("100000000", "10000000", "1118482"):
        _refused(_cli("curve", CAROUSEL, "--points", points, "--json"), "--points", "<= 1118481")
    with pytest.raises(SceneError, match="curve_points"):
        build_scene(loads_scene("[contacts]\nspeeds = [0.1, 0.2]\n[report]\ncurve_points = 1118482\n"))


@pytest.mark.parametrize("flag", [["sweep", str(ROOT / "designs" / "median_law.toml"), "--runs", "100000001"],
                                  ["precision", str(ROOT / "designs" / "startup11.toml"), "--repeats", "0"],
                                  ["predict", "--runs", "1"]])
def test_every_integer_flag_is_bounded(flag):
    _refused(_cli(*flag), "must be an integer")


def test_jitter_beyond_what_the_sensor_law_models_is_refused_not_clipped(tmp_path):
    # 1 s of jitter at 50 Hz used to be clipped to a quarter period without a word.
    text = BASE + "[estimation]\njitter = 1.0\nduration = 1.0\nbrake_time = 0.5\n"
    _refused(_cli("estimate", _scene(tmp_path, text), "--out", str(tmp_path / "o")),
             "'jitter' parameter of Sensors", "estimation.jitter")
    assert not (tmp_path / "o").exists()


def test_an_empty_out_is_refused_not_replaced_by_the_default(tmp_path):
    _refused(_cli("run", CAROUSEL, "--out", "", cwd=tmp_path), "--out", "must name a folder")
    assert not (tmp_path / "out").exists()


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux's /proc")
def test_an_out_on_a_file_system_that_makes_nothing_is_refused_before_work(tmp_path):
    # /proc makes no folder or file even for a superuser (os.access may still say writable):
    # refused in one line naming the folder, and no temporary name leaks into the message.
    for args in (("run", CAROUSEL, "--out", "/proc/ac-out"),
                 ("estimate", str(ROOT / "designs" / "estimate.toml"), "--save-record", "/proc/ac.csv")):
        done = _cli(*args, cwd=tmp_path)
        _refused(done, "cannot write the output", "'/proc'")
        assert ".new" not in done.stderr and ".tmp" not in done.stderr


def test_estimate_never_substitutes_another_scenario(tmp_path):
    _refused(_cli("estimate", str(ROOT / "designs" / "closed_loop.toml"), "--out", str(tmp_path / "o")),
             "no [estimation] section and no [simulation] run to record")


def test_outputs_beyond_the_documented_size_are_refused_before_work(tmp_path):
    # 2e5 Hz for 2 s: 400 001 samples of 14 signals, ~160 MiB of result.json (limit 64 MiB).
    text = BASE.replace("[sensors]", "[x]").split("[x]")[0] + (
        '[control]\ncontroller = "viscosity"\nslope = 40.0\nduration = 2.0\nrate = 2e5\n')
    done = _cli("run", _scene(tmp_path, text), "--out", str(tmp_path / "o"))
    _refused(done, "outputs are limited to 64 MiB", "control.duration")
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_a_second_run_into_a_claimed_folder_is_refused_before_work(tmp_path):
    out = tmp_path / "o"
    with claim_output_dir(out):                  # another run holds the folder
        _refused(_cli("run", CAROUSEL, "--out", str(out)), "another run", "is writing into")
        assert not out.exists()
    done = _cli("run", CAROUSEL, "--out", str(out))   # released: the folder is free again
    assert done.returncode == 0 and (out / "result.json").exists(), done.stderr


@pytest.mark.parametrize("command", [["curve"], ["allocate"], ["schedule"], ["precision"], ["estimate"],
                                     ["predict"]])
def test_every_command_refuses_a_sweep_scene_with_one_message(command):
    _refused(_cli(*command, str(ROOT / "designs" / "median_law.toml")), SWEEP_MESSAGE, "'active-contacts sweep'")


def test_sweep_refuses_a_scene_without_a_sweep():
    _refused(_cli("sweep", CAROUSEL), "has no [sweep] section")


def test_sweep_tables_past_their_limit_are_refused_before_any_work(tmp_path, monkeypatch, capsys):
    # The estimate (bytes per run of a 16-run probe) against the table a sweep writes: within
    # 10 % for 3000 runs (the rows' lengths vary with their digits; measured 1e6 runs: 88
    # bytes per run estimated, 81.7 written).
    import toolkit.scenes.limits as limits
    from toolkit.cli import main
    from toolkit.scenes.study import check_sweep_table

    design = ROOT / "designs" / "median_law.toml"
    estimate = check_sweep_table(build_scene(load_scene(design)), runs=3000)
    assert main(["sweep", str(design), "--runs", "3000", "--out", str(tmp_path / "ok")]) == 0
    written = (tmp_path / "ok" / "results.csv").stat().st_size
    assert abs(estimate / written - 1) <= 0.10, (estimate, written)
    # A limit below the table: refused in one line before anything is written (exit 2).
    capsys.readouterr()
    monkeypatch.setattr(limits, "MAX_TABLE_BYTES", written // 2)
    assert main(["sweep", str(design), "--runs", "3000", "--out", str(tmp_path / "no")]) == 2
    err = capsys.readouterr().err.strip()
    assert "results.csv" in err and "at most about" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "no").exists()


def test_an_unknown_simulation_method_is_named_by_its_scene_key():
    text = "[contacts]\nspeeds = [0.1, 0.2]\n[body]\nmass = 1.0\n[simulation]\nt_end = 1.0\nmethod = 'radua'\n"
    with pytest.raises(SceneError, match=r"'simulation.method' value in the scene must be one of .*'radua'.*'radau'"):
        build_scene(loads_scene(text))


def test_json_output_of_a_mixed_integer_allocation_is_json_only(tmp_path):
    # Unequal magnitudes go to the MILP (HiGHS), whose native banner printed on stdout before
    # any option applied and broke '--json'. stdout must parse whole; the speeds realize the
    # target: the weighted median of the allocation is the requested 0.05 m/s (forces 1, 2,
    # 1.5, 0.5 N: the median contact, at rtol 1e-9 of the speed for the solver's tolerance).
    import json

    import numpy as np

    from toolkit import ContactSet

    text = ("[contacts]\nspeeds = [-0.3, -0.1, 0.1, 0.3]\nforces = [1.0, 2.0, 1.5, 0.5]\n[body]\nmass = 1.0\n"
            "[motors]\nspeed_limit = 0.35\n[target]\nkind = 'equilibrium_speed'\nspeed = 0.05\n")
    done = _cli("allocate", _scene(tmp_path, text), "--json")
    assert done.returncode == 0, done.stderr
    data = json.loads(done.stdout)
    lo, hi = ContactSet(np.array(data["speeds"]), [1.0, 2.0, 1.5, 0.5]).equilibrium()
    assert lo <= 0.05 * (1 + 1e-9) and hi >= 0.05 * (1 - 1e-9)


@pytest.mark.parametrize("value, error, match", [
    (np.array([0.1, np.nan]), "ParameterError", "be finite"),
    (np.array([[0.1, 0.2]]), "ParameterError", "be 1-dimensional"),
    (np.empty(0), "ParameterError", "not be empty"),
    ([0.1, math.inf], "ParameterError", "be finite"),
    (np.array([True, False]), "ParameterTypeError", "real numbers"),
    (np.array([1 + 2j]), "ParameterTypeError", "real numbers"),
    ("0.1", "ParameterTypeError", "array of numbers"),
])
def test_float_arrays_and_other_values_are_checked_alike(value, error, match):
    # as_float_array takes a float64 array straight to the shape and finiteness checks (the
    # type checks cannot fail on it): the same refusals as for any other value, and a
    # read-only copy (never the caller's array) when it passes.
    from toolkit import errors

    with pytest.raises(getattr(errors, error), match=match):
        errors.as_float_array(value, "x", "Y")
    given = np.array([0.1, -2.0])
    checked = errors.as_float_array(given, "x", "Y")
    assert checked is not given and not checked.flags.writeable and np.array_equal(checked, given)
    assert errors.as_float(np.float64(0.5), "x", "Y") == 0.5 and errors.as_float(2, "x", "Y") == 2.0
    for bad in (math.nan, math.inf, True, "1"):
        with pytest.raises((errors.ParameterError, errors.ParameterTypeError)):
            errors.as_float(bad, "x", "Y")


# -- inputs a new user tried: each a one-line refusal naming the file, line, column
#    or key (exit 2), or the documented success --------------------------------------------

ESTIMATE = str(ROOT / "designs" / "estimate.toml")


@pytest.fixture(scope="module")
def record_lines(tmp_path_factory):
    """A 2 s startup-then-brake record of the carousel's encoders (the 'estimate' design's)."""
    from toolkit.analysis.scenarios import carousel_brake_scenario
    from toolkit.model.record_io import write_record_csv

    path = tmp_path_factory.mktemp("record") / "run.csv"
    write_record_csv(carousel_brake_scenario(seed=1, t_end=2.0, brake_time=1.0).record, path)
    return path.read_text().splitlines()


def _record(tmp_path: Path, lines: list[str], line: int, column: int, value: str) -> str:
    """The record with the field at (line, column), both counted from 1, replaced by ``value``."""
    edited = list(lines)
    fields = edited[line - 1].split(",")
    fields[column - 1] = value
    edited[line - 1] = ",".join(fields)
    path = tmp_path / "edited.csv"
    path.write_text("\n".join(edited) + "\n")
    return str(path)


def test_a_400_digit_count_is_refused_with_its_line_and_column(tmp_path, record_lines):
    done = _cli("estimate", ESTIMATE, "--record", _record(tmp_path, record_lines, 9, 2, "9" * 400),
                "--out", str(tmp_path / "o"))
    _refused(done, "'central_count' parameter of read_record_csv(edited.csv) on line 9, column 2",
             "within int64")
    assert "OverflowError" not in done.stderr and not (tmp_path / "o").exists()


@pytest.mark.slow
def test_a_command_beyond_the_motor_limits_is_refused_without_warnings(tmp_path, record_lines):
    # command_3 is column 2 + 10 wheels + 3 = 15; the design's motors: +-0.35 m/s.
    done = _cli("estimate", ESTIMATE, "--record", _record(tmp_path, record_lines, 20, 15, "1e308"),
                "--out", str(tmp_path / "o"))
    _refused(done, "'command_3_m_s' parameter of read_record_csv(edited.csv) on line 20, column 15",
             "within the motors' speed limits [-0.35, 0.35] m/s", "'1e308'")
    assert "RuntimeWarning" not in done.stderr


@pytest.mark.slow
def test_a_record_with_a_byte_order_mark_is_read_and_its_first_nis_cell_is_empty(tmp_path, record_lines):
    path = tmp_path / "excel.csv"
    path.write_bytes(b"\xef\xbb\xbf" + ("\n".join(record_lines) + "\n").encode())
    done = _cli("estimate", ESTIMATE, "--record", str(path), "--out", str(tmp_path / "o"))
    assert done.returncode == 0 and done.stderr == "", done.stderr
    rows = [line.split(",") for line in (tmp_path / "o" / "estimate.csv").read_text().splitlines()]
    nis = rows[0].index("kalman_nis")
    assert rows[1][nis] == ""                             # no innovation at the first sample
    assert all(float(row[nis]) >= 0.0 for row in rows[2:])    # a NIS is a squared norm
    assert len(rows) == 1 + 101                           # 2 s at 50 Hz, both ends


def test_a_record_over_the_size_cap_is_refused_naming_the_cap(tmp_path, record_lines, monkeypatch, capsys):
    import toolkit.model.record_io as record_io
    from toolkit.cli import main

    path = tmp_path / "big.csv"
    path.write_text("\n".join(record_lines) + "\n")
    size = path.stat().st_size
    monkeypatch.setattr(record_io, "MAX_RECORD_BYTES", size - 1)
    assert main(["estimate", ESTIMATE, "--record", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"'{path}' is {size} bytes; record files are limited to {size - 1}" in err


@pytest.mark.slow
def test_a_record_with_other_channels_than_the_scene_names_the_header(tmp_path, record_lines):
    # The scene has 4 contacts (4 wheel encoders); the file 10 channels: the file's header is
    # what is refused, with the scene's count as the rule and the file's as the value.
    text = Path(ESTIMATE).read_text().replace(
        "speeds = [0.15, 0.161, 0.172, 0.183, 0.194, 0.206, 0.217, 0.228, 0.239, 0.25]",
        "speeds = [0.15, 0.2, 0.25, 0.3]")
    path = tmp_path / "record.csv"
    path.write_text("\n".join(record_lines) + "\n")
    _refused(_cli("estimate", _scene(tmp_path, text), "--record", str(path), "--out", str(tmp_path / "o")),
             "'header' parameter of read_record_csv(record.csv) on line 6, column 3 must name one wheel_count "
             "column per wheel encoder of the scene's [sensors] (4). Got '10 wheel_count columns' instead.")


@pytest.mark.slow
def test_predict_with_too_few_contacts_names_the_flag_not_a_start(tmp_path):
    done = _cli("predict", "--contacts", "3")
    _refused(done, "--contacts: must be an integer >= 5, got 3")
    assert "start" not in done.stderr
    # A scene of three contacts: the contact count is named, not the start nobody set.
    text = "[contacts]\nspeeds = [0.0, 0.1, 0.2]\nforces = 0.2\n[body]\nmass = 1.0\n[motors]\nspeed_limit = 0.35\n"
    done = _cli("predict", _scene(tmp_path, text), "--runs", "2")
    _refused(done, "'apparatus' parameter of ViscosityProblem must have at least 5 contacts", "Got '3 contacts'")
    assert "'start' parameter" not in done.stderr


def test_the_viscosity_checks_least_contacts_is_the_flags_bound():
    # (n - 1) / 2 - 1 spacings above the lowest contact must exceed the equilibrium set's
    # half-width, 0 (odd n) or 1/2 (even n): n = 5 is the first, 3 and 4 are not.
    from toolkit.predictions import Apparatus
    from toolkit.predictions.viscosity import MIN_CONTACTS, ViscosityProblem
    from toolkit.scenes.limits import FLAGS

    assert MIN_CONTACTS == FLAGS["predict --contacts"].low == 5
    carousel = Apparatus.carousel()
    for n in (5, 6, 7):
        ViscosityProblem(carousel.with_contacts(n), runs=2)
    for n in (1, 2, 3, 4):
        with pytest.raises(ParameterError, match=f"'apparatus' .* Got '{n} contacts'"):
            ViscosityProblem(carousel.with_contacts(n), runs=2)


@pytest.mark.slow
def test_a_closed_pipe_ends_quietly_as_head_expects():
    # The reader goes away before the command writes a line (`designs | head -0`): exit 141
    # (128 + SIGPIPE, what `yes | head` gives), nothing on stderr.
    # argparse's --help drops a failed write itself: 0 there (unbuffered) or 141 (buffered).
    for args, codes in ((["designs"], {141}), (["--help"], {0, 141})):
        process = subprocess.Popen([sys.executable, "-m", "toolkit.cli", *args], stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, cwd=ROOT)
        process.stdout.close()
        err = process.stderr.read()
        assert process.wait(timeout=300) in codes and err == b"", (args, err)
    # And as a shell user types it: the first line, the command ends quietly.
    done = subprocess.run(["sh", "-c", f"'{sys.executable}' -m toolkit.cli designs | head -1"],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert done.returncode == 0 and done.stderr == "" and done.stdout.count("\n") == 1, done


def test_a_closed_stdout_is_a_one_line_error():
    done = subprocess.run(["sh", "-c", f"'{sys.executable}' -m toolkit.cli designs >&-"],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)
    _refused(done, "the standard output is closed")


def test_a_toml_error_names_the_file(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text("[contacts]\nspeeds = [0.1, 0.2\n")
    _refused(_cli("curve", str(path)), f"The scene file '{path}' is not valid TOML")


def test_a_record_too_long_names_the_duration_not_the_rate(tmp_path):
    text = Path(ESTIMATE).read_text().replace("duration = 10.0 ", "duration = 1e12 ")
    done = _cli("estimate", _scene(tmp_path, text), "--out", str(tmp_path / "o"))
    _refused(done, "'estimation.duration' value in the scene must be at most 200000 s at sensors.rate = 50 Hz")
    assert "'sensors.rate' value" not in done.stderr


@pytest.mark.slow
def test_outputs_too_large_for_many_contacts_advise_fewer_contacts(tmp_path):
    # 1e7 contacts: 3e7 numbers of contacts in the outputs, well past 64 MiB; no rate to lower.
    text = "[contacts]\nrandom = {n = 10000000, low = -1.0, high = 1.0}\n"
    done = _cli("curve", _scene(tmp_path, text))
    _refused(done, "outputs are limited to 64 MiB: declare fewer contacts (the scene has 10000000)")
    assert "rate" not in done.stderr


@pytest.mark.slow
def test_every_run_json_has_the_same_top_level_keys(tmp_path, capsys):
    # A plain, a planar and a sweep scene: the run's keys first, the stages' results under
    # their names, then 'written'.
    import json

    from toolkit.cli import main
    from toolkit.scenes.report import RUN_KEYS

    seen = {}
    for design in ("five_five", "sliding_disc", "median_law"):
        assert main(["run", str(ROOT / "designs" / f"{design}.toml"), "--json", "--out", str(tmp_path / design)]) == 0
        data = json.loads(capsys.readouterr().out)
        assert tuple(data)[:len(RUN_KEYS)] == RUN_KEYS and tuple(data)[-1] == "written", (design, list(data))
        assert data["met"] is True and data["shortfalls"] == [] and data["compile_time"] >= 0.0
        seen[design] = data
    assert seen["sliding_disc"]["stages"] == ["planar"] and "planar" in seen["sliding_disc"]
    assert seen["median_law"]["stages"] == ["sweep"] and seen["median_law"]["sweep"]["runs"] > 0
    assert seen["five_five"]["stages"][0] == "curve" and "curve" in seen["five_five"]
    # planar.json carries the same keys as the planar run's stdout (less 'written').
    planar = json.loads((tmp_path / "sliding_disc" / "planar.json").read_text())
    assert tuple(planar) == tuple(seen["sliding_disc"])[:-1]


def test_the_benches_find_their_designs_through_the_package():
    # No bench reads designs/ beside the source tree; the package's path is the installed one.
    import toolkit
    from toolkit.scenes.designs import design_path

    for source in (ROOT / "toolkit" / "bench").glob("*.py"):
        joined = [line.strip() for line in source.read_text().splitlines() if '/ "designs"' in line]
        # (the start-up bench's baseline is a checkout of an older commit: its own designs/)
        assert all(line.startswith('"baseline": (baseline,') for line in joined), (source.name, joined)
    with design_path("median_law") as path:
        assert path.parent == Path(toolkit.__file__).parent / "designs" and path.read_text().startswith("#")
    with pytest.raises(Exception, match="name a shipped design"):
        with design_path("median_lawn"):
            pass


@pytest.mark.slow
def test_a_record_whose_estimates_pass_the_output_limit_is_refused_before_work(tmp_path, record_lines,
                                                                              monkeypatch, capsys):
    # 101 samples x (time, truth, 7 estimators) x 30 bytes = 27270 bytes of series; with a
    # limit of 10000 bytes at most 10000 // (30 * 9) = 37 samples fit. The scene's own
    # series (2 curve points, a 0.1 s record) fit.
    import toolkit.scenes.build as build
    from toolkit.cli import main

    text = (Path(ESTIMATE).read_text().replace("duration = 10.0 ", "duration = 0.1 ")
            .replace("brake_time = 5.0 ", "brake_time = 0.05 ")
            .replace("plots = true", "plots = true\ncurve_points = 2"))
    path = tmp_path / "record.csv"
    path.write_text("\n".join(record_lines) + "\n")
    monkeypatch.setattr(build, "MAX_OUTPUT_BYTES", 10000)
    assert main(["estimate", _scene(tmp_path, text), "--record", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"The record file '{path}' has 101 samples" in err, err
    assert "at most 37 samples with 7 estimators" in err and not (tmp_path / "o").exists()
