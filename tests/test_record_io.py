"""Encoder records as CSV (toolkit.model.record_io): the exact round trip, a logger's file
without metadata, and malformed files refused with the line number."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

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


# -- small records written by hand: the format line by line, each refusal in full -------------
from toolkit import ParameterTypeError  # noqa: E402
from toolkit.model.record_io import LiveColumns, read_live_record, record_csv_text  # noqa: E402
from toolkit.model.sensors import Encoder, Sensors  # noqa: E402

_TEXT = """# active-contacts encoder record 1
# central_resolution = 0.0001
# wheel_resolution = 2e-05
# wheel_backlash = 0.001
# initial_commands = 0.05 -0.05
time_s,central_count,wheel_count_1,wheel_count_2,command_1_m_s,command_2_m_s,force_N,truth_speed_m_s,\
truth_position_m,truth_contact_speed_1_m_s,truth_contact_speed_2_m_s,sequence,received_s,answered_s,estimate_m_s,\
estimate_variance_m2_s2
0.0,0,0,0,0.1,-0.1,0.5,0.0,0.0,0.1,-0.1,7,0.0,0.25,0.0,0.0001
0.015625,1,1,-1,0.1,-0.1,-0.25,0.1,0.001,0.1,-0.1,8,0.5,0.75,0.1,0.0002
0.03125,3,2,-3,0.2,-0.2,0.0,0.2,0.002,0.1,-0.1,9,1.0,1.25,0.2,0.0003
"""


def _small():
    record = EncoderRecord([0.0, 0.015625, 0.03125], [0, 1, 3], [[0, 0], [1, -1], [2, -3]],
                           [[0.1, -0.1], [0.1, -0.1], [0.2, -0.2]], 1e-4, 2e-5, wheel_backlash=0.001,
                           initial_commands=[0.05, -0.05], force=[0.5, -0.25, 0.0], truth_speed=[0.0, 0.1, 0.2],
                           truth_position=[0.0, 1e-3, 2e-3], truth_contact_speeds=[[0.1, -0.1]] * 3)
    live = LiveColumns(np.array([7, 8, 9]), np.array([0.0, 0.5, 1.0]), np.array([0.25, 0.75, 1.25]),
                       np.array([0.0, 0.1, 0.2]), np.array([1e-4, 2e-4, 3e-4]))
    return record, live


def _sensors(rate=64.0, n=2):
    # q_c = 2 pi 0.1 / 6283.185307179586 = 1e-4 to 1e-12 (within the reader's rel_tol).
    return Sensors(Encoder(2 * np.pi * 0.1 / 1e-4, 0.1, rate=rate), Encoder(2 * np.pi * 0.1 / 2e-5, 0.1, rate=rate,
                                                                          backlash=0.001), n)


def test_the_format_line_by_line_with_every_column(tmp_path):
    """A record with every optional part (initial commands, force, truth, a live run's
    columns) written as the format says, character for character, and read back bit for bit."""
    record, live = _small()
    assert record_csv_text(record, live=live) == _TEXT
    path = write_record_csv(record, tmp_path / "small.csv", live)
    assert path == tmp_path / "small.csv" and path.read_text() == _TEXT
    back, columns = read_live_record(path)
    _same(record, back)
    for name in ("sequence", "received", "answered", "estimate", "variance"):
        np.testing.assert_array_equal(getattr(columns, name), getattr(live, name), err_msg=name)
    assert columns.sequence.dtype == np.int64
    _same(record, read_record_csv(path))
    assert read_live_record(write_record_csv(record, tmp_path / "plain.csv"))[1] is None
    # Without the truth's third part, no truth is written; without force, no force column.
    partial = dataclasses.replace(record, truth_contact_speeds=None, force=None, initial_commands=None)
    lines = record_csv_text(partial).splitlines()
    assert lines[4] == "time_s,central_count,wheel_count_1,wheel_count_2,command_1_m_s,command_2_m_s"
    assert lines[5] == "0.0,0,0,0,0.1,-0.1" and len(lines) == 8


def test_writing_refuses_what_is_not_a_record_or_its_live_columns():
    record, live = _small()
    with pytest.raises(ParameterTypeError, match="^" + re.escape(
            "The 'record' parameter of write_record_csv must be an EncoderRecord. Got 3 instead.") + "$"):
        write_record_csv(3, "unused.csv")
    with pytest.raises(ParameterTypeError, match="^" + re.escape(
            "The 'record' parameter of record_csv_text must be an EncoderRecord. Got 'r' instead.") + "$"):
        record_csv_text("r")
    short = dataclasses.replace(live, sequence=np.array([7, 8]))
    for bad in (short, "live"):
        with pytest.raises(ParameterError, match="^" + re.escape(
                "The 'live' parameter of record_csv_text must be LiveColumns of 3 samples. Got ") + ".* instead.$"):
            record_csv_text(record, live=bad)


def _refused(tmp_path, text, message, sensors=None, motors=None, name="r.csv"):
    path = tmp_path / name
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    with pytest.raises(ParameterError) as info:
        read_record_csv(path, sensors, motors=motors)
    assert str(info.value) == message
    return info.value


_HEAD = "time_s,central_count,wheel_count_1,command_1_m_s"
_META1 = "# active-contacts encoder record 1\n# central_resolution = 0.5\n# wheel_resolution = 0.25\n"


def _at(parameter, line, column):
    """The start of a refusal of ``r.csv``: the parameter, the line and the column it names."""
    return f"The '{parameter}' parameter of read_record_csv(r.csv) on line {line}, column {column} must "


_KEYS = "['central_resolution', 'wheel_resolution', 'wheel_backlash', 'initial_commands']"
_INT64_RULE = "be an integer count within int64 [-9223372036854775808, 9223372036854775807]"


@pytest.mark.parametrize("text, message", [
    ("# other format\n", _at("first line", 1, 1) + f"be {RECORD_MAGIC!r}. Got '# other format' instead."),
    ("", _at("first line", 1, 1) + f"be {RECORD_MAGIC!r}. Got '' instead."),
    (_META1 + "# colour = blue\n",
     _at("comment", 4, 1) + f"be 'key = value' with a key in {_KEYS}. Got 'colour = blue' instead."),
    (_META1 + "# wheel_backlash 0.1\n",
     _at("comment", 4, 1) + f"be 'key = value' with a key in {_KEYS}. Got 'wheel_backlash 0.1' instead."),
    (_META1 + "# wheel_backlash = -0.25\n", _at("wheel_backlash", 4, 1) + "be >= 0. Got '-0.25' instead."),
    (_META1 + "# central_resolution = 0\n", _at("central_resolution", 4, 1) + "be > 0. Got '0' instead."),
    (_META1 + "# wheel_resolution = inf\n", _at("wheel_resolution", 4, 1) + "be finite. Got 'inf' instead."),
    (_META1 + "# initial_commands = 0.5 x\n", _at("initial_commands", 4, 2) + "be a number. Got 'x' instead."),
    (_META1 + "#\n", _at("header", 5, 1) + "follow the comment lines. Got 'end of file' instead."),
    (_META1 + "time_s,central_count,command_1_m_s\n", _at("header", 4, 3)
     + "name at least one 'wheel_count_1' column. Got 'time_s,central_count,command_1_m_s' instead."),
    (_META1 + "time_s,central_count,wheel_count_1,command_2_m_s\n", _at("header", 4, 4)
     + f"be {_HEAD!r}. Got 'time_s,central_count,wheel_count_1,command_2_m_s' instead."),
    (_META1 + _HEAD + ",force_N,extra\n", _at("header", 4, 6)
     + f"be '{_HEAD},force_N'. Got '{_HEAD},force_N,extra' instead."),
    (_META1 + _HEAD + "\n\n\n", _at("data", 5, 1) + "hold at least one sample row. Got 'end of file' instead."),
    (_META1 + _HEAD + "\n0.0,1,2,0.5,7\n", _at("row", 5, 5) + "have 4 comma-separated fields. Got 5 instead."),
    (_META1 + _HEAD + "\n0.0,1,2\n", _at("row", 5, 4) + "have 4 comma-separated fields. Got 3 instead."),
    (_META1 + _HEAD + "\n0.0,1,2,0.5\n0.5,1,2,nan\n", _at("command_1_m_s", 6, 4) + "be finite. Got 'nan' instead."),
    (_META1 + _HEAD + "\n0.0,1,2,0.5\n-inf,1,2,0.5\n", _at("time_s", 6, 1) + "be finite. Got '-inf' instead."),
    (_META1 + _HEAD + "\n0.5,1,2,0.5\n0.25,1,2,0.5\n",
     _at("time_s", 6, 1) + "increase strictly (previous row 0.5). Got '0.25' instead."),
    (_META1 + _HEAD + "\n0.0,1," + "1" * 41 + ",0.5\n",
     _at("wheel_count_1", 5, 3) + _INT64_RULE + ". Got '" + "1" * 41 + "' instead."),
    (_META1 + "# initial_commands = 0.5 0.25\n" + _HEAD + "\n0.0,1,2,0.5\n",
     _at("initial_commands", 4, 1) + "hold 1 speeds. Got 2 instead."),
])
def test_malformed_small_files_are_refused_in_full(tmp_path, text, message):
    _refused(tmp_path, text, message)


def test_counts_of_forty_digits_are_read_and_refused_by_value(tmp_path):
    """Forty digits is the longest count read (a longer one is refused unread): forty zeros
    and a one is the count 1, and a forty-digit count beyond int64 is refused by its value."""
    path = tmp_path / "r.csv"
    path.write_text(_META1 + _HEAD + "\n0.0,1," + "0" * 39 + "7,0.5\n")
    assert read_record_csv(path).wheel_counts[0, 0] == 7
    _refused(tmp_path, _META1 + _HEAD + "\n0.0,1," + "9" * 40 + ",0.5\n",
             _at("wheel_count_1", 5, 3) + _INT64_RULE + ". Got '" + "9" * 40 + "' instead.")


def test_the_scene_encoders_period_is_bracketed_at_half_a_period(tmp_path):
    """At 64 Hz (period 2^-6 s) a step of 1.5 periods is the edge, taken; the next double above
    it is refused, on the fast block reader and on the row-by-row one alike (a bad count later
    in the same block sends the block to it); below, 0.5 period taken and just below it (the nearest double whose difference to the period is beyond it)."""
    sensors = _sensors(n=1)
    meta = ("# active-contacts encoder record 1\n# central_resolution = 0.0001\n# wheel_resolution = 2e-05\n"
            "# wheel_backlash = 0.001\n" + _HEAD + "\n")
    h = 2.0 ** -6
    for step in (1.5 * h, 0.5 * h):
        path = tmp_path / "ok.csv"
        path.write_text(meta + f"0.0,0,0,0.1\n{step!r},1,1,0.1\n")
        assert read_record_csv(path, sensors).times[1] == step
    # (Below, 0.5 h - 2^-59, two doubles down: one double down rounds back onto the edge in
    # step - h.)
    for step in (float(np.nextafter(1.5 * h, 1.0)), 0.5 * h * (1 - 2.0 ** -52)):
        for tail in ("", f"{step + h!r},1,x,0.1\n"):
            _refused(tmp_path, meta + f"0.0,0,0,0.1\n{step!r},1,1,0.1\n" + tail,
                     f"The 'time_s' parameter of read_record_csv(r.csv) on line 7, column 1 must follow the previous "
                     f"row (0.0 s) by one period of the scene's encoders (0.015625 s) within half a period. "
                     f"Got '{step!r}' instead.", sensors)


def test_the_scene_encoders_are_checked_against_the_file(tmp_path):
    record, _ = _small()
    path = write_record_csv(record, tmp_path / "r.csv")
    _same(record, read_record_csv(path, _sensors()))
    other = dataclasses.replace(_sensors(), wheel=Encoder(2 * np.pi * 0.1 / 2e-5, 0.1, rate=64.0, backlash=0.002))
    _refused(tmp_path, path.read_bytes(), "The 'wheel_backlash' parameter of read_record_csv(r.csv) on line 4, "
             "column 1 must equal the scene's encoders' 0.002. Got 0.001 instead.", other)
    coarse = dataclasses.replace(_sensors(), central=Encoder(2 * np.pi * 0.1 / 1e-4 * (1 + 1e-9), 0.1, rate=64.0))
    error = _refused(tmp_path, path.read_bytes(), "The 'central_resolution' parameter of read_record_csv(r.csv) on "
                     f"line 2, column 1 must equal the scene's encoders' {coarse.central.distance_per_count!r}. "
                     "Got 0.0001 instead.", coarse)
    assert error.parameter == "central_resolution"
    # Within 1e-12 relative the file's value is kept.
    near = dataclasses.replace(_sensors(), central=Encoder(2 * np.pi * 0.1 / 1e-4 * (1 + 1e-13), 0.1, rate=64.0))
    assert read_record_csv(path, near).central_resolution == 1e-4
    with pytest.raises(ParameterTypeError, match="^" + re.escape(
            "The 'sensors' parameter of read_record_csv must be a Sensors or None. Got 'enc' instead.") + "$"):
        read_record_csv(path, "enc")
    with pytest.raises(ParameterTypeError, match="^" + re.escape(
            "The 'motors' parameter of read_record_csv must be a Motors or None. Got 2 instead.") + "$"):
        read_record_csv(path, motors=2)


def test_a_file_without_backlash_or_final_newline_and_with_crlf_lines(tmp_path):
    """No ``wheel_backlash`` line and no scene: no play (0); Windows line ends and a last row
    without a newline are read the same; a blank comment line is skipped."""
    path = tmp_path / "r.csv"
    path.write_bytes((_META1 + "#\n" + _HEAD + "\n0.0,1,2,0.5\n\n0.5,-3,4,-0.25").replace("\n", "\r\n").encode())
    record = read_record_csv(path)
    assert record.wheel_backlash == 0.0 and record.central_resolution == 0.5 and record.wheel_resolution == 0.25
    np.testing.assert_array_equal(record.times, [0.0, 0.5])
    np.testing.assert_array_equal(record.central_counts, [1, -3])
    np.testing.assert_array_equal(record.wheel_counts, [[2], [4]])
    np.testing.assert_array_equal(record.commands, [[0.5], [-0.25]])
    assert record.times.flags.owndata or record.times.base is None or record.times.base.size == 2


def test_folders_missing_and_oversized_files_are_named_in_full(tmp_path, monkeypatch):
    import toolkit.model.record_io as record_io

    with pytest.raises(SceneFileNotFoundError) as info:
        read_record_csv(tmp_path)
    assert str(info.value) == f"The record file {str(tmp_path)!r} is a folder, not a CSV file."
    with pytest.raises(SceneFileNotFoundError) as info:
        read_record_csv(tmp_path / "none.csv")
    assert str(info.value) == f"The record file {str(tmp_path / 'none.csv')!r} does not exist."
    path = tmp_path / "r.csv"
    path.write_text(_META1 + _HEAD + "\n0.0,1,2,0.5\n")
    size = path.stat().st_size
    assert read_record_csv(path).n_samples == 1
    monkeypatch.setattr(record_io, "MAX_RECORD_BYTES", 2 ** 20)
    body = _META1 + _HEAD + "\n0.0,1,2,0.5\n"
    path.write_text(body + " " * (2 ** 20 - len(body)))
    assert read_record_csv(path).n_samples == 1                  # at the cap: read
    _refused(tmp_path, body + " " * (2 ** 20 + 1 - len(body)), f"The record file {str(path)!r} is {2 ** 20 + 1} "
             f"bytes; record files are limited to {2 ** 20} bytes (1 MiB): split a longer log into several records.")


def test_commands_at_the_motors_limits_are_read_on_both_readers(tmp_path):
    """A command equal to a speed limit is within it (``<=``), on the block reader and on the
    row-by-row one (sent there by a bad count further down the same block, which is then the
    refusal)."""
    from toolkit.model.motors import Motors

    motors = Motors(speed_limits=(-0.25, 0.5))
    rows = _META1 + _HEAD + "\n0.0,1,2,0.5\n0.5,1,2,-0.25\n"
    path = tmp_path / "r.csv"
    path.write_text(rows)
    np.testing.assert_array_equal(read_record_csv(path, motors=motors).commands[:, 0], [0.5, -0.25])
    _refused(tmp_path, rows + "1.0,1,x,0.0\n", _at("wheel_count_1", 7, 3) + "be an integer count. Got 'x' instead.",
             motors=motors)
    _refused(tmp_path, rows.replace("-0.25", "-0.2500000000000001"), _at("command_1_m_s", 6, 4)
             + "lie within the motors' speed limits [-0.25, 0.5] m/s. Got '-0.2500000000000001' instead.",
             motors=motors)


def test_a_trailing_comma_is_a_field_too_many(tmp_path):
    _refused(tmp_path, _META1 + _HEAD + "\n0.0,1,2,0.5,\n", _at("row", 5, 5)
             + "have 4 comma-separated fields. Got 5 instead.")


def test_the_period_is_checked_across_blocks(tmp_path, monkeypatch):
    """Blocks of two rows: a step off the encoders' period between the last row of one block
    and the first of the next is refused on that row's line; the first row of the file has
    no previous row to follow."""
    import toolkit.model.record_io as record_io

    monkeypatch.setattr(record_io, "_BLOCK_ROWS", 2)
    sensors = _sensors(n=1)
    h = 2.0 ** -6
    meta = ("# active-contacts encoder record 1\n# central_resolution = 0.0001\n# wheel_resolution = 2e-05\n"
            "# wheel_backlash = 0.001\n" + _HEAD + "\n")
    good = [k * h for k in range(5)]
    path = tmp_path / "r.csv"
    path.write_text(meta + "".join(f"{t!r},0,0,0.1\n" for t in [100.0 + t for t in good]))
    assert read_record_csv(path, sensors).n_samples == 5
    bad = good[:2] + [good[2] + 0.75 * h] + [t + 0.75 * h for t in good[3:]]
    _refused(tmp_path, meta + "".join(f"{t!r},0,0,0.1\n" for t in bad), _at("time_s", 8, 1)
             + f"follow the previous row ({good[1]!r} s) by one period of the scene's encoders (0.015625 s) within "
             f"half a period. Got '{bad[2]!r}' instead.", sensors)


def test_a_line_of_exactly_the_longest_length_is_read(tmp_path, monkeypatch):
    """The line cap counts bytes before the newline: a line of exactly ``MAX_LINE_BYTES`` is
    read, one byte longer is refused at the column just past the cap."""
    import toolkit.model.record_io as record_io

    path = tmp_path / "r.csv"
    text = _META1 + _HEAD + "\n0.0,1,2,0.5\n"
    path.write_text(text)
    longest = max(len(line) for line in text.splitlines())
    monkeypatch.setattr(record_io, "MAX_LINE_BYTES", longest)
    assert read_record_csv(path).n_samples == 1
    monkeypatch.setattr(record_io, "MAX_LINE_BYTES", longest - 1)
    with pytest.raises(ParameterError, match="^" + re.escape(_at("line", 4, longest)
                                                             + f"be at most {longest - 1} bytes (1 MiB)")):
        read_record_csv(path)


def test_the_scene_encoders_agree_within_1e_12_relative_and_1e_15_absolute(tmp_path):
    """``math.isclose`` with rel_tol 1e-12 and abs_tol 1e-15, bracketed: a central resolution
    of 0.5 m 0.5e-12 off (relative) is the file's, 2e-12 off is refused; a play of 0.9e-15 m in
    the scene agrees with the file's none, 1.1e-15 m does not."""
    path = tmp_path / "r.csv"
    path.write_text(_META1 + "# wheel_backlash = 0\n" + _HEAD + "\n0.0,1,2,0.5\n")

    def encoders(central=0.5, play=0.0):
        return Sensors(Encoder(2 * np.pi / central, 1.0, rate=64.0), Encoder(2 * np.pi / 0.25, 1.0, rate=64.0,
                                                                            backlash=play), 1)

    assert read_record_csv(path, encoders(0.5 * (1 + 0.5e-12))).central_resolution == 0.5
    with pytest.raises(ParameterError, match=re.escape(_at("central_resolution", 2, 1))):
        read_record_csv(path, encoders(0.5 * (1 + 2e-12)))
    assert read_record_csv(path, encoders(play=0.9e-15)).wheel_backlash == 0.0
    with pytest.raises(ParameterError, match=re.escape(_at("wheel_backlash", 4, 1))):
        read_record_csv(path, encoders(play=1.1e-15))


