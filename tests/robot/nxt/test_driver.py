"""The NXT driver against the emulated brick on a pseudo-terminal: it drives, reads every
sensor, fires the camera; its frames equal nxt-python's; it survives garbage, dropped
replies and error statuses; it fails clearly and stops the motors when the port goes."""

import os
import struct
import subprocess
import sys
import textwrap
import threading
import time

import nxt.motor
import nxt.sensor
import numpy as np
import pytest
from nxt.brick import Brick

from ibr.errors import InputError
from robot.nxt import protocol as P
from robot.nxt.driver import LinkConfig, NXTRobot, NXTRobotConfig, RobotConnectionError
from robot.nxt.emulator import EmulatorConfig, NXTEmulator
from robot.photo_source import FolderPhotoSource, OpenCVPhotoSource
from robot.protocol import Robot

FAST = EmulatorConfig(time_scale=20.0)
CONFIG = NXTRobotConfig(poll_s=0.005, shutter_pulse_s=0.02, stall_s=0.2, image_size=(64, 48))
LINK = LinkConfig(timeout_s=0.2, retries=2, reconnect_s=0.3, reconnect_interval_s=0.02)


@pytest.fixture()
def emu(tmp_path):
    (tmp_path / "card").mkdir()
    with NXTEmulator(FAST, camera_dir=tmp_path / "card", link=tmp_path / "rfcomm0") as e:
        yield e


@pytest.fixture()
def robot(emu):
    with NXTRobot(emu.port, CONFIG, FolderPhotoSource(emu.camera_dir), LINK) as r:
        yield r


def test_is_a_robot(robot):
    assert isinstance(robot, Robot)


def test_drive_and_turn_odometry_follows_the_wheels(robot, emu):
    r = robot.drive(0.5)
    assert not r.blocked
    assert r.odometry_delta[0] == pytest.approx(0.5, abs=0.01)
    assert emu.pose[0] == pytest.approx(0.5, abs=0.01)
    r = robot.turn(np.pi / 2)
    assert r.odometry_delta[2] == pytest.approx(np.pi / 2, abs=0.03)
    robot.drive(-0.3)
    odo = robot.odometry()
    assert np.allclose(odo[:2], emu.pose[:2], atol=0.02)  # start pose is the origin of both
    assert odo[2] == pytest.approx(emu.pose[2], abs=0.03)
    assert all(m.power == 0 for m in emu.motors)  # stopped after every motion


def test_both_wheels_start_together_over_a_slow_link(tmp_path):
    """Over a link with a Bluetooth-like round trip the right wheel's command must not wait
    for the left's reply: the left wheel alone would pivot the robot about the right one
    (about 4 cm at this round trip) and a turn in place would move it."""
    (tmp_path / "card").mkdir()
    slow = EmulatorConfig(time_scale=FAST.time_scale, reply_latency_s=0.03)
    with NXTEmulator(slow, camera_dir=tmp_path / "card") as emu, \
            NXTRobot(emu.port, CONFIG, FolderPhotoSource(emu.camera_dir), LINK) as robot:
        robot.turn(np.pi / 2)
        assert emu.pose[2] == pytest.approx(np.pi / 2, abs=0.03)
        assert np.hypot(*emu.pose[:2]) < 0.005
        assert np.allclose(robot.odometry()[:2], emu.pose[:2], atol=0.01)


def test_every_sensor_reads_the_simulated_world(robot, emu):
    assert robot.battery_mv() == FAST.battery_mv
    assert robot.ultrasonic() == pytest.approx(2.0)  # facing +x, the wall is 2 m away
    assert robot.compass() == pytest.approx(0.0, abs=np.radians(1))
    robot.turn(np.pi / 2)
    assert robot.compass() == pytest.approx(emu.pose[2], abs=np.radians(1))
    assert robot.ultrasonic() == pytest.approx(1.5 - emu.pose[1], abs=0.01)
    assert robot.bumpers() == (False, False)
    r = robot.drive(5.0)  # into the wall at y = 1.5
    assert r.bumper_front and not r.bumper_rear and r.odometry_delta[0] < 1.45
    assert robot.bumpers() == (True, False)
    assert emu.pose[1] == pytest.approx(1.5 - FAST.robot_radius_m, abs=0.02)
    r = robot.drive(-0.2)
    assert not r.blocked and robot.bumpers() == (False, False)


def test_stall_without_bumper(robot, emu):
    robot.brick.set_input_mode(0, 0, 0)  # front bumper unplugged: the wall goes unseen
    robot.turn(-np.pi / 2)
    r = robot.drive(5.0)  # into the wall at y = -1.5 with no bumper to tell
    assert r.stalled and not r.bumper_front


