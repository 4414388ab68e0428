"""The panoramic search: a level camera's photo against cylindrical panoramas of the map,
every position of a grid and every heading at once."""

import numpy as np
import pytest
import shapely

from ibr.camera import Camera
from localization.level_view_likelihood import LevelViewLikelihood
from localization.motion_models import wrap_angle
from localization.render_likelihood import likelihood_renderer
from localization.view_search import Cylinder, PanoramaIndex, grid_positions
from robot.sim_robot import SimRobot, SimRobotConfig


def test_grid_positions_lie_in_the_free_space():
    free = shapely.box(0, 0, 2, 1).difference(shapely.box(0.9, 0, 1.1, 0.6))
    xy = grid_positions(free, 0.1)
    assert len(xy) == 200 - 12 and shapely.contains_xy(free, xy[:, 0], xy[:, 1]).all()


def test_a_thin_free_corridor_off_the_grid_centres_still_gets_positions_along_it():
    """Squares that the free space only partly overlaps get a position in their free part:
    every point of a diagonal corridor narrower than the spacing is within a square's
    diagonal of one (with centres alone, most of it had none)."""
    corridor = shapely.LineString([(0, 0), (5, 3.3)]).buffer(0.12)
    xy = grid_positions(corridor, 0.5)
    assert shapely.contains_xy(corridor, xy[:, 0], xy[:, 1]).all()
    along = np.array([[t * 5, t * 3.3] for t in np.linspace(0, 1, 50)])
    nearest = np.hypot(*(along[:, None] - xy[None]).transpose(2, 0, 1)).min(axis=1)
    assert nearest.max() < 0.5 * np.sqrt(2)


def test_the_cylinder_keeps_every_ray_inside_the_pinhole_image():
    cyl = Cylinder(f=27.7, cx=15.5, cy=11.5, width=32, height=24)
    u, v = cyl.maps(np.array([-cyl.half_fov, 0.0, cyl.half_fov]))
    assert u.min() >= -0.5 - 1e-3 and u.max() <= 31.5 + 1e-3
    assert v.min() >= -0.5 and v.max() <= 23.5
    assert cyl.n_cols % 8 == 0 and cyl.step == pytest.approx(2 * np.pi / cyl.n_cols)


def test_the_search_scores_the_photo_as_the_views_do_and_ranks_the_truth_first(gl_ctx, office):
    """At the grid cell of the true pose the panorama's score equals the perspective
    view's NCC (the cylinder's geometry and heading convention are right), and over all
    positions and headings of the office the truth's cell is among the best few."""
    robot = SimRobot(office, SimRobotConfig(), np.random.default_rng(0), gl_ctx, (0.0, -2.5, 0.0))
    lik = LevelViewLikelihood(likelihood_renderer(office.mesh, gl_ctx, office.background), office.light,
                              Camera(robot.intrinsics, *robot.image_size), robot.cam_from_robot)
    index = PanoramaIndex(lik, robot.free, 0.25)
    C, step = index.cyl.n_cols, index.cyl.step
    for k in range(3):
        p, c = k * 37 % len(index.positions), (k * 53) % C
        truth = index.robot_poses(index.positions[p][None], np.array([-c * step]))[0]
        robot.kidnap(truth)
        photo = robot.capture().image
        v = index.scores(photo)
        lik.set_observation(photo, index.size)
        assert v[p, c] == pytest.approx(lik.ncc(truth[None], index.size)[0], abs=0.05)
        assert (v > v[p, c]).sum() < 10
        best, _ = index.best_poses(photo, 1, np.random.default_rng(0))
        assert np.hypot(*(best[0, :2] - truth[:2])) < 0.75 * 0.25 + 0.06
        assert abs(wrap_angle(best[0, 2] - truth[2])) < step


def test_a_track_scores_each_photo_at_the_cell_the_odometry_puts_it_in(gl_ctx, office):
    """Three photos along a drive (noise-free odometry): the track's score at the true cell
    now is the mean of each photo's score at its own true cell, and ranks among the best."""
    robot = SimRobot(office, SimRobotConfig(), np.random.default_rng(0), gl_ctx, (0.0, -2.5, 0.0))
    lik = LevelViewLikelihood(likelihood_renderer(office.mesh, gl_ctx, office.background), office.light,
                              Camera(robot.intrinsics, *robot.image_size), robot.cam_from_robot)
    index = PanoramaIndex(lik, robot.free, 0.25)
    C, step = index.cyl.n_cols, index.cyl.step
    p0 = int(np.argmin(np.hypot(*(index.positions - [-1.0, -1.0]).T)))
    cells = [(p0, 0)]  # then 0.5 m along +x (one grid step), then a turn by 8 columns
    xy = index.positions[p0] + [0.5, 0.0]
    cells.append((int(np.argmin(np.hypot(*(index.positions - xy).T))), 0))
    cells.append((cells[1][0], 8))
    track, own = [], []
    for p, c in cells:
        pose = index.robot_poses(index.positions[p][None], np.array([-c * step]))[0]
        robot.kidnap(pose)
        image = robot.capture().image
        track.append((pose.copy(), image))  # odometry in the world frame: exact
        own.append(index.photo_scores(image)[p, c])
    v = index.track_scores(track)
    p, c = cells[-1]
    assert v[p, c] == pytest.approx(np.mean(own), abs=1e-5)
    assert (v > v[p, c]).sum() < 10
    assert index.cells(track[-1][0][None])[0][0] == p
