"""The rendered-view localiser (6-DoF particle filter, Gauss-Newton, verdict) and the hybrid on
a synthetic scene whose answer is known: the office's photos are rendered from its mesh, so
the rendered likelihood's optimum is the truth."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ibr.scene import load_scene
from localization.eval import draw_prior
from localization.render_localizer import RenderLocalizerConfig
from localization.localize import LocConfig, SceneLocalizer
from localization.feature_localizer import PnPResult, pose_errors
from localization.hybrid import HybridConfig, localize_hybrid
from localization.pose6_filter import (Pose6FilterConfig, PriorBox, annealing_temperature, apply_offsets,
                                       cam_from_world_of, diffuse, particles_from_cam_from_world, pose_covariance,
                                       sample_around, weighted_pose)

SMALL = RenderLocalizerConfig(filter=Pose6FilterConfig(n_particles=100, n_initial=400, steps=6),
                              modes=4, reference_views=4)


@pytest.fixture(scope="module")
def office_scene():
    return load_scene("synthetic:office?views=10&width=320&height=240")


def test_particles_round_trip_cam_from_world(office_scene):
    T = np.stack([c.cam_from_world for c in office_scene.cameras])
    np.testing.assert_allclose(cam_from_world_of(particles_from_cam_from_world(T)), T, atol=1e-9)


def test_weighted_pose_averages_rotations_on_the_sphere():
    base = Rotation.from_euler("xyz", [10, -20, 30], degrees=True)
    offsets = Rotation.from_rotvec(np.radians([[3, 0, 0], [-3, 0, 0], [0, 3, 0], [0, -3, 0]]))
    R_wc = (base * offsets).as_rotvec()
    particles = np.c_[np.tile([1.0, 2.0, 3.0], (4, 1)) + [[0.1, 0, 0], [-0.1, 0, 0], [0, 0, 0], [0, 0, 0]], R_wc]
    T = weighted_pose(particles, np.ones(4))
    expected = np.r_[[1.0, 2.0, 3.0], base.as_rotvec()]
    np.testing.assert_allclose(particles_from_cam_from_world(T)[0], expected, atol=1e-3)


@pytest.fixture(scope="module")
def pf_setup(office_scene, gl_ctx):
    held = office_scene.views[3]
    loc = SceneLocalizer(office_scene.without(held.name), "pf", LocConfig(render=SMALL, model="mesh"), ctx=gl_ctx)
    yield held, loc
    loc.release()


def synthetic_pnp(held, renderer, rng, offset_m: float, inliers: int) -> PnPResult:
    """A PnP result with a known answer: pixels of the view and their true world points
    (rendered G-buffer), 0.5 px noise, a pose `offset_m` off the truth, `inliers` of 300
    matches."""
    g = renderer.render(held.camera)
    v, u = np.nonzero(g.mask)
    pick = rng.choice(len(u), inliers, replace=False)
    uv = np.c_[u[pick], v[pick]] + rng.normal(scale=0.5, size=(inliers, 2))
    T = held.camera.cam_from_world.copy()
    T[:3, 3] += [offset_m, 0, 0]
    return PnPResult(T, 300, inliers, held.camera.with_pose(T), uv, g.world[v[pick], u[pick]].astype(float))


class FixedPnP:
    """A feature map whose PnP always returns the given result."""

    def __init__(self, result):
        self.result = result

    def localize(self, image, camera):
        return self.result


def test_pf_converges_to_the_true_pose_and_says_so(pf_setup):
    held, loc = pf_setup
    rng = np.random.default_rng(1)
    truth = held.camera.cam_from_world
    prior = draw_prior(truth, 0.3, 10.0, rng)
    start = pose_errors(prior, truth)
    res = loc.localize(held.image, held.camera, prior, 0.3, 10.0, rng)
    pos, rot = pose_errors(res.cam_from_world, truth)
    assert start[0] > 0.1 and start[1] > 3.0  # the prior is well off
    assert pos < 0.01 and rot < 0.2, (start, pos, rot)  # Gauss-Newton pins it
    assert res.localized and res.verdict.confidence > 0.9, res.verdict


def test_a_blank_photo_and_a_photo_of_another_place_are_not_localised(pf_setup, gl_ctx):
    held, loc = pf_setup
    rng = np.random.default_rng(3)
    truth = held.camera.cam_from_world
    blank = np.full_like(held.image, 128)
    elsewhere = load_scene("synthetic:courtyard?views=4&width=320&height=240").views[1].image
    for image in (blank, elsewhere):
        res = loc.localize(image, held.camera, draw_prior(truth, 0.3, 10.0, rng), 0.3, 10.0, rng)
        assert not res.localized and res.verdict.reason, res.verdict


def test_hybrid_keeps_a_strong_pnp_pose_and_arbitrates_a_weak_one(pf_setup):
    held, loc = pf_setup
    rng = np.random.default_rng(2)
    truth = held.camera.cam_from_world
    renderer = loc.model.fine.renderer
    particles = sample_around(draw_prior(truth, 0.3, 10.0, rng), 400, 0.3, np.radians(10), rng)
    spread = (0.3, np.radians(10))
    strong = synthetic_pnp(held, renderer, rng, 0.004, 200)
    res = localize_hybrid(loc.model, FixedPnP(strong), held.image, held.camera, particles, spread, rng)
    assert res.source == "pnp" and res.verdict.localized
    np.testing.assert_array_equal(res.cam_from_world, strong.cam_from_world)  # not dragged away
    weak = synthetic_pnp(held, renderer, rng, 0.03, 15)
    res = localize_hybrid(loc.model, FixedPnP(weak), held.image, held.camera, particles, spread, rng)
    assert res.source == "render" and res.verdict.localized
    assert pose_errors(res.cam_from_world, truth)[0] < 0.01  # the rendered alignment fixed it


def test_annealing_temperature_keeps_the_asked_share_of_effective_particles():
    cost = np.random.default_rng(0).uniform(0.1, 0.6, 500)
    for fraction in (0.2, 0.5, 0.8):
        t = annealing_temperature(cost, fraction, (10.0, 1e-4))
        w = np.exp(-(cost - cost.min()) / t)
        assert abs(w.sum() ** 2 / (w @ w) / len(cost) - fraction) < 1e-3
    # clamped to the bounds: equal costs never need cooling, a huge spread hits the hottest bound
    assert annealing_temperature(np.full(10, 0.3), 0.5, (0.2, 0.002)) == pytest.approx(0.002)
    assert annealing_temperature(np.r_[0.0, np.full(99, 50.0)], 0.5, (0.2, 0.002)) == pytest.approx(0.2)


def test_diffusion_follows_the_particles_covariance():
    rng = np.random.default_rng(0)
    base = particles_from_cam_from_world(np.eye(4))
    # particles spread along a diagonal of x and yaw (the ridge a narrow camera sees)
    s = rng.normal(size=(4000, 1))
    ridge = np.c_[0.1 * s, np.zeros((4000, 3)), 0.02 * s, np.zeros((4000, 1))]
    particles = apply_offsets(np.repeat(base, 4000, axis=0), ridge)
    cov = pose_covariance(particles)
    assert cov[0, 4] / np.sqrt(cov[0, 0] * cov[4, 4]) > 0.99
    moved = diffuse(particles, 0.5, (0.001, 0.0001), rng)
    step = pose_covariance(np.c_[moved[:, :3] - particles[:, :3], np.zeros((4000, 3))])[:3, :3]
    np.testing.assert_allclose(step[0, 0], 0.25 * cov[0, 0] + 0.001 ** 2, rtol=0.1)
    assert step[1, 1] < 0.01 * step[0, 0]  # no spread where the particles have none


@pytest.mark.realdata
def test_pf_localises_a_held_out_fountain_photo_from_a_1m_30deg_prior(strecha_dir):
    """The rendered-view localiser (photo-textured proxy with trust, eval-loc's settings) on
    fountain-P11 with 0005 held out, from a prior drawn +-1 m / +-30 deg around the truth:
    under 5 cm / 5 deg, and it says it localised."""
    scene = load_scene(strecha_dir / "fountain-P11")
    held = scene.view("0005.jpg")
    loc = SceneLocalizer(scene.without(held.name), "pf")
    rng = np.random.default_rng(0)
    truth = held.camera.cam_from_world
    prior = draw_prior(truth, 1.0, 30.0, rng)
    res = loc.localize(held.image, held.camera, prior, 1.0, 30.0, rng)
    pos, rot = pose_errors(res.cam_from_world, truth)
    assert pose_errors(prior, truth)[0] > 0.3
    assert pos < 0.05 and rot < 5.0, (pose_errors(prior, truth), pos, rot)
    assert res.localized, res.verdict
    loc.release()


def test_prior_box_contains_exactly_what_sample_around_draws():
    rng = np.random.default_rng(4)
    pose = cam_from_world_of(np.array([[1.0, -2.0, 0.5, 0.3, -1.2, 2.0]]))[0]
    box = PriorBox(pose, 1.0, np.radians(30))
    assert box.contains(sample_around(pose, 500, 1.0, np.radians(30), rng)).all()
    outside = sample_around(pose, 200, 1.0, np.radians(30), rng)
    outside[:100, 0] += 2.0  # 1-3 m off in x
    turned = Rotation.from_matrix(pose[:3, :3].T) * Rotation.from_euler("x", 35, degrees=True)
    outside[100:] = np.r_[particles_from_cam_from_world(pose)[0, :3], turned.as_rotvec()]  # 35 deg off
    assert not box.contains(outside).any()
