"""`ibrnav demo --session DIR` resumes a killed mission from its capture session: nothing
lost, nothing duplicated. The random stage is deterministic given the seed (a
resumed run replays it to the same records and photos); the adaptive stage after a resume
is not bit-identical to an uninterrupted run (COLMAP's SfM is not bit-reproducible), so
the end-to-end test checks the plan: the photo budget, one record set per photo, one commit
per step, a folder that loads as a Scene."""

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np

from robot.mission.mission import run_random_stage
from robot.mission.observer import MissionObserver
from robot.mission.journal import SessionJournal
from robot.mission.random_stage import RandomExplorationConfig
from robot.session import KILL_ENV, CaptureSession, load_session_scene
from robot.sim_robot import SimRobot, SimRobotConfig

BIN = Path(sys.executable).parent
DEMO = ["demo", "--world", "office", "--random-photos", "36", "--circle-step-deg", "20", "--photos", "40", "--width", "240",
        "--height", "180", "--max-rounds", "4", "--goals-per-round", "2", "--tour-frames", "0", "--sweep-frontiers"]


def demo(session: Path, kill_at: str | None = None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != KILL_ENV}
    if kill_at:
        env[KILL_ENV] = kill_at
    return subprocess.run([str(BIN / "ibrnav"), *DEMO, "--session", str(session), "--save",
                           str(session.parent / "demo.rrd")], capture_output=True, text=True, timeout=300, env=env,
                          check=False)


def test_demo_killed_twice_resumes_to_the_planned_capture(tmp_path):
    folder = tmp_path / "capture"
    # records: 0 start, then 4 per random photo (photo, evaluation, estimate, commit):
    # 42 is photo 10's estimate, killed half-written after its photo was stored and logged
    killed = demo(folder, "42:log")
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    assert len(list((folder / "photos").iterdir())) == 11
    # resumed (the random stage replayed and checked), then killed inside adaptive round 1
    killed = demo(folder, "157:log")
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    assert "resuming the mission" in killed.stdout and "10 photos" in killed.stdout  # photo 10 rolled back
    done = demo(folder)
    assert done.returncode == 0, done.stderr
    assert "resumed after adaptive round 0" in done.stderr
    captured = int(re.search(r"captured (\d+) photos", done.stdout).group(1))
    # the photo budget is reached unless the rounds ran out first: on this 36-photo, 240 x 180 map
    # the filter can lose the robot, goals are given up and round 4 ends with 38 photos (1 run in 14)
    assert captured == 40 or "adaptive stage stopped: budget (4 rounds)" in done.stderr, done.stderr[-2000:]
    log = [json.loads(line) for line in (folder / "log.jsonl").read_text().splitlines()]
    assert [r["seq"] for r in log] == list(range(len(log)))
    photos = [r for r in log if r["kind"] == "photo"]
    files = sorted(p.name for p in (folder / "photos").iterdir())
    assert files == [f"photo_{i:05d}.png" for i in range(len(photos))]  # every photo once, none missing
    assert [r["index"] for r in photos] == list(range(len(photos)))
    assert [r["robot_index"] for r in photos] == list(range(len(photos)))  # the robot's counter restored
    assert sum(r["stage"] == "random" for r in photos) == 36
    assert all(isinstance(r["fixed"], bool) == (r["stage"] != "random") for r in photos)  # fixed by vision or not
    assert sum(r["stage"] != "localise" for r in photos) == captured <= 40  # the photo budget, not more
    for i, r in enumerate(log):  # each photo's records once: photo, evaluation, estimate
        if r["kind"] == "photo":
            assert [log[i + 1]["kind"], log[i + 2]["kind"]] == ["evaluation", "estimate"]
    stages = [r["state"]["stage"] for r in log if r["kind"] == "commit"]
    assert stages[:36] == ["random"] * 36 and stages[-1] == "finished"
    adaptive = [r["state"] for r in log if r["kind"] == "commit" and r["state"]["stage"] == "adaptive"]
    rounds = [s["rounds"] for s in adaptive]
    assert rounds == list(range(len(rounds))) and len(rounds) >= 2  # each round once (more when goals are given up)
    assert all(sum(s["failure_reasons"].values()) == s["failed"] for s in adaptive)  # by reason, across resumes
    met = [sum(s["obstacles_met"].values()) for s in adaptive]
    assert met == sorted(met)  # counted on across the resumes, never from 0 again
    assert len(load_session_scene(folder).views) == len(photos)
    again = demo(folder)
    assert again.returncode == 0 and "already finished" in again.stdout
    assert (folder / "log.jsonl").read_text().count("\n") == len(log)


