"""Encoder records as CSV (toolkit.model.record_io): the exact round trip, a logger's file
without metadata, and malformed files refused with the line number."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from toolkit import ParameterError, SceneFileNotFoundError
from toolkit.analysis.scenarios import carousel_brake_scenario
from toolkit.model.record_io import RECORD_MAGIC, read_record_csv, write_record_csv
from toolkit.model.sensors import EncoderRecord
from toolkit.model.truth import WorldTruth


@pytest.fixture(scope="module")
def scenario():
    return carousel_brake_scenario(seed=3, t_end=2.0, brake_time=1.0,
                                   truth=WorldTruth(jitter=5e-4, read_noise=0.5))


def _same(a: EncoderRecord, b: EncoderRecord) -> None:
    for field in dataclasses.fields(EncoderRecord):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if x is None or y is None:
            assert x is None and y is None, field.name
        else:
            np.testing.assert_array_equal(x, y, err_msg=field.name)     # bit for bit


def test_round_trip_is_exact(scenario, tmp_path):
    record = dataclasses.replace(scenario.record, force=np.linspace(-0.3, 0.7, scenario.record.n_samples))
    path = write_record_csv(record, tmp_path / "run.csv")
    back = read_record_csv(path)
    _same(record, back)
    assert back.times.dtype == np.float64 and back.central_counts.dtype == np.int64
    # Read with the scene's encoders: the same record (their resolutions agree).
    _same(record, read_record_csv(path, scenario.sensors))


def test_a_logger_file_without_metadata_takes_the_scene_encoders(scenario, tmp_path):
    rec = scenario.record
    bare = dataclasses.replace(rec, truth_speed=None, truth_position=None, truth_contact_speeds=None,
                               force=None, initial_commands=None)
    path = write_record_csv(bare, tmp_path / "log.csv")
    text = path.read_text().splitlines()
    log = [text[0]] + [line for line in text[1:] if not line.startswith("#")]
    path.write_text("\n".join(log) + "\n")
    with pytest.raises(ParameterError, match="'sensors' parameter of read_record_csv must be given"):
        read_record_csv(path)
    back = read_record_csv(path, scenario.sensors)
    assert back.central_resolution == scenario.sensors.central.distance_per_count
    assert back.wheel_backlash == scenario.sensors.backlash
    np.testing.assert_array_equal(back.wheel_counts, rec.wheel_counts)
    assert back.truth_speed is None and back.force is None and back.initial_commands is None


def _lines(scenario, tmp_path):
    path = write_record_csv(scenario.record, tmp_path / "run.csv")
    return path, path.read_text().splitlines()


@pytest.mark.parametrize("edit, match", [
    (lambda L: L.__setitem__(0, "# some other format"), "'first line' parameter of read_record_csv\\(run.csv\\) on line 1"),
    (lambda L: L.__setitem__(5, L[5].replace("time_s", "t")), "'header' parameter of .* on line 6"),
    (lambda L: L.__setitem__(9, L[9].replace(",", ";", 1)), "'row' parameter of .* on line 10 must have"),
    (lambda L: L.__setitem__(9, "0.0," + L[9].split(",", 1)[1]), "'time_s' parameter of .* on line 10 must increase"),
    (lambda L: L.__setitem__(12, L[12].split(",")[0] + ",12.5," + L[12].split(",", 2)[2]),
     "'central_count' parameter of .* on line 13 must be an integer count. Got '12.5'"),
    (lambda L: L.__setitem__(20, ",".join(L[20].split(",")[:13] + ["nan"] + L[20].split(",")[14:])),
     "'command_2_m_s' parameter of .* on line 21 must be finite"),
    (lambda L: L.__setitem__(2, "# wheel_resolution = abc"), "'wheel_resolution' parameter of .* on line 3"),
    (lambda L: L.__setitem__(3, "# colour = blue"), "'comment' parameter of .* on line 4"),
])
def test_bad_files_are_refused_with_the_line(scenario, tmp_path, edit, match):
    path, lines = _lines(scenario, tmp_path)
    edit(lines)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ParameterError, match=match):
        read_record_csv(path)


def test_encoders_that_disagree_with_the_file_are_refused(scenario, tmp_path):
    path, _ = _lines(scenario, tmp_path)
    other = dataclasses.replace(scenario.sensors, central=dataclasses.replace(scenario.sensors.central,
                                                                              counts_per_rev=4096))
    with pytest.raises(ParameterError, match="'central_resolution' parameter of read_record_csv"):
        read_record_csv(path, other)
    with pytest.raises(SceneFileNotFoundError):
        read_record_csv(tmp_path / "missing.csv")
    assert RECORD_MAGIC.startswith("#")


def test_a_folder_or_a_missing_file_is_named_for_what_it_is(tmp_path):
    from toolkit.errors import SceneFileNotFoundError
    from toolkit.model.record_io import read_record_csv

    with pytest.raises(SceneFileNotFoundError, match="is a folder, not a CSV file"):
        read_record_csv(tmp_path)
    with pytest.raises(SceneFileNotFoundError, match="does not exist"):
        read_record_csv(tmp_path / "none.csv")