def test_int64_ends_magic_spaces_and_a_missing_resolution(tmp_path):
    """The least int64 count is read exactly; the magic line may carry spaces around it; a file
    that gives the central resolution but not the wheels' needs the scene's encoders, and
    says which line is missing, on the header's line."""
    path = tmp_path / "r.csv"
    low = -2 ** 63
    path.write_text("  " + _META1.replace("\n", "  \n", 1) + _HEAD + f"\n0.0,{low},2,0.5\n")
    assert read_record_csv(path).central_counts[0] == low
    text = "# active-contacts encoder record 1\n# central_resolution = 0.5\n" + _HEAD + "\n0.0,1,2,0.5\n"
    _refused(tmp_path, text, _at("sensors", 3, 1) + "be given (the scene's [sensors]) when no '# wheel_resolution "
             "= ...' line precedes the header. Got None instead.")


def test_valid_rows_at_every_edge_are_read_by_the_block_reader(tmp_path, monkeypatch):
    """Commands at both motor limits and a step of exactly 1.5 periods are within the rules, so
    the block reader (NumPy's) takes them without the row-by-row reader (disabled here)."""
    import toolkit.model.record_io as record_io
    from toolkit.model.motors import Motors

    h = 2.0 ** -6
    meta = ("# active-contacts encoder record 1\n# central_resolution = 0.0001\n# wheel_resolution = 2e-05\n"
            "# wheel_backlash = 0.001\n" + _HEAD + "\n")
    path = tmp_path / "r.csv"
    path.write_text(meta + f"0.0,0,0,-0.25\n{1.5 * h!r},1,1,0.5\n{2.5 * h!r},2,2,0.0\n")

    def refuse(*args, **kwargs):
        raise AssertionError("a valid block went to the row-by-row reader")

    monkeypatch.setattr(record_io, "_slow_block", refuse)
    record = read_record_csv(path, _sensors(n=1), motors=Motors(speed_limits=(-0.25, 0.5)))
    np.testing.assert_array_equal(record.commands[:, 0], [-0.25, 0.5, 0.0])