def test_capture_fires_the_shutter_and_matches_the_photo(robot, emu):
    robot.drive(0.2)
    p0 = robot.capture()
    p1 = robot.capture()
    assert emu.shots == 2 and (p0.index, p1.index) == (0, 1)
    assert p0.image.shape == (48, 64, 3) and p0.image[0, 0, 0] == 37  # shot 1's red
    assert p1.image[0, 0, 0] == 74
    assert p0.odometry[0] == pytest.approx(0.2, abs=0.01) and p0.range_m == pytest.approx(1.8, abs=0.01)
    assert emu.motors[0].power == 0 and not emu.motors[0].running  # shutter port off again


def test_stale_photo_in_the_folder_is_not_taken(robot, emu):
    old = emu.camera_dir / "OLD.png"
    import cv2

    cv2.imwrite(str(old), np.zeros((48, 64, 3), np.uint8))
    os.utime(old, (time.time() - 100, time.time() - 100))
    robot.photos = FolderPhotoSource(emu.camera_dir)
    robot.photos._seen.discard(old)  # as if it had arrived just now, but written long ago
    p = robot.capture()
    assert p.image[0, 0, 0] == 37


def test_opencv_capture_device_source(tmp_path):
    import cv2

    for i in range(3):
        cv2.imwrite(str(tmp_path / f"f_{i:03d}.png"), np.full((10, 12, 3), 10 * i, np.uint8))
    src = OpenCVPhotoSource(str(tmp_path / "f_%03d.png"))
    images = [src.fetch(time.time(), 1.0)[0] for _ in range(3)]
    assert [int(im[0, 0, 0]) for im in images] == [0, 10, 20]
    with pytest.raises(InputError, match="cannot open"):
        OpenCVPhotoSource(str(tmp_path / "none_%03d.png"))


# --- frames equal nxt-python's ---------------------------------------------------
class _RecordingSock:
    """An nxt-python socket that records frames (length header as its Bluetooth backends
    add it) and answers every command with a success reply."""

    def __init__(self):
        self.sent = []

    def send(self, data):
        self.sent.append(struct.pack("<H", len(data)) + data)

    def close(self):
        pass

    def recv(self):
        op = self.sent[-1][3]
        return bytes((2, op, 0)) + bytes(P.REPLY_LENGTH[P.Opcode(op)] - 3)


def nxt_python_frame(frame: bytes) -> bytes:
    """The frame nxt-python sends for the command in `frame` (decoded field by field)."""
    sock = _RecordingSock()
    b, op, a = Brick(sock), frame[3], frame[4:]
    M, S = nxt.motor, nxt.sensor
    if op == P.Opcode.SET_OUTPUT_STATE:
        port, power, mode, reg, turn, run, limit = struct.unpack("<BbBBbBI", a)
        b.set_output_state(M.Port(port), power, M.Mode(mode), M.RegulationMode(reg), turn, M.RunState(run), limit)
    elif op == P.Opcode.SET_INPUT_MODE:
        b.set_input_mode(S.Port(a[0]), S.Type(a[1]), S.Mode(a[2]))
    elif op == P.Opcode.GET_OUTPUT_STATE:
        b.get_output_state(M.Port(a[0]))
    elif op == P.Opcode.GET_INPUT_VALUES:
        b.get_input_values(S.Port(a[0]))
    elif op == P.Opcode.RESET_MOTOR_POSITION:
        b.reset_motor_position(M.Port(a[0]), bool(a[1]))
    elif op == P.Opcode.GET_BATTERY_LEVEL:
        b.get_battery_level()
    elif op == P.Opcode.KEEP_ALIVE:
        b.keep_alive()
    elif op == P.Opcode.LS_WRITE:
        b.ls_write(S.Port(a[0]), a[3:3 + a[1]], a[2])
    elif op == P.Opcode.LS_GET_STATUS:
        b.ls_get_status(S.Port(a[0]))
    elif op == P.Opcode.LS_READ:
        b.ls_read(S.Port(a[0]))
    else:
        raise AssertionError(f"unexpected opcode {op:#x}")
    return sock.sent[0]


def test_every_frame_the_driver_sends_equals_nxt_pythons(robot, emu):
    robot.drive(0.3)
    robot.turn(-0.5)
    robot.compass(), robot.ultrasonic(), robot.bumpers(), robot.battery_mv()
    robot.capture()
    robot.stop()
    frames = list(emu.received)
    assert {f[3] for f in frames} == {int(op) for op in P.Opcode}  # every command was exercised
    for f in frames:
        theirs = nxt_python_frame(f)
        if f[2] == P.TYPE_DIRECT and theirs[2] == P.TYPE_NO_REPLY:
            theirs = theirs[:2] + bytes((P.TYPE_DIRECT,)) + theirs[3:]  # we ask for a confirmation
        assert f == theirs


# --- faults ---------------------------------------------------------------------
def test_garbage_before_a_reply_is_skipped(robot, emu):
    emu.inject_garbage(b"\x07\x00\x02\x0b\xff junk \x02\x00")
    assert robot.battery_mv() == FAST.battery_mv
    assert robot.link.reader.discarded >= 10


