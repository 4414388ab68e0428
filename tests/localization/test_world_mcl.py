"""World-scaled SE(2) MCL: the horizon-free comparison, the settings derived from the
world, adaptive tempering and the mode estimate."""

import numpy as np
import pytest

from ibr.camera import Camera
from ibr.synthetic import make_world
from localization.level_view_likelihood import LevelViewLikelihood, ncc_rows
from localization.particle_filter import effective_sample_size, sample_free_poses
from localization.render_likelihood import likelihood_renderer
from localization.motion_models import apply_odometry, odometry_decomposition, se2_backward
from localization.world_mcl import (Basin, MCLSettings, calibrated_temperature, ess_temperature, measure_basin,
                                    mode_estimate)
from robot.protocol import robot_camera
from robot.sim_robot import SimRobot, SimRobotConfig


def test_horizon_free_ncc_ignores_the_row_profile_every_level_view_shares():
    rng = np.random.default_rng(0)
    obs = rng.random((24, 32))
    horizon = np.linspace(1.0, -1.0, 24)[:, None]  # sky above, ground below
    assert ncc_rows(np.stack([obs + horizon, 0.5 * obs]), obs) == pytest.approx([1.0, 1.0], abs=1e-6)
    shifted = np.roll(obs, 3, axis=1) + horizon
    assert ncc_rows(shifted[None], obs)[0] < 0.5


def _courtyard(gl_ctx, seed=3):
    world = make_world("courtyard", seed)
    start = world.start_pose(np.random.default_rng(0))
    robot = SimRobot(world, SimRobotConfig(), np.random.default_rng(0), gl_ctx, start)
    lik = LevelViewLikelihood(likelihood_renderer(world.mesh, gl_ctx, world.background), world.light,
                              Camera(robot.intrinsics, *robot.image_size), robot.cam_from_robot)
    return world, robot, lik


def test_views_show_the_sky_where_the_model_is_empty_and_the_truth_wins_outdoors(gl_ctx):
    """The batched read-back equals the renderer's own per-camera render at twice the size,
    area-averaged (luminance, the background where nothing is drawn); in the courtyard, where half the view is sky, the
    true pose scores above 1000 random poses of the site."""
    world, robot, lik = _courtyard(gl_ctx)
    pose = np.array([12.0, 5.0, np.pi])  # on the site, looking at the buildings
    cam = robot_camera(pose, robot.intrinsics, robot.image_size, robot.cam_from_robot).scaled(0.2)
    g = lik.model.render(cam, world.light)
    ref = g.color.astype(np.float32) @ np.array([0.299, 0.587, 0.114], np.float32) / 255
    ref = ref.reshape(24, 2, 32, 2).mean(axis=(1, 3))
    got = lik.render(pose[None], (32, 24))[0]
    assert (g.depth <= 0).mean() > 0.2  # sky in view
    assert np.abs(got - ref).mean() < 0.01
    lik.set_observation(world.photograph(robot_camera(pose, robot.intrinsics, robot.image_size,
                                                      robot.cam_from_robot), gl_ctx), (32, 24))
    others = sample_free_poses(robot.free, 1000, np.random.default_rng(1))
    others = others[np.hypot(*(others[:, :2] - pose[:2]).T) > 1.0]
    v = lik.ncc(np.r_[pose[None], others], (32, 24))
    assert v[0] > v[1:].max()


def test_the_basin_is_wider_outdoors_and_the_settings_follow_it(gl_ctx, office):
    """The measured peak is wider in the courtyard (surfaces metres away) than in the
    office; counts scale with free area / basin cells, within their bounds; bins are half
    a basin."""
    _, robot, lik = _courtyard(gl_ctx)
    wide = measure_basin(lik, robot.free, np.random.default_rng(0), n_poses=8)
    orobot = SimRobot(office, SimRobotConfig(), np.random.default_rng(0), gl_ctx, (0.0, -2.5, 0.0))
    olik = LevelViewLikelihood(likelihood_renderer(office.mesh, gl_ctx, office.background), office.light,
                               Camera(orobot.intrinsics, *orobot.image_size), orobot.cam_from_robot)
    narrow = measure_basin(olik, orobot.free, np.random.default_rng(0), n_poses=8)
    assert wide.m > 1.5 * narrow.m
    s = MCLSettings.for_world(100.0, Basin(0.5, 0.1), per_basin=1.0, n_min=10, n_cap=10**6)
    assert s.n_global == int(np.ceil(100.0 / (np.pi * 0.25) * (np.pi / 0.1)))
    assert MCLSettings.for_world(1e6, Basin(0.5, 0.1), n_cap=5000).n_global == 5000
    assert s.kld_bin == pytest.approx((0.25, 0.25, 0.05))


