"""Encoder records as CSV files: what a 50 Hz logger on the hardware writes, and what a
simulated run saves in the same form.

The format (UTF-8 text; ``#`` lines first, then one header row, then one row per sample)::

    # active-contacts encoder record 1
    # central_resolution = 0.00020401...     (m per central count; optional)
    # wheel_resolution = 7.8715...e-05       (m per wheel count at the contact; optional)
    # wheel_backlash = 0.0008                (m at the contact; optional, default 0)
    # initial_commands = 0.0 0.0 ...         (m/s, the commands before the first row; optional)
    time_s,central_count,wheel_count_1,...,wheel_count_n,command_1_m_s,...,command_n_m_s[,force_N]
    0.0,0,0,...,0.15,...

Required columns, in this order: the sample time (s, strictly increasing), the central
encoder's count, one count per wheel channel, one commanded contact speed per wheel (m/s,
sent at that sample and held to the next). Optional, after them: ``force_N`` (an outside
force held over the period), then the simulated truth ``truth_speed_m_s``,
``truth_position_m`` and ``truth_contact_speed_1_m_s .. _n_m_s`` (for scoring; a hardware log
has none), then a live run's (:class:`LiveColumns`; :func:`read_record_csv` skips them). Counts are integers; every number finite. The resolutions come from the comment
lines or, when the file has none, from the scene's encoders (``sensors``); both present must
agree. Numbers are written with 17 significant digits (``repr``), so a record written and
read back is the same record, bit for bit (tested). A malformed file is refused with its line
number, the column, the rule and the value found.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ParameterError, ParameterTypeError, SceneFileNotFoundError, parameter_message
from .sensors import EncoderRecord, Sensors

__all__ = ["write_record_csv", "read_record_csv", "read_live_record", "record_csv_text", "LiveColumns",
           "RECORD_MAGIC"]

#: The first line of every record file (its version).
RECORD_MAGIC = "# active-contacts encoder record 1"
_META = ("central_resolution", "wheel_resolution", "wheel_backlash", "initial_commands")
_LIVE = ("sequence", "received_s", "answered_s", "estimate_m_s", "estimate_variance_m2_s2")


@dataclass(frozen=True, eq=False)
class LiveColumns:
    """What a live run logs beside each sample's counts and commands
    (:func:`toolkit.live.run_live`).

    Attributes
    ----------
    sequence : ndarray of shape (k,), int
        The device's sequence number of the sample.
    received, answered : ndarray of shape (k,), s
        Host time the sample's line was received and its command written (from the start).
    estimate, variance : ndarray of shape (k,), m/s and (m/s)^2
        The estimate the controller acted on, and its variance.
    """

    sequence: np.ndarray
    received: np.ndarray
    answered: np.ndarray
    estimate: np.ndarray
    variance: np.ndarray


def _header(n: int, force: bool, truth: bool, live: bool = False) -> list[str]:
    names = (["time_s", "central_count"] + [f"wheel_count_{i}" for i in range(1, n + 1)]
             + [f"command_{i}_m_s" for i in range(1, n + 1)])
    if force:
        names.append("force_N")
    if truth:
        names += ["truth_speed_m_s", "truth_position_m"] + [f"truth_contact_speed_{i}_m_s" for i in range(1, n + 1)]
    if live:
        names += list(_LIVE)
    return names


def write_record_csv(record: EncoderRecord, path: Any, live: LiveColumns | None = None) -> Path:
    """Write ``record`` to ``path`` (CSV, the format of the module docstring); return the path.

    The truth columns are written when the record has the true speed, position and contact
    speeds (a simulated record); ``force_N`` when it has a force; a live run's columns when
    ``live`` is given (one entry per sample).
    """
    path = Path(path)
    path.write_text(record_csv_text(record, "write_record_csv", live), encoding="utf-8")
    return path


def record_csv_text(record: EncoderRecord, owner: str = "record_csv_text", live: LiveColumns | None = None) -> str:
    """The CSV text :func:`write_record_csv` writes (for a caller that writes files its own way)."""
    if not isinstance(record, EncoderRecord):
        raise ParameterTypeError(parameter_message("record", owner, "be an EncoderRecord", record))
    if live is not None and (not isinstance(live, LiveColumns) or live.sequence.shape != (record.n_samples,)):
        raise ParameterError(parameter_message("live", owner, f"be LiveColumns of {record.n_samples} samples",
                                               live))
    n = record.n_wheels
    truth = (record.truth_speed is not None and record.truth_position is not None
             and record.truth_contact_speeds is not None)
    force = record.force is not None
    lines = [RECORD_MAGIC,
             f"# central_resolution = {record.central_resolution!r}",
             f"# wheel_resolution = {record.wheel_resolution!r}",
             f"# wheel_backlash = {record.wheel_backlash!r}"]
    if record.initial_commands is not None:
        lines.append("# initial_commands = " + " ".join(repr(float(v)) for v in record.initial_commands))
    lines.append(",".join(_header(n, force, truth, live is not None)))
    for k in range(record.n_samples):
        row = [repr(float(record.times[k])), str(int(record.central_counts[k]))]
        row += [str(int(c)) for c in record.wheel_counts[k]]
        row += [repr(float(u)) for u in record.commands[k]]
        if force:
            row.append(repr(float(record.force[k])))
        if truth:
            row += [repr(float(record.truth_speed[k])), repr(float(record.truth_position[k]))]
            row += [repr(float(v)) for v in record.truth_contact_speeds[k]]
        if live is not None:
            row += [str(int(live.sequence[k]))] + [repr(float(column[k])) for column in
                                                   (live.received, live.answered, live.estimate, live.variance)]
        lines.append(",".join(row))
    return "\n".join(lines) + "\n"


class _Reader:
    """Parses one file, refusing with the line number."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.owner = f"read_record_csv({path.name})"

    def fail(self, line: int, what: str, rule: str, value: Any) -> ParameterError:
        return ParameterError(parameter_message(what, f"{self.owner} on line {line}", rule, value))

    def number(self, text: str, line: int, column: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise self.fail(line, column, "be a number", text) from None
        if not math.isfinite(value):
            raise self.fail(line, column, "be finite", text)
        return value

    def count(self, text: str, line: int, column: str) -> int:
        try:
            return int(text)
        except ValueError:
            raise self.fail(line, column, "be an integer count", text) from None


def read_record_csv(path: Any, sensors: Sensors | None = None) -> EncoderRecord:
    """Read an encoder record written by :func:`write_record_csv` or by a logger (a live run's
    columns, if any, are checked and left out: :func:`read_live_record` returns them).

    Parameters
    ----------
    path : str or Path
    sensors : Sensors, optional
        The encoders that wrote it (a scene's ``[sensors]``): their resolutions and backlash
        when the file gives none; checked against the file's when both do, and their wheel
        count against the file's channels.

    Raises
    ------
    SceneFileNotFoundError
        The file does not exist.
    ParameterError
        A malformed file, naming the line, the column, the rule and the value.
    """
    return read_live_record(path, sensors)[0]


def read_live_record(path: Any, sensors: Sensors | None = None) -> tuple[EncoderRecord, LiveColumns | None]:
    """:func:`read_record_csv`, and the live run's columns (None when the file has none)."""
    owner = "read_record_csv"
    path = Path(path)
    if sensors is not None and not isinstance(sensors, Sensors):
        raise ParameterTypeError(parameter_message("sensors", owner, "be a Sensors or None", sensors))
    if path.is_dir():
        raise SceneFileNotFoundError(f"The record file {str(path)!r} is a folder, not a CSV file.")
    if not path.is_file():
        raise SceneFileNotFoundError(f"The record file {str(path)!r} does not exist.")
    reader = _Reader(path)
    lines = path.read_text(encoding="utf-8").splitlines()
    if not lines or lines[0].strip() != RECORD_MAGIC:
        raise reader.fail(1, "first line", f"be {RECORD_MAGIC!r}", lines[0] if lines else "")
    meta: dict[str, Any] = {}
    index = 1
    while index < len(lines) and lines[index].startswith("#"):
        body = lines[index][1:].strip()
        if body:
            key, sep, value = body.partition("=")
            key = key.strip()
            if not sep or key not in _META:
                raise reader.fail(index + 1, "comment", f"be 'key = value' with a key in {list(_META)}", body)
            if key == "initial_commands":
                meta[key] = np.array([reader.number(v, index + 1, key) for v in value.split()])
            else:
                meta[key] = reader.number(value.strip(), index + 1, key)
        index += 1
    if index == len(lines):
        raise reader.fail(index, "header", "follow the comment lines", "end of file")
    header = [name.strip() for name in lines[index].split(",")]
    header_line = index + 1
    wheels = sum(1 for name in header if name.startswith("wheel_count_"))
    if wheels < 1:
        raise reader.fail(header_line, "header", "name at least one 'wheel_count_1' column", lines[index])
    force = "force_N" in header
    truth = "truth_speed_m_s" in header
    live = "sequence" in header
    expected = _header(wheels, force, truth, live)
    if header != expected:
        raise reader.fail(header_line, "header", f"be {','.join(expected)!r}", lines[index])
    n = wheels
    rows = [(number + 1, line) for number, line in enumerate(lines[index + 1:], start=index + 1) if line.strip()]
    if not rows:
        raise reader.fail(header_line + 1, "data", "hold at least one sample row", "end of file")
    k = len(rows)
    times, central = np.empty(k), np.empty(k, dtype=np.int64)
    wheel, commands = np.empty((k, n), dtype=np.int64), np.empty((k, n))
    extra = np.empty((k, len(expected) - 2 - 2 * n))
    for j, (line, text) in enumerate(rows):
        fields = text.split(",")
        if len(fields) != len(expected):
            raise reader.fail(line, "row", f"have {len(expected)} comma-separated fields", len(fields))
        times[j] = reader.number(fields[0], line, "time_s")
        if j and not times[j] > times[j - 1]:
            raise reader.fail(line, "time_s", f"increase strictly (previous row {float(times[j - 1])!r})", fields[0])
        central[j] = reader.count(fields[1], line, "central_count")
        for i in range(n):
            wheel[j, i] = reader.count(fields[2 + i], line, expected[2 + i])
            commands[j, i] = reader.number(fields[2 + n + i], line, expected[2 + n + i])
        for i, column in enumerate(expected[2 + 2 * n:]):
            text = fields[2 + 2 * n + i]
            extra[j, i] = reader.count(text, line, column) if column == "sequence" else reader.number(text, line, column)
    resolutions = {}
    for key, from_sensors in (("central_resolution", None if sensors is None else sensors.central.distance_per_count),
                              ("wheel_resolution", None if sensors is None else sensors.wheel.distance_per_count),
                              ("wheel_backlash", None if sensors is None else sensors.backlash)):
        value = meta.get(key, from_sensors)
        if value is None:
            if key == "wheel_backlash":
                value = 0.0
            else:
                raise ParameterError(parameter_message(
                    "sensors", owner, f"be given when the file states no {key} (the scene's [sensors])", None))
        if from_sensors is not None and not math.isclose(value, from_sensors, rel_tol=1e-12, abs_tol=1e-15):
            raise ParameterError(parameter_message(
                key, f"{owner}({path.name})", f"equal the scene's encoders' {from_sensors!r}", value))
        resolutions[key] = value
    if sensors is not None and sensors.n_wheels != n:
        raise ParameterError(parameter_message("sensors", owner, f"have the file's {n} wheel channels",
                                               sensors.n_wheels))
    initial = meta.get("initial_commands")
    if initial is not None and initial.shape != (n,):
        raise ParameterError(parameter_message("initial_commands", f"{owner}({path.name})",
                                               f"hold {n} speeds", initial.size))
    column = 0
    fields: dict[str, Any] = {}
    if force:
        fields["force"] = extra[:, 0]
        column = 1
    if truth:
        fields.update(truth_speed=extra[:, column], truth_position=extra[:, column + 1],
                      truth_contact_speeds=extra[:, column + 2:column + 2 + n])
    columns = None
    if live:
        values = extra[:, extra.shape[1] - len(_LIVE):]
        columns = LiveColumns(values[:, 0].astype(np.int64), *(values[:, i].copy() for i in range(1, len(_LIVE))))
    record = EncoderRecord(times, central, wheel, commands, resolutions["central_resolution"],
                           resolutions["wheel_resolution"], resolutions["wheel_backlash"],
                           initial_commands=initial, **fields)
    return record, columns
