"""Surface coverage against known answers: a wall, cameras in front of it, an occluder."""

import numpy as np
import pytest
import trimesh

from ibr.camera import Camera, intrinsics_from_fov
from robot.mission.coverage import CoverageConfig, CoverageTracker, coverage_curve, path_length

K = intrinsics_from_fov(90.0, 64, 64)


def wall() -> trimesh.Trimesh:
    """A 2 x 2 m wall in the plane y = 2 facing -y (towards the cameras at y = 0)."""
    v = np.array([[-1, 2, -1], [1, 2, -1], [1, 2, 1], [-1, 2, 1.0]])
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)


def cam_at(x: float) -> Camera:
    return Camera.look_at([x, 0, 0], [x, 2, 0], K, 64, 64)


def test_one_photo_covers_nothing_and_two_apart_cover_the_shared_view():
    cfg = CoverageConfig(n_samples=2000, min_angle_deg=5.0, max_range_m=10)
    curve = coverage_curve(wall(), [cam_at(0.0), cam_at(0.5)], cfg)
    assert curve[0] == 0.0
    # both 90-degree cameras at 2 m see x in [x_c - 2, x_c + 2]: the whole 2 m wall; every
    # sample is >= 2 * atan(0.25 / 2.3) ~ 12 degrees apart (> 5) from the two centres
    assert curve[1] == pytest.approx(1.0)


def test_close_cameras_do_not_make_a_pair():
    cfg = CoverageConfig(n_samples=2000, min_angle_deg=5.0, max_range_m=10)
    # 5 cm apart at 2 m: at most ~1.4 degrees between the sightings
    assert coverage_curve(wall(), [cam_at(0.0), cam_at(0.05)], cfg)[-1] == 0.0


def test_range_and_occlusion_hide_samples():
    far = CoverageConfig(n_samples=2000, max_range_m=1.5)
    assert coverage_curve(wall(), [cam_at(0.0), cam_at(0.5)], far)[-1] == 0.0
    # a blocker at y = 1 covering x < 0 for both cameras hides part of the wall
    b = trimesh.creation.box(extents=[4, 0.1, 4], transform=trimesh.transformations.translation_matrix([-2, 1, 0]))
    scene = trimesh.util.concatenate([wall(), b])
    tracker = CoverageTracker(scene, CoverageConfig(n_samples=4000, max_range_m=10))
    tracker.add(cam_at(0.2))
    tracker.add(cam_at(0.7))
    on_wall = np.isclose(tracker.samples.points[:, 1], 2.0)
    x = tracker.samples.points[:, 0]
    # the camera at x = 0.2 sees past the blocker's edge (x = 0, y = 1) only wall points
    # with x > -0.2; the one at 0.7 those with x > -0.7: covered needs both
    assert (tracker.covered & on_wall & (x > -0.15)).sum() > 0.9 * (on_wall & (x > -0.15)).sum()
    assert not (tracker.covered & on_wall & (x < -0.25)).any()


def test_path_length():
    assert path_length(np.array([[0, 0, 0], [3, 4, 1], [3, 0, 0.0]])) == pytest.approx(9.0)


def test_eval_capture_of_the_true_photos_is_near_perfect():
    """eval-capture measures what it claims: the world's own photos at the query poses over
    its true mesh render the query views back (high PSNR and SSIM, all covered), while
    photos from elsewhere over the same mesh do much worse."""
    import shapely

    from explore.candidates import sample_candidates
    from ibr.synthetic import make_world
    from robot.mission.evaluation import eval_capture
    from robot.protocol import robot_camera
    from robot.sim_robot import SimRobot, SimRobotConfig

    world = make_world("office", 0)
    rng = np.random.default_rng(0)
    robot = SimRobot(world, SimRobotConfig(image_size=(96, 72)), rng, start_pose=tuple(world.start_pose(rng)))
    poses = sample_candidates(world.free_space, 6, np.random.default_rng(7), 0.15)
    cams = [robot_camera(p, robot.intrinsics, robot.image_size, robot.cam_from_robot) for p in poses]
    images = [world.photograph(c) for c in cams]
    args = (robot.intrinsics, robot.image_size, robot.cam_from_robot)
    good = eval_capture(world, cams, images, world.mesh, 6, np.random.default_rng(7), *args)
    assert good["poses"] == 6 and good["covered"]["worst_decile"] > 0.95
    assert good["psnr_db"]["worst_decile"] > 30 and good["ssim"]["mean"] > 0.9
    other = eval_capture(world, cams[:2], images[:2], world.mesh, 6, np.random.default_rng(8), *args)
    assert other["psnr_db"]["mean"] < good["psnr_db"]["mean"] - 5
    assert shapely.contains_xy(world.free_space, poses[:, 0], poses[:, 1]).all()


def test_achievable_coverage_bounds_any_capture():
    """The dense capture of the whole free space covers at least what a loop of photos does,
    and most of the office (whose free space reaches every wall)."""
    from ibr.synthetic import loop_route, make_world
    from robot.mission.coverage import CoverageConfig, achievable_coverage, coverage_curve
    from robot.protocol import robot_camera
    from robot.sim_robot import SimRobot, SimRobotConfig

    world = make_world("office", 0)
    robot = SimRobot(world, SimRobotConfig(image_size=(96, 72)), np.random.default_rng(0),
                     start_pose=(*loop_route(world)[0], 0.0))
    cfg = CoverageConfig(n_samples=2000)
    at = lambda poses: [robot_camera(p, robot.intrinsics, robot.image_size, robot.cam_from_robot)  # noqa: E731
                        for p in poses]
    best = achievable_coverage(world.mesh, world.free_space, at, n_poses=400, config=cfg)
    loop = loop_route(world)
    heads = np.arctan2(*np.diff(np.vstack([loop, loop[:1]]), axis=0).T[::-1])
    some = coverage_curve(world.mesh, at(np.c_[loop, heads]), cfg)[-1]
    assert best >= some and best > 0.6
