"""A simulated capture mission (`ibrnav drive --session`) killed mid-write and resumed ends
with exactly the photos and log records of an uninterrupted run with the same seed."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from robot.drive import run_drive
from robot.session import KILL_ENV, CaptureSession
from robot.sim_robot import SimRobot, SimRobotConfig
from robot.waypoint_follower import FollowerConfig

BIN = Path(sys.executable).parent
DEMO = ["drive", "--seed", "3", "--max-legs", "4", "--width", "32", "--height", "24"]


def demo(session: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / "ibrnav"), *DEMO, "--session", str(session),
                           "--save", str(session.parent / f"{session.name}.rrd")],
                          capture_output=True, text=True, timeout=300, env=env)


def contents(session: Path) -> tuple[bytes, dict]:
    photos = {p.name: p.read_bytes() for p in sorted((session / "photos").iterdir())}
    return (session / "log.jsonl").read_bytes(), photos


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted run of the same mission."""
    folder = tmp_path_factory.mktemp("ref") / "ref"
    ref = demo(folder)
    assert ref.returncode == 0, ref.stderr
    return contents(folder)


def assert_resumes_to(reference, session: Path) -> subprocess.CompletedProcess:
    resumed = demo(session)
    assert resumed.returncode == 0, resumed.stderr
    log_ref, photos_ref = reference
    log_run, photos_run = contents(session)
    assert len(photos_run) == len(photos_ref) == 4
    assert len(log_run.splitlines()) == len(log_ref.splitlines()) == 1 + 5 * 4
    assert log_run == log_ref and photos_run == photos_ref  # nothing lost, nothing twice
    return resumed


def test_killed_mid_write_mission_resumes_to_the_uninterrupted_result(tmp_path, reference):
    # records: 0 start, then 5 per leg (motion, sensors, photo, estimate, commit): 9 is
    # leg 1's estimate, killed half-written after its photo was stored and logged
    killed = demo(tmp_path / "run", env=dict(os.environ, **{KILL_ENV: "9:log"}))
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    assert len(list((tmp_path / "run" / "photos").iterdir())) == 2  # legs 0 and 1's photos
    resumed = assert_resumes_to(reference, tmp_path / "run")
    assert "resuming" in resumed.stdout and "after leg 1 (1 photos kept" in resumed.stdout
    again = demo(tmp_path / "run")  # a finished mission stays finished
    assert again.returncode == 0 and "already finished" in again.stdout
    assert contents(tmp_path / "run") == reference


def test_mission_killed_from_outside_resumes_to_the_uninterrupted_result(tmp_path, reference):
    session = tmp_path / "run"
    proc = subprocess.Popen([str(BIN / "ibrnav"), *DEMO, "--session", str(session), "--save",
                             str(tmp_path / "run.rrd")], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    photo = session / "photos" / "photo_00001.png"
    while not photo.exists() and proc.poll() is None:
        time.sleep(0.002)
    proc.send_signal(signal.SIGKILL)  # wherever it is: inside leg 1's records, or just after
    assert proc.wait(timeout=60) == -signal.SIGKILL
    assert_resumes_to(reference, session)


def test_stopping_between_legs_and_resuming_in_process_is_seamless(tmp_path, office):
    start = np.array([-1.5, -2.5, 0.0])
    route = np.array([[1.5, -2.5], [1.5, 2.5]])

    def run(folder, stop_after=None):
        robot = SimRobot(office, SimRobotConfig(image_size=(24, 16)), np.random.default_rng(5), start_pose=start)
        with CaptureSession.open_or_create(folder, robot.intrinsics, robot.image_size, robot.cam_from_robot,
                                           rollback=True) as s:
            for i, leg in enumerate(run_drive(robot, s, route, start, 5, FollowerConfig(max_legs=5))):
                if stop_after is not None and i + 1 == stop_after:
                    break
        return robot

    a = run(tmp_path / "a")
    run(tmp_path / "b", stop_after=2)
    b = run(tmp_path / "b")
    assert contents(tmp_path / "a") == contents(tmp_path / "b")
    assert np.array_equal(a.true_pose, b.true_pose)  # the simulator state was restored too