class Stop(Exception):
    pass


class StopAfter(MissionObserver):
    def __init__(self, n):
        self.n, self.seen = n, 0

    def estimate(self, pose, source):
        self.seen += 1
        if self.seen == self.n:
            raise Stop


def random_stage_into(folder: Path, robot: SimRobot, stop_after: int, replayable: bool) -> tuple | None:
    """The random stage (30 photos from the office start) into the capture session at
    `folder`, each photo written as taken; stopped after `stop_after` observer calls (0:
    never). Returns `_random_stage`'s (photos, body), or None when it was stopped."""
    start = np.array([-1.5, -2.5, 0.0])
    cfg = RandomExplorationConfig(circle_step_rad=np.radians(30))
    with CaptureSession.open_or_create(folder, robot.intrinsics, robot.image_size, robot.cam_from_robot,
                                       rollback=True) as s:

        class Write(StopAfter):
            def photo(self, mp):
                s.add_photo(mp.photo, pose=mp.estimate, stage=mp.stage)

        try:
            return run_random_stage(robot, start, 30, cfg, np.random.default_rng(9), Write(stop_after),
                                 SessionJournal(s, robot, replayable=replayable))
        except Stop:
            return None


def office_robot(office) -> SimRobot:
    return SimRobot(office, SimRobotConfig(image_size=(32, 24)), np.random.default_rng(4), start_pose=(-1.5, -2.5, 0.0))


def test_random_stage_resumes_to_the_records_and_photos_of_an_uninterrupted_run(tmp_path, office):
    a = office_robot(office)
    random_stage_into(tmp_path / "a", a, 0, replayable=True)
    # stopped inside photo 16's records (before its commit)
    random_stage_into(tmp_path / "b", office_robot(office), 17, replayable=True)
    assert len(CaptureSession.open(tmp_path / "b", rollback=True).photos) == 16
    b = office_robot(office)
    random_stage_into(tmp_path / "b", b, 0, replayable=True)
    assert (tmp_path / "a" / "log.jsonl").read_bytes() == (tmp_path / "b" / "log.jsonl").read_bytes()
    for p in (tmp_path / "a" / "photos").iterdir():
        assert p.read_bytes() == (tmp_path / "b" / "photos" / p.name).read_bytes()
    assert len(list((tmp_path / "b" / "photos").iterdir())) == 30
    assert np.array_equal(a.true_pose, b.true_pose)


def test_a_real_robot_takes_the_remaining_random_photos_from_where_it_is(tmp_path, office):
    """No replay without a simulator: the stage goes on from the last logged estimate."""
    robot = office_robot(office)
    folder = tmp_path / "real"
    assert random_stage_into(folder, robot, 17, replayable=False) is None
    photos, body = random_stage_into(folder, robot, 0, replayable=False)
    records = CaptureSession.open(folder).records
    assert len(photos) == 30 and [r["index"] for r in records if r["kind"] == "photo"] == list(range(30))
    assert [r["kind"] for r in records] == ["photo", "commit"] * 30
    # photo 16 was rolled back and taken again after the robot had already photographed it once
    assert [r["robot_index"] for r in records if r["kind"] == "photo"][16] == 17
    assert body.path_m >= records[31]["state"]["path_m"] > 0  # the odometer goes on from the commit
