"""How far a shared error of a fix's map points moves it (`robot.mission.fix_precision`)."""

from types import SimpleNamespace

import numpy as np
from scipy.optimize import least_squares

from localization.pose_views import robot_camera
from robot.mission.adaptive import PRECISE_SEEDS_M_PER_PX, AdaptiveConfig, AdaptiveMission
from robot.mission.fix_precision import bias_sensitivity
from robot.sim_robot import SimRobotConfig, forward_camera_mount

K = np.array([[277.0, 0, 160], [0, 277.0, 120], [0, 0, 1]])
SIZE = (320, 240)
MOUNT = forward_camera_mount(SimRobotConfig().camera_height_m, tilt_down_rad=SimRobotConfig().camera_tilt_rad)
POSE = np.array([0.5, -1.0, 0.3])


def points_ahead(distance_m, half_width_m, n=40, seed=0):
    """`n` points (N, 3) on a wall `distance_m` ahead of the robot at POSE, `half_width_m`
    either side of its view and 0-1 m up: what a fix's inliers look like."""
    rng = np.random.default_rng(seed)
    ahead = np.array([np.cos(POSE[2]), np.sin(POSE[2]), 0.0])
    side = np.array([-np.sin(POSE[2]), np.cos(POSE[2]), 0.0])
    return (np.r_[POSE[:2], 0.0] + distance_m * ahead + rng.uniform(-1, 1, (n, 1)) * half_width_m * side
            + rng.uniform(0.0, 1.0, (n, 1)) * np.array([0, 0, 1.0]))


def pixels(pose, xyz):
    """(2N,) the pixels of `xyz` (N, 3) in the camera of the robot at `pose` (3,), flattened."""
    return robot_camera(pose, K, SIZE, MOUNT).project(xyz)[0].ravel()


def refit(xyz, uv):
    """The robot pose (3,) whose camera best fits the pixels `uv` (2N,) of `xyz` (least squares)."""
    def residual(p):
        return pixels(p, xyz) - uv
    return least_squares(residual, POSE, x_scale=[0.1, 0.1, 0.01], xtol=1e-12, ftol=1e-12).x


def test_a_shared_pixel_of_error_moves_the_fix_by_the_sensitivity_at_most():
    """Pixels moved by an error of 1 px RMS per point, in the pattern that moves the pose most,
    move the least-squares pose by the sensitivity (within a few per cent: the model is
    linearised); random errors of 1 px at every point move it by less."""
    xyz = points_ahead(3.0, 1.0)
    s = bias_sensitivity(robot_camera(POSE, K, SIZE, MOUNT), xyz, MOUNT)
    uv = pixels(POSE, xyz)
    J = np.array([(pixels(POSE + d, xyz) - uv) / 1e-5 for d in np.eye(3) * 1e-5]).T
    # the pixel error of RMS 1 px per point that moves the (x, y) fix most: J (J^T J)^-1 along
    # the top eigenvector of the (x, y) block of (J^T J)^-1
    cov = np.linalg.inv(J.T @ J)
    delta = J @ cov @ np.r_[np.linalg.eigh(cov[:2, :2])[1][:, -1], 0.0]
    delta *= np.sqrt(len(xyz)) / np.linalg.norm(delta)
    moved = np.hypot(*(refit(xyz, uv + delta)[:2] - POSE[:2]))
    assert abs(moved - s) < 0.05 * s
    rng = np.random.default_rng(1)
    for _ in range(5):
        noise = rng.normal(size=(len(xyz), 2))
        noise /= np.linalg.norm(noise, axis=1, keepdims=True)  # 1 px at every point, any direction
        assert np.hypot(*(refit(xyz, uv + noise.ravel())[:2] - POSE[:2])) <= 1.001 * s


def test_far_points_in_a_narrow_patch_hold_a_fix_less_than_near_spread_ones():
    """Near points spread over the view pin the robot to a few cm per pixel, below the gate
    (`PRECISE_SEEDS_M_PER_PX`, `explore --precise-seeds`); the same number of points 6 m away in a narrower
    patch leave it free by metres along the view. One point fixes nothing."""
    cam = robot_camera(POSE, K, SIZE, MOUNT)
    gate = PRECISE_SEEDS_M_PER_PX
    near = bias_sensitivity(cam, points_ahead(1.0, 0.5), MOUNT)
    wider = bias_sensitivity(cam, points_ahead(6.0, 2.0), MOUNT)
    far = bias_sensitivity(cam, points_ahead(6.0, 0.3), MOUNT)
    assert near < 0.5 * gate and gate < wider < far and far > 1.0
    assert bias_sensitivity(cam, points_ahead(3.0, 1.0)[:1], MOUNT) == np.inf


def test_a_weak_fix_is_counted_and_poses_no_photo():
    """`AdaptiveMission._precise` with `--precise-seeds`: a fix on near points spread over the
    view may pose its photo; one on a far, narrow patch may not, and is counted in
    `weak_fixes`. Without it (the default), every fix may."""
    robot = SimpleNamespace(cam_from_robot=MOUNT)
    cam = robot_camera(POSE, K, SIZE, MOUNT)
    far = SimpleNamespace(cam_from_world=cam.cam_from_world, camera=cam, inlier_xyz=points_ahead(6.0, 0.3))
    default = SimpleNamespace(robot=robot, config=AdaptiveConfig(), weak_fixes=0)
    assert AdaptiveMission._precise(default, far) and default.weak_fixes == 0
    mission = SimpleNamespace(robot=robot, config=AdaptiveConfig(max_seed_m_per_px=PRECISE_SEEDS_M_PER_PX),
                              weak_fixes=0)

    def fix(xyz):
        return SimpleNamespace(cam_from_world=cam.cam_from_world, camera=cam, inlier_xyz=xyz)
    assert AdaptiveMission._precise(mission, fix(points_ahead(1.0, 0.5)))
    assert mission.weak_fixes == 0
    assert not AdaptiveMission._precise(mission, far)
    assert mission.weak_fixes == 1
