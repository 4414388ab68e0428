import dataclasses

import numpy as np
import pytest

from ibr.errors import InputError
from localization.motion_models import apply_odometry, odometry_decomposition, wrap_angle
from robot.protocol import Robot
from robot.sim_robot import SimRobot, SimRobotConfig

START = (-1.5, -2.5, 0.0)  # a corner of the office's clear loop


def drive_square(robot):
    for _ in range(4):
        robot.drive(2.0)
        robot.turn(np.pi / 2)


def odometry_error(office, alphas, seed):
    robot = SimRobot(office, dataclasses.replace(SimRobotConfig(), alphas=alphas),
                     np.random.default_rng(seed), start_pose=START)
    drive_square(robot)
    in_world = apply_odometry(np.array(START), odometry_decomposition(np.zeros(3), robot.odometry()))[0]
    return np.hypot(*(in_world[:2] - robot.true_pose[:2])), abs(wrap_angle(in_world[2] - robot.true_pose[2]))


def test_odometry_error_grows_with_alphas(office):
    levels = [(0.0, 0.0, 0.0, 0.0), (0.01, 0.001, 0.01, 0.001), (0.1, 0.01, 0.1, 0.01)]
    errors = np.array([[odometry_error(office, a, s) for s in range(20)] for a in levels])
    mean_pos, mean_rot = errors[..., 0].mean(axis=1), errors[..., 1].mean(axis=1)
    assert mean_pos[0] < 1e-9 and mean_rot[0] < 1e-9  # noiseless odometry is exact
    assert mean_pos[0] < mean_pos[1] < mean_pos[2]
    assert mean_rot[0] < mean_rot[1] < mean_rot[2]


def test_front_bumper_fires_against_a_wall(office):
    robot = SimRobot(office, rng=np.random.default_rng(0), start_pose=(-1.5, -2.5, np.pi))  # facing -x wall
    result = robot.drive(5.0)
    assert result.bumper_front and not result.bumper_rear and not result.stalled
    assert robot.bumpers() == (True, False)
    assert robot.true_pose[0] == pytest.approx(-3.0 + robot.config.radius_m, abs=0.02)


def test_rear_bumper_fires_reversing_into_a_wall(office):
    robot = SimRobot(office, rng=np.random.default_rng(0), start_pose=(-1.5, -2.5, 0.0))
    result = robot.drive(-5.0)
    assert result.bumper_rear and not result.bumper_front
    assert robot.true_pose[0] == pytest.approx(-3.0 + robot.config.radius_m, abs=0.02)


def test_side_contact_stalls_without_a_bumper(office):
    # heading 75 deg away from the wall normal: the wall meets the robot's side
    robot = SimRobot(office, rng=np.random.default_rng(0), start_pose=(-2.5, -2.5, np.pi - np.radians(75)))
    result = robot.drive(5.0)
    assert result.stalled and not (result.bumper_front or result.bumper_rear)


def test_ultrasonic_measures_the_wall(office):
    cfg = dataclasses.replace(SimRobotConfig(), ultrasonic_sigma_m=0.0)
    robot = SimRobot(office, cfg, np.random.default_rng(0), start_pose=(-1.5, -2.5, np.pi))
    assert robot.ultrasonic() == pytest.approx(1.5, abs=0.01)
    far = SimRobot(office, cfg, np.random.default_rng(0), start_pose=(0.0, -2.5, 0.0))
    assert far.ultrasonic() == cfg.ultrasonic_max_m  # 3 m to the +x wall: out of range


def test_capture_keeps_truth_apart(office, gl_ctx):
    robot = SimRobot(office, dataclasses.replace(SimRobotConfig(), image_size=(80, 60)),
                     np.random.default_rng(0), gl_ctx, start_pose=START)
    assert isinstance(robot, Robot)
    robot.drive(0.5)
    photo = robot.capture()
    assert photo.image.shape == (60, 80, 3) and photo.index == 0
    assert not hasattr(photo, "pose")
    assert robot.truth[0]["index"] == 0
    np.testing.assert_allclose(robot.truth[0]["pose"], [-1.0, -2.5, 0.0], atol=0.02)


@pytest.mark.parametrize("move", ["drive", "turn"])
def test_a_non_finite_command_is_rejected_and_the_pose_kept(office, move):
    robot = SimRobot(office, start_pose=START)
    with pytest.raises(InputError, match=f"{move} .* must be a finite number"):
        getattr(robot, move)(float("nan"))
    assert np.allclose(robot.true_pose, START)


def test_start_outside_free_space_is_rejected(office):
    with pytest.raises(InputError, match="not in the free space"):
        SimRobot(office, start_pose=(0.0, 0.0, 0.0))  # on the table
