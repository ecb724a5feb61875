"""Encoder records as CSV (toolkit.model.record_io): the exact round trip, a logger's file
without metadata, and malformed files refused with the line number."""

from __future__ import annotations

import dataclasses
import re

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
    with pytest.raises(ParameterError, match=r"'sensors' parameter of read_record_csv\(log.csv\) on line 2, column 1 "
                       r"must be given \(the scene's \[sensors\]\) when no '# central_resolution = ...' line"):
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
    (lambda L: L.__setitem__(0, "# some other format"),
     "'first line' parameter of read_record_csv\\(run.csv\\) on line 1, column 1"),
    (lambda L: L.__setitem__(5, L[5].replace("time_s", "t")), "'header' parameter of .* on line 6, column 1"),
    (lambda L: L.__setitem__(9, L[9].replace(",", ";", 1)), "'row' parameter of .* on line 10, column \\d+ must have"),
    (lambda L: L.__setitem__(9, "0.0," + L[9].split(",", 1)[1]),
     "'time_s' parameter of .* on line 10, column 1 must increase"),
    (lambda L: L.__setitem__(12, L[12].split(",")[0] + ",12.5," + L[12].split(",", 2)[2]),
     "'central_count' parameter of .* on line 13, column 2 must be an integer count. Got '12.5'"),
    (lambda L: L.__setitem__(20, ",".join(L[20].split(",")[:13] + ["nan"] + L[20].split(",")[14:])),
     "'command_2_m_s' parameter of .* on line 21, column 14 must be finite"),
    (lambda L: L.__setitem__(2, "# wheel_resolution = abc"), "'wheel_resolution' parameter of .* on line 3, column 1"),
    (lambda L: L.__setitem__(3, "# colour = blue"), "'comment' parameter of .* on line 4, column 1"),
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


def test_a_byte_order_mark_is_accepted(scenario, tmp_path):
    # A spreadsheet's "CSV UTF-8" starts with U+FEFF: the same record, bit for bit.
    path, lines = _lines(scenario, tmp_path)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    _same(scenario.record, read_record_csv(path))


def test_counts_are_checked_against_int64_with_line_and_column(scenario, tmp_path):
    path, lines = _lines(scenario, tmp_path)
    top = 2**63 - 1                          # int64's largest: read exactly
    fields = lines[8].split(",")
    fields[3] = str(top)
    lines[8] = ",".join(fields)
    path.write_text("\n".join(lines) + "\n")
    assert read_record_csv(path).wheel_counts[2, 1] == top
    for text in (str(top + 1), str(-top - 2), "9" * 400):     # one past each end, and 400 digits
        fields[3] = text
        lines[8] = ",".join(fields)
        path.write_text("\n".join(lines) + "\n")
        with pytest.raises(ParameterError, match=r"'wheel_count_2' parameter of read_record_csv\(run.csv\) on "
                           r"line 9, column 4 must be an integer count within int64"):
            read_record_csv(path)


def test_commands_are_checked_against_the_motors_limits(scenario, tmp_path):
    from toolkit.model.motors import Motors

    path, lines = _lines(scenario, tmp_path)
    motors = Motors(lag=0.0075, speed_limits=(-0.35, 0.35))
    _same(scenario.record, read_record_csv(path, motors=motors))     # the simulated commands are within
    n = scenario.record.n_wheels
    for value in ("1e308", "0.35000000000000003", "-0.5"):        # 0.35's next double is beyond
        edited = list(lines)
        fields = edited[30].split(",")
        fields[2 + n + 4] = value                                   # command_5, column 2 + n + 5
        edited[30] = ",".join(fields)
        path.write_text("\n".join(edited) + "\n")
        with pytest.raises(ParameterError, match=rf"'command_5_m_s' parameter of .* on line 31, column {n + 7} "
                           r"must lie within the motors' speed limits \[-0.35, 0.35\] m/s"):
            read_record_csv(path, motors=motors)
        assert read_record_csv(path).commands[24, 4] == float(value)     # no motors: finite is enough
    edited = list(lines)
    edited[4] = "# initial_commands = " + " ".join(["0.1"] * (n - 1) + ["2.0"])
    path.write_text("\n".join(edited) + "\n")
    with pytest.raises(ParameterError, match=rf"'initial_commands' parameter of .* on line 5, column {n} must lie"):
        read_record_csv(path, motors=motors)


