"""The live loop (toolkit.live): the line protocol, the record's live columns, the simulated
device over a pseudo-terminal against the offline loop, the replay of a live log, and the
safety rules (Ctrl-C, silence, corrupt lines, a handshake unlike the scene, bad ports)."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
import tty
from pathlib import Path

import numpy as np
import pytest

from toolkit import build_scene, load_scene
from toolkit.errors import DeviceError
from toolkit.live import (Device, DeviceFaults, DeviceWorld, Hello, LinkCounts, LiveStatus, SerialDevice,
                          SimulatedDevice, run_live)
from toolkit.live import protocol
from toolkit.live.runner import MISSED_RUN
from toolkit.live.scene import scene_device, scene_loop, warm_loop
from toolkit.loop import closed_loop
from toolkit.model.record_io import LiveColumns, read_live_record, read_record_csv, write_record_csv
from toolkit.scenes.spec import loads_scene
from toolkit.scenes.study import control_world, estimate_record

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "designs" / "speed_hold_live.toml"

# The live loop runs against the wall clock (a device over a pseudo-terminal, deadlines per
# period): under pytest-xdist these tests run on one worker, one at a time, with the other
# tests that do (Makefile, --dist loadgroup).
pytestmark = pytest.mark.wall_clock


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "toolkit.cli", *args], capture_output=True, text=True, cwd=ROOT,
                          timeout=600)


#: A world unlike the scene in the ways [control.truth] offers (the device runs it; the
#: estimator is told the scene). Not friction_spread: the offline loop binds the controller
#: to the true plant (its allocation sees the drawn wheels), a live host binds it to the scene.
TRUTH = """
[control.truth]
drag = 2.5
lag = 0.01
contact_drift = 0.002
read_noise = 0.4
missed_count_prob = 0.01
jitter = 0.002
"""


@pytest.fixture(scope="module")
def slow_scene(tmp_path_factory):
    """The shipped design at 20 Hz, as a file: a loaded machine's pauses of a few tens of ms
    (in the host or the simulated device) do not read as 3 periods of silence."""
    path = tmp_path_factory.mktemp("scene") / "speed_hold_live.toml"
    path.write_text(DESIGN.read_text().replace("rate = 50.0 ", "rate = 20.0 "))
    return path


def slow_design(rate: float, truth: str = ""):
    """The shipped design read at ``rate`` Hz (a long period leaves the host's answer time to
    spare on a loaded machine), on the world ``truth`` declares."""
    text = DESIGN.read_text().replace("rate = 50.0 ", f"rate = {rate!r} ") + truth
    return build_scene(loads_scene(text, name="speed_hold_live"))


# -- the protocol ---------------------------------------------------------------------------------

def test_checksum_is_crc16_ccitt_false():
    # The catalogue's check value of CRC-16/CCITT-FALSE over "123456789" is 0x29B1.
    assert protocol.crc(b"123456789") == 0x29B1
    assert protocol.encode("STOP") == b"$STOP*%04X\n" % protocol.crc(b"STOP")


def test_lines_round_trip_exactly():
    speeds = np.array([0.1, -0.35, 1 / 3, 2.0 ** -40])
    command = protocol.parse(protocol.command_line(7, speeds))
    assert command.seq == 7
    np.testing.assert_array_equal(command.speeds, speeds)                  # 17 digits: bit for bit
    sample = protocol.parse(protocol.sample_line(3, 2**32 + 5, -12, np.array([4, -5], dtype=np.int64)))
    assert (sample.seq, sample.device_us, sample.central, sample.wheels.tolist()) == (3, 5, -12, [4, -5])
    hello = protocol.parse(protocol.hello_line(10, 50.0, 8192.0, 3591.84))
    assert hello == Hello(protocol.VERSION, 10, 50.0, 8192.0, 3591.84)


@pytest.mark.parametrize("spot", [1, 3, 8, -7])
def test_a_changed_byte_is_refused(spot):
    line = bytearray(protocol.sample_line(12, 240000, 5, np.array([1, 2, 3], dtype=np.int64)))
    line[spot] ^= 0x01
    with pytest.raises(protocol.ProtocolError):
        protocol.parse(bytes(line))


# -- the record's live columns -------------------------------------------------------------------

def test_live_columns_round_trip_and_old_readers_skip_them(tmp_path):
    scene = slow_design(10.0)
    record = _offline(scene, 1.0).record
    k = record.n_samples
    rng = np.random.default_rng(1)
    live = LiveColumns(np.arange(k) * 2, rng.random(k), rng.random(k) + 1, rng.normal(size=k), rng.random(k))
    path = write_record_csv(record, tmp_path / "record.csv", live)
    back, columns = read_live_record(path)
    for name in ("sequence", "received", "answered", "estimate", "variance"):
        np.testing.assert_array_equal(getattr(columns, name), getattr(live, name))       # bit for bit
    np.testing.assert_array_equal(read_record_csv(path).wheel_counts, record.wheel_counts)
    assert read_live_record(write_record_csv(record, tmp_path / "plain.csv"))[1] is None


# -- the simulated device against the offline loop ------------------------------------------------

def _offline(objects, duration):
    plant, sensors, wander = control_world(objects, duration)
    spec, control = objects.scene.control, objects.control
    return closed_loop.simulate_closed_loop(plant, control.controller, duration, sensors=sensors,
                                            estimator=control.estimator, v0=spec.v0, seed=spec.seed,
                                            budget=control.budget, wander=wander)


def test_live_loop_on_the_simulated_device_is_the_offline_loop(monkeypatch):
    # With each command taking effect from its sample's instant (the offline loop's
    # idealization), the device is the offline loop's plant side and the host its per-sample
    # step: the same samples, estimates, commands and true speeds, bit for bit.
    duration = 2.0
    objects = slow_design(10.0, TRUTH)
    monkeypatch.setattr(closed_loop, "_COMPILED", False)         # the offline loop around advance
    offline = _offline(objects, duration)
    objects = slow_design(10.0, TRUTH)                           # a fresh estimator
    loop = scene_loop(objects, duration)
    warm_loop(loop)
    plant, sensors, wander = control_world(objects, duration)
    spec = objects.scene.control
    device = SimulatedDevice(DeviceWorld(plant, sensors, spec.v0, spec.seed, wander), apply="sample")
    live = run_live(loop, device)
    assert live.status is LiveStatus.COMPLETED
    if device.report["missing"]:
        pytest.skip("a command missed its 0.1 s period on this machine: the device held the last one")
    k = offline.times.size
    np.testing.assert_array_equal(live.record.times, offline.times)
    np.testing.assert_array_equal(live.record.central_counts, offline.record.central_counts)
    np.testing.assert_array_equal(live.estimate, offline.estimate)
    np.testing.assert_array_equal(live.record.commands, offline.commands)
    np.testing.assert_array_equal(device.truth.truth_speed[:k], offline.speed)
    np.testing.assert_array_equal(device.truth.truth_contact_speeds[:k], offline.contact_speeds)


@pytest.mark.slow
def test_a_live_log_replays_bit_for_bit(tmp_path, slow_scene):
    out, replay = tmp_path / "live", tmp_path / "replay"
    run = cli("live", str(slow_scene), "--device", "sim", "--duration", "3", "--out", str(out))
    assert run.returncode == 0, run.stderr
    _, live = read_live_record(out / "record.csv")
    again = cli("estimate", str(slow_scene), "--record", str(out / "record.csv"), "--out", str(replay))
    assert again.returncode == 0, again.stderr
    lines = (replay / "estimate.csv").read_text().splitlines()
    column = lines[0].split(",").index("kalman_speed_m_s")
    replayed = np.array([float(line.split(",")[column]) for line in lines[1:]])
    np.testing.assert_array_equal(replayed, live.estimate)                         # bit for bit
    objects = build_scene(load_scene(slow_scene))
    record = read_record_csv(out / "record.csv", objects.estimation.sensors)
    np.testing.assert_array_equal(estimate_record(objects, record).results[0].speed, live.estimate)
    result = json.loads((out / "result.json").read_text())
    assert result["status"] == "COMPLETED" and result["timing"]["samples"] == live.sequence.size
    assert result["score"]["estimate_rms_error"] > 0          # scored against the device's truth file


# -- safety ---------------------------------------------------------------------------------------

@pytest.mark.slow
def test_ctrl_c_sends_zeros_within_a_period_and_exits_130(tmp_path, slow_scene):
    process = subprocess.Popen([sys.executable, "-m", "toolkit.cli", "live", str(slow_scene), "--device", "sim",
                                "--duration", "60", "--out", str(tmp_path)], cwd=ROOT, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    assert process.stdout.readline().startswith("live on sim")          # the loop runs
    time.sleep(1.0)                                                    # (a Ctrl-C mid-run, not at its start)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=120)
    assert process.returncode == 130
    assert len(err.splitlines()) == 1 and "interrupted" in err
    result = json.loads((tmp_path / "result.json").read_text())
    assert result["status"] == "INTERRUPTED" and result["timing"]["samples"] >= 1
    stop = result["device"]["stop"]
    # STOP (wheels to zero) came before the device's next sample: at most one sample passed
    # after the last command it took.
    assert stop is not None and stop["sample"] - stop["last_command"] <= 1
    truth = read_record_csv(tmp_path / "truth.csv")
    np.testing.assert_array_equal(truth.commands[-1], 0.0)


@pytest.mark.slow
def test_silence_sends_zeros_and_exits_3(tmp_path, slow_scene):
    run = cli("live", str(slow_scene), "--device", "sim?silent_after=20", "--duration", "5", "--out", str(tmp_path))
    assert run.returncode == 3
    assert run.stderr.splitlines() == [run.stderr.strip()] and "silent for 3 periods" in run.stderr
    result = json.loads((tmp_path / "result.json").read_text())
    assert result["status"] == "SILENCE" and result["timing"]["samples"] == 20
    assert result["device"]["stop"] is not None                       # the host stopped it
    np.testing.assert_array_equal(read_record_csv(tmp_path / "truth.csv").commands[-1], 0.0)


@pytest.mark.slow
def test_corrupt_lines_are_counted_and_skipped(tmp_path, slow_scene):
    run = cli("live", str(slow_scene), "--device", "sim?corrupt=0.01", "--duration", "10", "--out",
              str(tmp_path / "out"), "--json")
    assert run.returncode == 0, run.stderr
    result = json.loads(run.stdout)
    corrupted = result["device"]["corrupted"]
    assert corrupted >= 1                                             # 201 lines at 1 %: the seed's draw
    timing = result["timing"]
    assert timing["corrupt"] == corrupted and timing["lost"] == corrupted
    assert timing["samples"] == 201 - corrupted and result["status"] == "COMPLETED"
    # The loop holds: the true speed at the end is the reference to within half a wheel-count
    # speed step at 20 Hz (1.6 mm/s), as without corruption.
    assert abs(result["score"]["final_speed"] - 0.15) < 0.5 * 1.6e-3


def test_a_handshake_unlike_the_scene_is_refused_naming_what_differs():
    objects = slow_design(50.0)
    loop = scene_loop(objects, 1.0)
    plant, sensors, _ = control_world(objects, 1.0)
    other = Hello(protocol.VERSION, 9, 200.0, 8192.0, 3591.84)
    device = SimulatedDevice(DeviceWorld(plant, sensors), DeviceFaults(hello=other))
    with pytest.raises(DeviceError) as error:
        run_live(loop, device)
    text = str(error.value)
    assert "wheels 9" in text and "(the scene's: 10)" in text and "rate 200 Hz" in text
    assert "central_cpr" not in text and "wheel_cpr" not in text          # those agree


def test_a_missing_port_is_one_line_exit_2(tmp_path):
    run = cli("live", str(DESIGN), "--device", "serial:///dev/no-such-port?baud=115200", "--out", str(tmp_path))
    assert run.returncode == 2 and len(run.stderr.splitlines()) == 1
    assert "'device'" in run.stderr and "/dev/no-such-port" in run.stderr and "Traceback" not in run.stderr
    with pytest.raises(DeviceError, match="serial://PATH"):
        scene_device(build_scene(load_scene(DESIGN)), "usb:ttyACM0", 1.0)


def test_a_busy_port_is_one_line_exit_2(tmp_path):
    import serial

    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    held = serial.Serial(path, exclusive=True)                         # another program holds it
    try:
        run = cli("live", str(DESIGN), "--device", f"serial://{path}", "--out", str(tmp_path))
    finally:
        held.close()
        os.close(master)
        os.close(slave)
    assert run.returncode == 2 and len(run.stderr.splitlines()) == 1
    assert "busy" in run.stderr and path in run.stderr


def test_the_docs_examples_are_valid_lines():
    text = (ROOT / "docs" / "live.md").read_text()
    lines = [line.strip() for line in text.splitlines() if line.startswith("    $")]
    assert len(lines) == 8
    kinds = [type(protocol.parse(line.encode())).__name__ for line in lines]
    assert kinds == ["Query", "Hello", "Start", "Sample", "Command", "Sample", "Command", "Stop"]


class _Bench(Device):
    """A device in memory: samples at once (counts at rest), commands kept; ``interrupt_at``
    raises KeyboardInterrupt instead of that sample (a Ctrl-C while waiting for it)."""

    def __init__(self, interrupt_at: int | None = None) -> None:
        self.counts, self.sent, self.closed, self.k, self.interrupt_at = LinkCounts(), [], 0, 0, interrupt_at

    def open(self, expected):
        return expected

    def read_sample(self, deadline):
        if self.k == self.interrupt_at:
            raise KeyboardInterrupt
        self.k += 1
        return protocol.Sample(self.k - 1, (self.k - 1) * 20000, 0, np.zeros(10, dtype=np.int64))

    def write_command(self, seq, speeds):
        self.sent.append((seq, speeds.copy()))

    def close(self):
        self.closed += 1


class _Slow:
    """An estimator that takes ``delay`` seconds to observe (a host that cannot keep up)."""

    def __init__(self, estimator, delay):
        self.estimator, self.delay = estimator, delay

    def reset(self, **state):
        self.estimator.reset(**state)

    def observe(self, sample):
        time.sleep(self.delay)
        return self.estimator.observe(sample)

    def commanded(self, command, force=0.0):
        self.estimator.commanded(command, force)


def test_missed_deadlines_in_a_row_stop_the_run():
    loop = scene_loop(slow_design(50.0), 5.0)
    slow = dataclasses.replace(loop, estimator=_Slow(loop.estimator, 1.5 * 0.02))    # 1.5 periods each
    device = _Bench()
    result = run_live(slow, device)
    # Each step 1.5 periods or more (a loaded machine stretches the sleep): a step of m
    # periods counts m, so the run stops after 3 samples at most, every one of them late.
    assert result.status is LiveStatus.MISSED and 2 <= result.sequence.size <= MISSED_RUN
    assert result.missed == result.sequence.size and device.closed == 1
    assert "deadlines missed in a row" in result.message and "zero commands sent" in result.message


class _Stall(_Slow):
    """An estimator that stalls ``delay`` seconds once, on the sample read at ``at`` s."""

    def __init__(self, estimator, delay, at):
        super().__init__(estimator, delay)
        self.at = at

    def observe(self, sample):
        if sample.time == self.at:
            time.sleep(self.delay)
        return self.estimator.observe(sample)


def test_one_step_of_several_periods_stops_the_run():
    # A host that stalls 5 periods on one sample (the samples that came meanwhile would be
    # answered after their successors) misses 5 deadlines in a row: the run stops there.
    loop = scene_loop(slow_design(50.0), 5.0)
    warm_loop(loop)                      # (no first-use cost in the steps before the stall)
    stalled = dataclasses.replace(loop, estimator=_Stall(loop.estimator, 5 * 0.02, at=0.08))
    device = _Bench()
    result = run_live(stalled, device)
    assert result.status is LiveStatus.MISSED and result.record.times[-1] == 0.08
    assert result.latency[-1] >= 5 * 0.02 and device.closed == 1


def test_ctrl_c_while_waiting_ends_the_run_and_closes_the_device():
    loop = scene_loop(slow_design(50.0), 5.0)
    device = _Bench(interrupt_at=7)
    result = run_live(loop, device)
    assert result.status is LiveStatus.INTERRUPTED and result.sequence.tolist() == list(range(7))
    assert device.closed == 1 and [seq for seq, _ in device.sent] == list(range(7))
    np.testing.assert_array_equal(result.record.commands, np.array([u for _, u in device.sent]))


def test_a_sample_waiting_past_the_deadline_is_read_not_silence():
    # The host was busy past its deadline while the device kept sending: the sample waiting
    # on the port is read (a poll), and silence is only a port with nothing on it.
    import time

    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        device = SerialDevice(f"serial://{os.ttyname(slave)}")
        os.write(master, protocol.sample_line(0, 20000, 12, np.array([5, 9])))
        time.sleep(0.05)                          # the line is on the port before the read
        sample = device.read_sample(time.perf_counter() - 1.0)
        assert sample is not None and (sample.seq, sample.central, sample.wheels.tolist()) == (0, 12, [5, 9])
        assert device.read_sample(time.perf_counter() - 1.0) is None
        device._port.close()
    finally:
        os.close(master)
        os.close(slave)
