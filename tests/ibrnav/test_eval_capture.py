"""`ibrnav eval-capture SESSION`: a session whose final model is the world's own photos at
the evaluation poses over the true mesh renders those views back (the command measures what
it claims); the world comes from the session's meta or --world; a session without a final
model or without a world is one error naming the folder."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from ibr.errors import InputError
from robot.protocol import Photo, robot_camera
from robot.session import CaptureSession

SIZE = (96, 72)
POSES, SEED = 4, 1  # eval-capture --poses 4 in a session of seed 0: poses seeded by 0 + 1


def _make_session(folder, world, poses, meta: dict, model: bool, model_shift_m: float = 0.0):
    """A session of the true photos at `poses` (the robot's camera), logged at their true
    poses (`evaluation` records, as a simulated mission logs them); with `model`, a final
    model of them over the world's true mesh, each camera moved `model_shift_m` along x."""
    from robot.sim_robot import SimRobot, SimRobotConfig

    robot = SimRobot(world, SimRobotConfig(image_size=SIZE), np.random.default_rng(0), start_pose=tuple(poses[0]))
    cams = [robot_camera(p, robot.intrinsics, SIZE, robot.cam_from_robot, name=f"photo_{i:05d}")
            for i, p in enumerate(poses)]
    with CaptureSession.create(folder, robot.intrinsics, SIZE, robot.cam_from_robot, meta) as s:
        for i, (pose, cam) in enumerate(zip(poses, cams)):
            s.add_photo(Photo(world.photograph(cam), float(i), pose, pose[2], 1.0, i), pose=pose)
            s.append("evaluation", true_pose=pose)
        if model:
            pts = world.mesh.sample(300, return_index=False)
            moved = [robot_camera(p + [model_shift_m, 0, 0], robot.intrinsics, SIZE, robot.cam_from_robot, name=c.name)
                     for p, c in zip(poses, cams)]
            s.write_model(moved, world.mesh, pts, np.full((len(pts), 3), 200, np.uint8))
    return folder


@pytest.fixture(scope="module")
def session(tmp_path_factory, office, gl_ctx):
    """A finished demo-like session in the office (seed 0): photos at eval-capture's poses,
    which its model puts 0.1 m off (a mission's localisation error)."""
    from robot.mission.evaluation import evaluation_poses

    poses = evaluation_poses(office, POSES, np.random.default_rng(SEED))
    meta = {"command": "demo", "world": "office", "seed": 0, "robot": "sim"}
    return _make_session(tmp_path_factory.mktemp("evalcap") / "session", office, poses, meta, model=True,
                         model_shift_m=0.1)


def evaluate(session, out, *flags) -> dict:
    """`ibrnav eval-capture SESSION --poses POSES --scale 1 FLAGS --json OUT`'s report."""
    from ibrnav.cli import build_parser

    args = build_parser().parse_args(["eval-capture", str(session), "--poses", str(POSES), "--scale", "1",
                                      "--json", str(out), *map(str, flags)])
    assert args.func(args) == 0
    return json.loads(out.read_text())


def test_true_photos_at_the_query_poses_render_back(session, tmp_path):
    """With the true poses (--truth poses) the photos are the query views: near perfect;
    the model's poses, 0.1 m off, show as a clearly lower PSNR."""
    from ibrnav.recording import recording_scalars

    rrd = tmp_path / "eval.rrd"
    r = evaluate(session, tmp_path / "eval.json", "--method", "ulr-pixel", "--truth", "poses", "--save", rrd)
    assert r["world"] == "synthetic:office?seed=0" and r["seed"] == SEED and r["poses"] == POSES == len(r["views"])
    assert r["photos"] == POSES and r["size"] == list(SIZE)
    assert r["covered"]["worst_decile"] > 0.95 and r["psnr_db"]["worst_decile"] > 30 and r["ssim"]["mean"] > 0.9
    assert all(v["psnr_db"] > 30 for v in r["views"])
    plots = recording_scalars(rrd)
    assert plots["plots/eval/covered"].notna().sum() == POSES
    off = evaluate(session, tmp_path / "off.json", "--method", "ulr-pixel", "--save", tmp_path / "off.rrd")
    assert off["truth"] == [] and off["psnr_db"]["mean"] < r["psnr_db"]["mean"] - 10


def test_model_folder_and_world_override(session, tmp_path):
    """The model/ folder names its session; --world replaces the recorded world: the same
    photos judged against another office seed (other textures) score far lower."""
    r = evaluate(session / "model", tmp_path / "other.json", "--seed", SEED, "--truth", "poses", "mesh",
                 "--world", "synthetic:office?seed=5", "--save", tmp_path / "other.rrd")
    assert r["world"] == "synthetic:office?seed=5" and r["session"] == str(session)
    assert r["psnr_db"]["mean"] < 20


def test_a_session_without_a_model_or_a_world_is_one_error_naming_it(session, tmp_path, office, ibrnav_command):
    killed = _make_session(tmp_path / "killed", office, np.array([[0.0, -2.0, 0.0]]), {"world": "office"},
                           model=False)
    with pytest.raises(InputError, match=f"{killed}: the session has no final model"):
        ibrnav_command("eval-capture", killed)
    nameless = tmp_path / "nameless"
    shutil.copytree(session, nameless)
    info = json.loads((nameless / "session.json").read_text())
    (nameless / "session.json").write_text(json.dumps({**info, "meta": {"command": "demo"}}))
    with pytest.raises(InputError, match=f"{nameless}: the session does not record the synthetic world"):
        ibrnav_command("eval-capture", nameless)
    with pytest.raises(InputError, match="not a capture session"):
        ibrnav_command("eval-capture", tmp_path)
