"""A capture mission on the emulated NXT: every leg's photo, readings and estimate land in
the session, which loads as a Scene."""

import numpy as np

from robot.drive import run_drive
from robot.nxt.driver import LinkConfig, NXTRobot, NXTRobotConfig
from robot.nxt.emulator import EmulatorConfig, NXTEmulator
from robot.photo_source import FolderPhotoSource
from robot.session import CaptureSession, load_session_scene
from robot.waypoint_follower import FollowerConfig


def test_nxt_mission_writes_a_session_that_loads_as_a_scene(tmp_path):
    card = tmp_path / "card"
    card.mkdir()
    start = np.array([-1.0, -1.0, 0.0])
    square = np.array([[0.0, -1.0], [0.0, 0.0], [-1.0, 0.0]])
    emu_config = EmulatorConfig(time_scale=20.0, image_size=(40, 30))
    config = NXTRobotConfig(poll_s=0.005, shutter_pulse_s=0.02, image_size=(40, 30))
    with NXTEmulator(emu_config, camera_dir=card, pose=tuple(start)) as emu, \
            NXTRobot(emu.port, config, FolderPhotoSource(card), LinkConfig(timeout_s=0.3)) as robot, \
            CaptureSession.create(tmp_path / "session", robot.intrinsics, robot.image_size,
                                  robot.cam_from_robot) as session:
        legs = list(run_drive(robot, session, square, start, seed=0,
                                        config=FollowerConfig(max_legs=5)))
        final_true = emu.pose.copy()
    assert len(legs) == 5 and emu.shots == 5
    assert np.hypot(*(legs[-1].leg.estimate[:2] - final_true[:2])) < 0.05  # compass + wheel odometry
    scene = load_session_scene(tmp_path / "session")
    assert len(scene) == 5
    assert [int(v.image[0, 0, 0]) for v in scene.views] == [(37 * i) % 256 for i in range(1, 6)]
    cam = scene.views[-1].camera
    assert np.allclose(cam.center[:2], legs[-1].leg.estimate[:2] + 0.05 * np.array(
        [np.cos(legs[-1].leg.estimate[2]), np.sin(legs[-1].leg.estimate[2])]))
    kinds = [r["kind"] for r in CaptureSession.open(tmp_path / "session").records]
    assert kinds[0] == "start" and kinds.count("commit") == kinds.count("photo") == 5


def test_drive_drives_the_emulated_nxt_into_a_session(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    ibrnav = str(Path(sys.executable).parent / "ibrnav")
    run = subprocess.run([ibrnav, "drive", "--robot", "nxt:emulator", "--max-legs", "3", "--width", "32",
                          "--height", "24", "--session", str(tmp_path / "s"), "--save", str(tmp_path / "d.rrd")],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "3 photos" in run.stdout
    assert len(load_session_scene(tmp_path / "s")) == 3
    bad = subprocess.run([ibrnav, "drive", "--robot", "nxt:" + str(tmp_path / "rfcomm0"), "--photo-dir", str(tmp_path),
                          "--save", str(tmp_path / "e.rrd")], capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "rfcomm0" in bad.stderr and "Traceback" not in bad.stderr