def test_rows_the_block_reader_gives_up_on_are_read_whole_by_the_row_reader(tmp_path):
    """Python's int() reads a count written with a digit separator (``1_0``), NumPy's reader
    does not: that block is read row by row, each count exactly (2^63 - 1 included, which a
    float would round), and only the commands are held to the motors' limits (not the force)."""
    from toolkit.model.motors import Motors

    head = "time_s,central_count,wheel_count_1,command_1_m_s,force_N"
    top = 2 ** 63 - 1
    path = tmp_path / "r.csv"
    path.write_text(_META1 + head + f"\n0.0,1_0,{top},0.5,7.5\n0.5,-3,4,-0.25,-9.0\n")
    record = read_record_csv(path, motors=Motors(speed_limits=(-0.25, 0.5)))
    np.testing.assert_array_equal(record.central_counts, [10, -3])
    assert record.wheel_counts[0, 0] == top and record.wheel_counts.dtype == np.int64
    np.testing.assert_array_equal(record.force, [7.5, -9.0])


def test_a_byte_order_mark_only_opens_the_file_and_a_trailing_letter_is_a_bad_value(tmp_path):
    """A byte-order mark anywhere but at the file's start is not dropped (it is text: the
    comment line it opens no longer starts with '#', so it is taken for a bad header); a
    value that ends in a letter is refused as written."""
    _refused(tmp_path, ("# active-contacts encoder record 1\n\ufeff# central_resolution = 0.5\n"
                        "# wheel_resolution = 0.25\n" + _HEAD + "\n0.0,1,2,0.5\n").encode(),
             _at("header", 2, 3) + "name at least one 'wheel_count_1' column. Got '\\ufeff# central_resolution = 0.5' "
             "instead.")
    _refused(tmp_path, _META1 + _HEAD + "\n0.0,1,2,0.5X\n", _at("command_1_m_s", 5, 4)
             + "be a number. Got '0.5X' instead.")