def test_rows_read_in_blocks_give_the_same_record_and_the_right_line(scenario, tmp_path, monkeypatch):
    # Blocks of 7 rows (the file's 101 rows: 15 blocks, the last short) and blank lines
    # between rows: the record of one block, bit for bit; an error in a late block names its line.
    import toolkit.model.record_io as record_io

    monkeypatch.setattr(record_io, "_BLOCK_ROWS", 7)
    path, lines = _lines(scenario, tmp_path)
    spaced = lines[:6] + [row for line in lines[6:] for row in (line, "")]
    path.write_text("\n".join(spaced) + "\n")
    _same(scenario.record, read_record_csv(path))
    assert scenario.record.n_samples == 101
    spaced[6 + 2 * 80] = spaced[6 + 2 * 80].replace(",", ",x", 1)           # data row 81: line 167
    path.write_text("\n".join(spaced) + "\n")
    with pytest.raises(ParameterError, match=r"'central_count' parameter of .* on line 167, column 2 must be an "
                       r"integer count. Got 'x"):
        read_record_csv(path)


def test_size_line_length_and_encoding_are_capped_with_the_rule(scenario, tmp_path, monkeypatch):
    import toolkit.model.record_io as record_io

    path, lines = _lines(scenario, tmp_path)
    size = path.stat().st_size
    assert record_io.MAX_RECORD_BYTES == 256 * 2**20 and size < record_io.MAX_RECORD_BYTES
    monkeypatch.setattr(record_io, "MAX_RECORD_BYTES", size - 1)
    with pytest.raises(ParameterError, match=rf"The record file '.*run.csv' is {size} bytes; record files are "
                       rf"limited to {size - 1} bytes \("):
        read_record_csv(path)
    monkeypatch.undo()
    monkeypatch.setattr(record_io, "MAX_LINE_BYTES", 100)
    with pytest.raises(ParameterError, match=r"'line' parameter of .* on line 5, column 101 must be at most 100 bytes"):
        read_record_csv(path)           # line 5, initial_commands, is the first over 100 bytes
    monkeypatch.undo()
    path.write_bytes(path.read_bytes().replace(b"time_s", b"time_\xe9", 1))
    with pytest.raises(ParameterError, match=r"'line' parameter of .* on line 6, column 6 must be UTF-8 text "
                       r"\(columns counted in bytes here\). Got 'byte 0xe9'"):
        read_record_csv(path)


def test_a_channel_count_other_than_the_scenes_names_the_header(scenario, tmp_path):
    # The file has 10 wheel channels; encoders of 4 wheels: the header is what is refused.
    path, _ = _lines(scenario, tmp_path)
    four = dataclasses.replace(scenario.sensors, n_wheels=4)
    with pytest.raises(ParameterError, match=r"'header' parameter of read_record_csv\(run.csv\) on line 6, column 3 "
                       r"must name one wheel_count column per wheel encoder of the scene's \[sensors\] \(4\). "
                       r"Got '10 wheel_count columns' instead"):
        read_record_csv(path, four)


def test_a_progress_bar_only_when_allowed_and_the_file_is_large(scenario, tmp_path, monkeypatch, capsys):
    import toolkit.model.record_io as record_io

    path, _ = _lines(scenario, tmp_path)
    read_record_csv(path, progress=True)              # small: no bar
    read_record_csv(path)
    assert capsys.readouterr().err == ""
    monkeypatch.setattr(record_io, "_PROGRESS_BYTES", 0)
    read_record_csv(path)                             # not allowed: no bar
    assert capsys.readouterr().err == ""
    read_record_csv(path, progress=True)
    assert "run.csv" in capsys.readouterr().err       # tqdm's bar, named by the file, on stderr


