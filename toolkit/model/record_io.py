"""Encoder records as CSV files: what a 50 Hz logger on the hardware writes, and what a
simulated run saves in the same form (:func:`write_record_csv`, :func:`read_record_csv`).

The format (at most ``MAX_RECORD_BYTES``; written with 17 significant digits, so a record
round-trips bit for bit) is in docs/guide/estimators.md. A bad file is refused with its
line, column, rule and value."""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ParameterError, ParameterTypeError, SceneFileNotFoundError, parameter_message
from .motors import Motors
from .sensors import EncoderRecord, Sensors

__all__ = ["write_record_csv", "read_record_csv", "read_live_record", "record_csv_text", "LiveColumns",
           "RECORD_MAGIC", "MAX_RECORD_BYTES"]

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
    """Parses one file, refusing with the line and the column."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.owner = f"read_record_csv({path.name})"

    def fail(self, line: int, column: int | None, what: str, rule: str, value: Any) -> ParameterError:
        where = f"{self.owner} on line {line}" + ("" if column is None else f", column {column}")
        return ParameterError(parameter_message(what, where, rule, value))

    def number(self, text: str, line: int, column: int, name: str,
               limits: tuple[float, float] | None = None) -> float:
        try:
            value = float(text)
        except ValueError:
            raise self.fail(line, column, name, "be a number", text) from None
        if not math.isfinite(value):
            raise self.fail(line, column, name, "be finite", text)
        if limits is not None and not limits[0] <= value <= limits[1]:
            raise self.fail(line, column, name, f"lie within the motors' speed limits "
                            f"[{limits[0]:g}, {limits[1]:g}] m/s", text)
        return value

    def count(self, text: str, line: int, column: int, name: str) -> int:
        if len(text) > _COUNT_DIGITS:      # (int() of a long text is slow, and out of range anyway)
            raise self.fail(line, column, name, _COUNT_RULE, text)
        try:
            value = int(text)
        except ValueError:
            raise self.fail(line, column, name, "be an integer count", text) from None
        if not _INT64[0] <= value <= _INT64[1]:
            raise self.fail(line, column, name, _COUNT_RULE, text)
        return value


#: Largest record file :func:`read_record_csv` reads, bytes: 256 MiB (about a million rows of
#: ten wheels as a logger writes them, some 6 hours at 50 Hz; half as many with the simulated
#: truth columns). A longer log is split into records.
MAX_RECORD_BYTES = 256 << 20
#: Longest line of a record file, bytes (a row of a thousand wheels fits many times over).
MAX_LINE_BYTES = 1 << 20
#: Files larger than this show a progress bar (when allowed): they take seconds to read.
_PROGRESS_BYTES = 32 << 20
#: Rows converted at once (NumPy's reader); a bad value's line is found row by row.
_BLOCK_ROWS = 4096
_INT64 = (int(np.iinfo(np.int64).min), int(np.iinfo(np.int64).max))
_COUNT_RULE = f"be an integer count within int64 [{_INT64[0]}, {_INT64[1]}]"
_COUNT_DIGITS = 40                       # a longer count is refused unread (int() of a long text is slow)


def _lines(stream: Any, reader: _Reader, bar: Any) -> Any:
    """``(line number, text)`` of every line, decoded (a UTF-8 byte-order mark dropped), each
    at most :data:`MAX_LINE_BYTES`; advances ``bar`` by the bytes read."""
    number = 0
    while True:
        raw = stream.readline(MAX_LINE_BYTES + 1)
        if not raw:
            return
        number += 1
        bar.update(len(raw))
        if len(raw) > MAX_LINE_BYTES and not raw.endswith(b"\n"):
            raise reader.fail(number, MAX_LINE_BYTES + 1, "line", f"be at most {MAX_LINE_BYTES} bytes (1 MiB)",
                              f"a longer line ({raw[:20]!r}...)")
        try:
            text = raw.decode("utf-8-sig" if number == 1 else "utf-8")
        except UnicodeDecodeError as error:
            raise reader.fail(number, error.start + 1, "line", "be UTF-8 text (columns counted in bytes here)",
                              f"byte 0x{raw[error.start]:02x}") from None
        yield number, text.rstrip("\r\n")


def _line_count(stream: Any, reader: _Reader) -> int:
    """Lines in the file (reads it once, in blocks; refuses one over the size cap)."""
    lines, size, last = 0, 0, b"\n"
    for block in iter(lambda: stream.read(1 << 20), b""):
        size += len(block)
        if size > MAX_RECORD_BYTES:        # grew since it was measured
            raise _too_large(reader, size)
        lines += block.count(b"\n")
        last = block[-1:]
    stream.seek(0)
    return lines + (last != b"\n")


def _too_large(reader: _Reader, size: int) -> ParameterError:
    return ParameterError(f"The record file {str(reader.path)!r} is {size} bytes; record files are limited to "
                          f"{MAX_RECORD_BYTES} bytes ({MAX_RECORD_BYTES / 2**20:g} MiB): split a longer log "
                          "into several records.")


def read_record_csv(path: Any, sensors: Sensors | None = None, *, motors: Motors | None = None,
                    progress: bool = False) -> EncoderRecord:
    """Read an encoder record written by :func:`write_record_csv` or by a logger (a live run's
    columns, if any, are checked and left out: ``read_live_record`` returns them).

    The file is read as a stream (in memory at once: the arrays returned and a block of rows), at
    most ``MAX_RECORD_BYTES``; a UTF-8 byte-order mark (a spreadsheet's "CSV UTF-8") is
    accepted. Every value is checked as it is read: counts integers within int64, every
    number finite, times strictly increasing (with ``sensors``, one encoder period apart
    within half a period), commands within ``motors``' speed limits.

    Parameters
    ----------
    path : str or Path
    sensors : Sensors, optional
        The encoders that wrote it (a scene's ``[sensors]``): their resolutions and backlash
        when the file gives none; checked against the file's when both do, their wheel
        count against the file's channels and their period against the rows' times.
    motors : Motors, optional
        The motors that took the commands (a scene's ``[motors]``): every command, and the
        initial commands, must lie within their speed limits (m/s).
    progress : bool, default False
        Allow a progress bar (tqdm, on stderr) for a file large enough to take seconds.

    Raises
    ------
    SceneFileNotFoundError
        The file does not exist.
    ParameterError
        A malformed file, naming the line, the column, the rule and the value; a file over
        the size cap.
    """
    return read_live_record(path, sensors, motors=motors, progress=progress)[0]


def read_live_record(path: Any, sensors: Sensors | None = None, *, motors: Motors | None = None,
                     progress: bool = False) -> tuple[EncoderRecord, LiveColumns | None]:
    """:func:`read_record_csv`, and the live run's columns (None when the file has none)."""
    owner = "read_record_csv"
    path = Path(path)
    if sensors is not None and not isinstance(sensors, Sensors):
        raise ParameterTypeError(parameter_message("sensors", owner, "be a Sensors or None", sensors))
    if motors is not None and not isinstance(motors, Motors):
        raise ParameterTypeError(parameter_message("motors", owner, "be a Motors or None", motors))
    if path.is_dir():
        raise SceneFileNotFoundError(f"The record file {str(path)!r} is a folder, not a CSV file.")
    if not path.is_file():
        raise SceneFileNotFoundError(f"The record file {str(path)!r} does not exist.")
    reader = _Reader(path)
    size = path.stat().st_size
    if size > MAX_RECORD_BYTES:
        raise _too_large(reader, size)
    limits = None if motors is None else motors.speed_limits
    from tqdm import tqdm

    with open(path, "rb") as stream, tqdm(total=size, unit="B", unit_scale=True, desc=path.name, file=sys.stderr,
                                          leave=False, disable=not (progress and size > _PROGRESS_BYTES)) as bar:
        capacity = _line_count(stream, reader)
        lines = _lines(stream, reader, bar)
        meta, meta_lines, number, text = _preamble(lines, reader, limits)
        header = [name.strip() for name in text.split(",")]
        expected = _check_header(header, number, text, reader, sensors)
        meta_lines["header"] = number
        period = None if sensors is None else sensors.period
        record = _rows(lines, number, capacity - number, expected, reader, limits, period)
    return _record(record, meta, meta_lines, expected, reader, sensors)


def _preamble(lines: Any, reader: _Reader, limits: tuple[float, float] | None) -> tuple[dict, dict, int, str]:
    """The magic line and the ``#`` comment lines; returns their values, the line of each,
    and the header line (number, text)."""
    number, text = next(lines, (1, ""))
    if text.strip() != RECORD_MAGIC:
        raise reader.fail(1, 1, "first line", f"be {RECORD_MAGIC!r}", text[:80])
    meta: dict[str, Any] = {}
    where: dict[str, int] = {}
    for number, text in lines:
        if not text.startswith("#"):
            return meta, where, number, text
        body = text[1:].strip()
        if body:
            key, sep, value = body.partition("=")
            key = key.strip()
            if not sep or key not in _META:
                raise reader.fail(number, 1, "comment", f"be 'key = value' with a key in {list(_META)}", body)
            if key == "initial_commands":
                meta[key] = np.array([reader.number(v, number, i, key, limits)
                                      for i, v in enumerate(value.split(), start=1)])
            else:
                meta[key] = reader.number(value.strip(), number, 1, key)
                if not meta[key] > 0 and not (key == "wheel_backlash" and meta[key] == 0):
                    raise reader.fail(number, 1, key, "be > 0" if key != "wheel_backlash" else "be >= 0",
                                      value.strip())
            where[key] = number
    raise reader.fail(number + 1, 1, "header", "follow the comment lines", "end of file")


def _check_header(header: list[str], line: int, text: str, reader: _Reader,
                  sensors: Sensors | None) -> list[str]:
    """The columns the header names, checked against the format and the scene's encoders."""
    wheels = sum(1 for name in header if name.startswith("wheel_count_"))
    if wheels < 1:
        raise reader.fail(line, 3, "header", "name at least one 'wheel_count_1' column", text)
    expected = _header(wheels, "force_N" in header, "truth_speed_m_s" in header, _LIVE[0] in header)
    if header != expected:
        column = next((i for i, (a, b) in enumerate(zip(header, expected), start=1) if a != b),
                      min(len(header), len(expected)) + 1)
        raise reader.fail(line, column, "header", f"be {','.join(expected)!r}", text)
    if sensors is not None and sensors.n_wheels != wheels:
        raise reader.fail(line, 3, "header", f"name one wheel_count column per wheel encoder of the scene's "
                          f"[sensors] ({sensors.n_wheels})", f"{wheels} wheel_count columns")
    return expected


def _rows(lines: Any, header_line: int, capacity: int, expected: list[str], reader: _Reader,
          limits: tuple[float, float] | None, period: float | None) -> dict[str, np.ndarray]:
    """Every sample row into preallocated arrays, a block at a time (NumPy's reader converts
    a block; a block it refuses is read again row by row, naming the line and the column)."""
    n = sum(1 for name in expected if name.startswith("wheel_count_"))
    times, counts = np.empty(capacity), np.empty((capacity, 1 + n), dtype=np.int64)
    numbers = np.empty((capacity, len(expected) - 2 - n))      # the commands, then force and truth
    k, previous = 0, -math.inf
    block: list[tuple[int, str]] = []

    def flush() -> None:
        nonlocal k, previous
        parsed = _fast_block([text for _, text in block], len(expected), n, limits, period, previous)
        if parsed is None:
            parsed = _slow_block(block, expected, n, reader, limits, period, previous)
        m = len(block)
        times[k:k + m], counts[k:k + m], numbers[k:k + m] = parsed
        k += m
        previous = float(times[k - 1])
        block.clear()

    for number, text in lines:
        if text.strip():
            block.append((number, text))
            if len(block) == _BLOCK_ROWS:
                flush()
    if block:
        flush()
    if k == 0:
        raise reader.fail(header_line + 1, 1, "data", "hold at least one sample row", "end of file")
    if k < capacity:                   # blank lines: trim (copies only then)
        times, counts, numbers = times[:k].copy(), counts[:k].copy(), numbers[:k].copy()
    return {"times": times, "counts": counts, "numbers": numbers}


def _fast_block(texts: list[str], width: int, n: int, limits: tuple[float, float] | None, period: float | None,
                previous: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The rows converted by :func:`numpy.loadtxt`, or None when any row breaks a rule (a
    field count, a value): then :func:`_slow_block` says where."""
    read = dict(delimiter=",", comments=None, ndmin=2)
    try:
        counts = np.loadtxt(texts, dtype=np.int64, usecols=range(1, 2 + n), **read)
        floats = np.loadtxt(texts, dtype=np.float64, usecols=[0, *range(2 + n, width)], **read)
    except (ValueError, OverflowError):
        return None
    if floats.shape != (len(texts), width - 1 - n) or any(text.count(",") != width - 1 for text in texts):
        return None
    times, numbers = floats[:, 0], floats[:, 1:]
    commands = numbers[:, :n]
    steps = np.diff(times, prepend=previous)
    if (not np.all(np.isfinite(floats)) or not np.all(steps > 0)
            or (period is not None and not np.all(np.abs((steps[1:] if math.isinf(previous) else steps) - period)
                                                  <= 0.5 * period))
            or (limits is not None and not np.all((commands >= limits[0]) & (commands <= limits[1])))):
        return None
    return times, counts, numbers


def _slow_block(block: list[tuple[int, str]], expected: list[str], n: int, reader: _Reader,
                limits: tuple[float, float] | None, period: float | None,
                previous: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The block read row by row, refusing the first bad value with its line and column."""
    width = len(expected)
    m = len(block)
    times, counts, numbers = np.empty(m), np.empty((m, 1 + n), dtype=np.int64), np.empty((m, width - 2 - n))
    for j, (line, text) in enumerate(block):
        fields = text.split(",")
        if len(fields) != width:
            raise reader.fail(line, min(len(fields), width) + 1, "row",
                              f"have {width} comma-separated fields", len(fields))
        times[j] = reader.number(fields[0], line, 1, "time_s")
        if not times[j] > previous:
            raise reader.fail(line, 1, "time_s", f"increase strictly (previous row {previous!r})", fields[0])
        if period is not None and math.isfinite(previous) and not abs(times[j] - previous - period) <= 0.5 * period:
            raise reader.fail(line, 1, "time_s", f"follow the previous row ({previous!r} s) by one period of the "
                              f"scene's encoders ({period:g} s) within half a period", fields[0])
        previous = float(times[j])
        for i in range(1 + n):
            counts[j, i] = reader.count(fields[1 + i], line, 2 + i, expected[1 + i])
        for i in range(width - 2 - n):
            column = 2 + n + i
            numbers[j, i] = reader.number(fields[column], line, column + 1, expected[column],
                                          limits if i < n else None)
    return times, counts, numbers


def _record(rows: dict[str, np.ndarray], meta: dict[str, Any], meta_lines: dict[str, int], expected: list[str],
            reader: _Reader, sensors: Sensors | None) -> tuple[EncoderRecord, LiveColumns | None]:
    """The record from the rows and the comment lines, resolutions checked against ``sensors``."""
    n = rows["counts"].shape[1] - 1
    resolutions = {}
    for key, from_sensors in (("central_resolution", None if sensors is None else sensors.central.distance_per_count),
                              ("wheel_resolution", None if sensors is None else sensors.wheel.distance_per_count),
                              ("wheel_backlash", None if sensors is None else sensors.backlash)):
        value = meta.get(key, from_sensors)
        if value is None:
            if key == "wheel_backlash":
                value = 0.0
            else:
                raise reader.fail(meta_lines["header"], 1, "sensors", f"be given (the scene's [sensors]) when "
                                  f"no '# {key} = ...' line precedes the header", None)
        if from_sensors is not None and not math.isclose(value, from_sensors, rel_tol=1e-12, abs_tol=1e-15):
            raise reader.fail(meta_lines[key], 1, key, f"equal the scene's encoders' {from_sensors!r}", value)
        resolutions[key] = value
    initial = meta.get("initial_commands")
    if initial is not None and initial.shape != (n,):
        raise reader.fail(meta_lines["initial_commands"], 1, "initial_commands", f"hold {n} speeds", initial.size)
    numbers = rows["numbers"]
    fields: dict[str, Any] = {}
    column = n
    if "force_N" in expected:
        fields["force"] = numbers[:, column]
        column += 1
    if "truth_speed_m_s" in expected:
        fields.update(truth_speed=numbers[:, column], truth_position=numbers[:, column + 1],
                      truth_contact_speeds=numbers[:, column + 2:column + 2 + n])
        column += 2 + n
    live = None
    if _LIVE[0] in expected:           # (the sequence numbers, read as doubles: exact below 2**53)
        live = LiveColumns(numbers[:, column].astype(np.int64), *(numbers[:, column + i].copy() for i in range(1, 5)))
    counts = rows["counts"]
    return EncoderRecord(rows["times"], counts[:, 0], counts[:, 1:], numbers[:, :n],
                         resolutions["central_resolution"], resolutions["wheel_resolution"],
                         resolutions["wheel_backlash"], initial_commands=initial, **fields), live