def test_dropped_reply_is_retried(robot, emu):
    emu.drop_replies(1)
    n = len(emu.received)
    assert robot.battery_mv() == FAST.battery_mv
    assert len(emu.received) - n == 2  # the command went out twice


def test_error_status_is_reported_and_i2c_errors_retried(robot, emu):
    emu.fail(P.Opcode.GET_BATTERY_LEVEL, 0xC0)
    with pytest.raises(P.NXTStatusError, match="out-of-range") as e:
        robot.battery_mv()
    assert isinstance(e.value, InputError)
    emu.fail(P.Opcode.LS_READ, 0xDD, times=2)  # bus errors: the driver tries again
    assert robot.ultrasonic() == pytest.approx(2.0)
    emu.fail(P.Opcode.LS_WRITE, 0xDD, times=10)
    with pytest.raises(P.NXTError, match="port 4"):
        robot.compass()


@pytest.mark.parametrize("move", ["drive", "turn"])
def test_a_non_finite_command_is_a_clear_error_and_sends_nothing(robot, emu, move):
    sent = len(emu.received)
    with pytest.raises(InputError, match=f"{move} .* must be a finite number"):
        getattr(robot, move)(float("nan"))
    assert len(emu.received) == sent


def test_missing_port_is_a_clear_error(tmp_path):
    with pytest.raises(RobotConnectionError, match="rfcomm9") as e:
        NXTRobot(str(tmp_path / "rfcomm9"), CONFIG, link_config=LINK)
    assert isinstance(e.value, InputError)


def test_a_port_without_an_nxt_is_a_clear_error():
    master, slave = os.openpty()  # a serial line where nobody answers
    try:
        with pytest.raises(RobotConnectionError, match="no NXT answers"):
            NXTRobot(os.ttyname(slave), CONFIG, link_config=LINK)
    finally:
        os.close(master), os.close(slave)


def test_unplugged_mid_drive_is_a_clear_error_and_the_motors_stop(robot, emu):
    emu.unplug_after(14)  # a few polls into the drive
    with pytest.raises(RobotConnectionError, match="lost the connection"):
        robot.drive(1.0)
    # the brick stops the wheels at the tacho limit every motion carries ...
    deadline = time.monotonic() + 3
    while any(m.running for m in emu.motors) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not any(m.running for m in emu.motors)
    assert emu.pose[0] == pytest.approx(1.0, abs=0.02)


def test_reconnects_and_brakes_when_the_port_comes_back(robot, emu):
    emu.unplug_after(14)

    def replug_when_gone():
        while emu.plugged:
            time.sleep(0.005)
        time.sleep(0.05)
        emu.replug()

    threading.Thread(target=replug_when_gone, daemon=True).start()
    r = robot.drive(1.0)
    assert robot.link.reconnects == 1, r
    assert r.odometry_delta[0] == pytest.approx(1.0, abs=0.03), (r, emu.pose)
    assert all(m.power == 0 for m in emu.motors)


def test_motors_stopped_when_the_with_block_raises(emu):
    with pytest.raises(KeyboardInterrupt):
        with NXTRobot(emu.port, CONFIG, link_config=LINK) as r:
            r.brick.set_output_state(1, 50, P.MODE_ON, 0, 0, P.RUN_RUNNING, 0)  # runs forever
            r.brick.set_output_state(2, 50, P.MODE_ON, 0, 0, P.RUN_RUNNING, 0)
            raise KeyboardInterrupt
    assert not any(m.running for m in emu.motors)


def test_motors_stopped_at_interpreter_exit(tmp_path):
    script = textwrap.dedent("""
        import atexit, sys
        emus = []
        # registered before anything of robot.nxt is imported (the driver registers its own
        # handler when imported), so it runs last: after the driver's
        atexit.register(lambda: print("running:", [m.running for m in emus[0].motors]))
        from robot.nxt.emulator import NXTEmulator
        from robot.nxt.driver import NXTRobot
        from robot.nxt import protocol as P
        emu = NXTEmulator()
        emus.append(emu)
        r = NXTRobot(emu.port)
        r.brick.set_output_state(1, 50, P.MODE_ON, 0, 0, P.RUN_RUNNING, 0)
        assert emu.motors[1].running
        sys.exit(3)  # no stop(), no close()
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert out.returncode == 3, out.stderr
    assert "running: [False, False, False]" in out.stdout


def test_keep_alive_is_sent_during_long_missions(emu):
    import dataclasses

    with NXTRobot(emu.port, dataclasses.replace(CONFIG, keep_alive_s=0.0), link_config=LINK) as r:
        n = sum(f[3] == P.Opcode.KEEP_ALIVE for f in emu.received)
        r.drive(0.1)
        r.turn(0.1)
        assert sum(f[3] == P.Opcode.KEEP_ALIVE for f in emu.received) == n + 2