def test_a_file_over_a_megabyte_is_counted_across_blocks(tmp_path):
    """The line count adds up every 1 MiB block (the arrays are sized by it): 60000 rows,
    about 1.6 MiB, read whole."""
    path = tmp_path / "r.csv"
    rows = "".join(f"{k / 64!r},{k},{-k},0.125\n" for k in range(60000))
    path.write_text(_META1 + _HEAD + "\n" + rows)
    assert path.stat().st_size > 1.5 * 2 ** 20
    record = read_record_csv(path)
    assert record.n_samples == 60000 and record.central_counts[-1] == 59999 and record.times[-1] == 59999 / 64


def test_the_line_count_refuses_a_file_that_grew_past_the_cap(monkeypatch):
    import io

    import toolkit.model.record_io as record_io

    monkeypatch.setattr(record_io, "MAX_RECORD_BYTES", 10)
    with pytest.raises(ParameterError) as info:
        record_io._line_count(io.BytesIO(b"0123456789\n"), record_io._Reader(Path("grown.csv")))
    assert str(info.value) == ("The record file 'grown.csv' is 11 bytes; record files are limited to 10 bytes "
                               "(9.53674e-06 MiB): split a longer log into several records.")
    # Read in blocks of 1 MiB: the size is the sum of the blocks (1.5 MiB > a 1.25 MiB cap).
    monkeypatch.setattr(record_io, "MAX_RECORD_BYTES", 5 << 18)
    with pytest.raises(ParameterError, match=f"is {3 << 19} bytes; record files are limited to {5 << 18} bytes"):
        record_io._line_count(io.BytesIO(b"\n" * (3 << 19)), record_io._Reader(Path("grown.csv")))


def test_the_progress_bar_counts_bytes_and_clears_itself(tmp_path, monkeypatch, capsys):
    """A file larger than the threshold (strictly) shows a bar in bytes with SI prefixes
    (a few kB here) on stderr, cleared when done (not left on its own line); at the
    threshold, none."""
    import toolkit.model.record_io as record_io

    path = tmp_path / "r.csv"
    path.write_text(_META1 + _HEAD + "\n" + "".join(f"{k!r}.0,{k},{k},0.5\n" for k in range(400)))
    size = path.stat().st_size
    assert 4000 < size < 999000
    monkeypatch.setattr(record_io, "_PROGRESS_BYTES", size)
    read_record_csv(path, progress=True)
    assert capsys.readouterr().err == ""
    monkeypatch.setattr(record_io, "_PROGRESS_BYTES", size - 1)
    read_record_csv(path, progress=True)
    err = capsys.readouterr().err
    assert re.search(r"r\.csv: .*/\d+\.\d+k \[.*B/s\]", err) and not err.endswith("\n")
