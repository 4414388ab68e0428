"""6-DoF particle filter and the hybrid on a synthetic scene whose answer is known: the
office's photos are rendered from its mesh, so the rendered likelihood's optimum is the truth."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ibr.scene import load_scene
from localization.eval_loc import LocConfig, SceneLocalizer, draw_prior
from localization.feature_localizer import PnPResult, pose_errors
from localization.hybrid import HybridConfig, localize_hybrid
from localization.pose6_filter import (Pose6Filter, Pose6FilterConfig, cam_from_world_of,
                                       particles_from_cam_from_world, sample_around, weighted_pose)

SMALL = Pose6FilterConfig(n_particles=150, steps=20, sizes=((40, 30), (80, 60)))


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
    loc = SceneLocalizer(office_scene.without(held.name), "pf", LocConfig(filter=SMALL, model="mesh"), ctx=gl_ctx)
    return held, loc


def synthetic_pnp(held, renderer, rng, offset_m=0.005) -> PnPResult:
    """A PnP result with a known answer: 300 pixels of the view, their true world points
    (rendered G-buffer), 0.5 px noise, and a pose `offset_m` off the truth."""
    g = renderer.render(held.camera)
    v, u = np.nonzero(g.mask)
    pick = rng.choice(len(u), 300, replace=False)
    uv = np.c_[u[pick], v[pick]] + rng.normal(scale=0.5, size=(300, 2))
    T = held.camera.cam_from_world.copy()
    T[:3, 3] += [offset_m, 0, 0]
    return PnPResult(T, 300, 300, held.camera.with_pose(T), uv, g.world[v[pick], u[pick]].astype(float))


def test_pf_converges_to_the_true_pose(pf_setup):
    held, loc = pf_setup
    rng = np.random.default_rng(1)
    truth = held.camera.cam_from_world
    prior = draw_prior(truth, 0.3, 10.0, rng)
    start = pose_errors(prior, truth)
    res = loc.localize(held.image, held.camera, prior, 0.3, 10.0, rng)
    pos, rot = pose_errors(res.cam_from_world, truth)
    assert start[0] > 0.15 and start[1] > 4.0  # the prior is well off
    # the rendered likelihood at 80x60 pins the pose to a few cm
    assert pos < 0.10 and rot < 2.0, (start, pos, rot)


def test_hybrid_with_a_pnp_proposal_converges_from_a_wrong_prior(pf_setup):
    held, loc = pf_setup
    rng = np.random.default_rng(2)
    truth = held.camera.cam_from_world
    pnp = synthetic_pnp(held, loc.likelihood.model, rng)
    prior = draw_prior(truth, 1.0, 30.0, rng)
    particles = sample_around(prior, SMALL.n_particles, 1.0, np.radians(30), rng)
    pf = Pose6Filter(loc.likelihood, SMALL, rng)
    res = localize_hybrid(pf, None, held.image, held.camera, particles, HybridConfig(), pnp=pnp)
    pos, rot = pose_errors(res.estimate.cam_from_world, truth)
    assert pos < 0.02 and rot < 0.5, (pose_errors(prior, truth), pos, rot)