def test_times_follow_the_encoders_period_when_the_scene_gives_it(scenario, tmp_path):
    # At 50 Hz a row must follow the previous by 0.02 s within 0.01 s: 0.029 s passes, 0.031 s
    # and a gap of 1e9 s do not (refused on the row that breaks the rule); without the scene's
    # encoders only the order is checked.
    path, lines = _lines(scenario, tmp_path)
    assert scenario.sensors.period == 0.02
    row = 6 + 40                                   # data row 40 (line 47): t = 0.8 s, previous 0.78
    for value, refused in (("0.809", False), ("0.811", True), ("1e9", True)):
        edited = list(lines)
        edited[row] = value + "," + edited[row].split(",", 1)[1]
        if value == "1e9":                         # keep the order: every later row moved too
            edited[row + 1:] = [repr(1e9 + 0.02 * k) + "," + line.split(",", 1)[1]
                                for k, line in enumerate(edited[row + 1:], start=1)]
        path.write_text("\n".join(edited) + "\n")
        if refused:
            with pytest.raises(ParameterError, match=r"'time_s' parameter of .* on line 47, column 1 must follow the "
                               r"previous row \(0.78 s\) by one period of the scene's encoders \(0.02 s\) within half"):
                read_record_csv(path, scenario.sensors)
        else:
            assert read_record_csv(path, scenario.sensors).times[40] == 0.809
        assert read_record_csv(path).times[40] == float(value)


@pytest.mark.parametrize("row", [0, 1, 2])
def test_the_first_rows_are_checked_and_named_like_any_other(scenario, tmp_path, row):
    """The first, second and third data rows (lines 7, 8, 9) are held to the same rules and
    refused with their own line: a time that does not increase (the second and third rows: a
    copy of the previous time), a time off the encoders' period (the scene's sensors), a
    count that is not an integer. Mutant killed: the block reader's order check from the
    third row on (``steps[2:] > 0``), which lets the second row through."""
    path, lines = _lines(scenario, tmp_path)
    line = 7 + row
    fields = lines[6 + row].split(",")
    edited = list(lines)
    if row:
        previous = lines[5 + row].split(",")[0]
        edited[6 + row] = ",".join([previous] + fields[1:])
        path.write_text("\n".join(edited) + "\n")
        with pytest.raises(ParameterError, match=rf"^The 'time_s' parameter of read_record_csv\(run.csv\) on line "
                           rf"{line}, column 1 must increase strictly \(previous row {re.escape(previous)}\)"):
            read_record_csv(path)
        edited[6 + row] = ",".join([repr(float(previous) + 0.031)] + fields[1:])
        path.write_text("\n".join(edited) + "\n")
        with pytest.raises(ParameterError, match=rf"^The 'time_s' parameter of read_record_csv\(run.csv\) on line "
                           rf"{line}, column 1 must follow the previous row"):
            read_record_csv(path, scenario.sensors)
    edited = list(lines)
    edited[6 + row] = ",".join(fields[:2] + ["1.5"] + fields[3:])
    path.write_text("\n".join(edited) + "\n")
    with pytest.raises(ParameterError, match=rf"^The 'wheel_count_1' parameter of read_record_csv\(run.csv\) on line "
                       rf"{line}, column 3 must be an integer count. Got '1.5' instead.$"):
        read_record_csv(path)


def test_a_valid_file_is_read_by_blocks_without_the_row_by_row_reader(scenario, tmp_path, monkeypatch):
    """The block reader (NumPy's) takes every valid block whole; the row-by-row reader only
    runs to name a bad value's line. A valid file read with the row-by-row reader disabled
    gives the same record (mutants: any change that makes the block reader give up on valid
    rows, e.g. its column ranges, its ``ndmin`` or its field count, which the row-by-row reader
    would otherwise hide behind the same numbers)."""
    import toolkit.model.record_io as record_io

    path = write_record_csv(scenario.record, tmp_path / "run.csv")
    expected = read_record_csv(path, scenario.sensors)

    def refuse(*args, **kwargs):
        raise AssertionError("a valid block went to the row-by-row reader")

    monkeypatch.setattr(record_io, "_slow_block", refuse)
    _same(read_record_csv(path, scenario.sensors), expected)