def test_ess_tempering_keeps_the_requested_share_of_particles():
    rng = np.random.default_rng(0)
    log_w = np.full(1000, -np.log(1000))
    loglik = -rng.random(1000) * 200  # a sharp likelihood: untempered, a few particles win
    t = ess_temperature(log_w, loglik, 0.1)
    assert t > 1 and effective_sample_size(log_w + loglik / t) >= 100
    assert effective_sample_size(log_w + loglik / (0.9 * t)) < 100  # the least such factor
    assert ess_temperature(log_w, np.zeros(1000), 0.1) == 1.0


def test_mode_estimate_is_the_heavier_mode_not_the_mean_between():
    rng = np.random.default_rng(0)
    a = np.c_[rng.normal(0, 0.02, (300, 2)), rng.normal(0, 0.01, 300)]
    b = np.c_[rng.normal(4, 0.02, (200, 2)), rng.normal(0, 0.01, 200)]
    est = mode_estimate(np.r_[a, b], np.full(500, 1 / 500), (0.2, 0.2, 0.1))
    assert np.hypot(*est[:2]) < 0.05


class _TwoPlaces:
    """A likelihood with a known answer: the NCC is a bump of `width_m` at each of two
    places (heading 0), of heights `heights`; the image is ignored."""

    def __init__(self, places, heights, width_m=0.3):
        self.places, self.heights, self.width = np.asarray(places, float), heights, width_m

    def set_observation(self, image, size):
        pass

    def observed_contrast(self):
        return 1.0

    def ncc(self, poses, size):
        poses = np.atleast_2d(poses)
        out = np.zeros(len(poses))
        for p, h in zip(self.places, self.heights):
            d2 = ((poses[:, :2] - p) ** 2).sum(1) + (np.angle(np.exp(1j * poses[:, 2])) / 0.2) ** 2 * self.width**2
            out = np.maximum(out, h * np.exp(-d2 / (2 * self.width**2)))
        return out


def _filter(lik, seed=0):
    import shapely

    from localization.particle_filter import ParticleFilter
    from localization.world_mcl import WorldMCL

    free = shapely.box(0, 0, 4, 2)
    settings = MCLSettings.for_world(free.area, Basin(0.3, 0.2), per_basin=4.0, n_cap=4000)
    pf = ParticleFilter(free, settings.filter_config(), np.random.default_rng(seed))
    pf.init_uniform()
    return WorldMCL(pf, lik, settings)


def test_two_places_the_likelihood_cannot_tell_apart_get_no_claim():
    """Two equally good places: whichever the cloud gathers on, the probes find the other
    as good, so the filter never claims convergence; when one place fits better, it
    converges there."""
    still = np.zeros(3)
    mcl = _filter(_TwoPlaces([[1, 1], [3, 1]], [0.9, 0.9]))
    steps = [mcl.step(still, still, None) for _ in range(8)]
    assert not any(s.converged for s in steps)
    mcl = _filter(_TwoPlaces([[1, 1], [3, 1]], [0.9, 0.4]))
    steps = [mcl.step(still, still, None) for _ in range(8)]
    assert steps[-1].converged and np.hypot(*(steps[-1].estimate[:2] - [1, 1])) < 0.15


def test_se2_backward_undoes_the_odometry_motion():
    rng = np.random.default_rng(0)
    then, now = np.array([1.0, 2.0, 0.3]), np.array([1.5, 2.4, 0.9])
    poses = np.c_[rng.uniform(-5, 5, (20, 2)), rng.uniform(-np.pi, np.pi, 20)]
    back = se2_backward(poses, then, now)
    assert apply_odometry(back, odometry_decomposition(then, now)) == pytest.approx(poses)


def test_the_temperature_is_the_best_views_shortfall_within_bounds():
    assert calibrated_temperature(np.array([0.2, 0.98, 0.5]), 0.01, 0.05) == pytest.approx(0.02)
    assert calibrated_temperature(np.array([0.2, 0.5]), 0.01, 0.05) == 0.05  # lost: no flatter than before
    floor = 1 / (12 * 255**2) / 0.01  # 8-bit quantisation's share of a contrast of 0.01
    assert calibrated_temperature(np.array([1.0]), 0.01, 0.05) == pytest.approx(floor)


def test_no_claim_while_the_photos_fit_worse_than_the_filters_long_run_average():
    """A filter that lost its claim (a kidnapping noticed) does not claim again on a place
    that now fits the photos worse than it used to (augmented MCL's w_fast < w_slow, the
    filter injecting particles), however tight its cloud; it claims again once they fit
    as well as before."""
    still = np.zeros(3)
    lik = _TwoPlaces([[1, 1]], [0.9])
    mcl = _filter(lik)
    assert [mcl.step(still, still, None) for _ in range(20)][-1].converged  # tracking a while
    mcl.converged, mcl.streak = False, 0  # the claim dropped
    lik.heights = [0.5]  # the same place now explains the photos worse
    worse = [mcl.step(still, still, None) for _ in range(3)]
    assert mcl.pf.w_fast < mcl.pf.w_slow
    assert not any(s.converged for s in worse)  # the cloud is tight and alone: 2 steps would do
    lik.heights = [0.9]
    assert [mcl.step(still, still, None) for _ in range(6)][-1].converged
