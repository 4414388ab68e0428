"""Pose proposals from features of rendered views (`localization.rendered_matches`) against
known answers: the office's photos and its true mesh, so a proposal's truth is the photo's pose."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ibr.scene import load_scene
from localization.eval import draw_prior
from localization.feature_localizer import pose_errors
from localization.rendered_matches import RenderedMatchConfig, rendered_proposals, turned
from localization.render_likelihood import likelihood_renderer


@pytest.fixture(scope="module")
def office_model(gl_ctx):
    scene = load_scene("synthetic:office?views=10&width=320&height=240")
    return scene, likelihood_renderer(scene.mesh, gl_ctx), scene.world.light


def test_turned_views_keep_the_centre_and_turn_by_the_angle(office_model):
    T = office_model[0].cameras[2].cam_from_world
    for yaw, pitch in ((0.3, 0.0), (0.0, -0.2)):
        U = turned(T, yaw, pitch)
        assert np.allclose(np.linalg.inv(U)[:3, 3], np.linalg.inv(T)[:3, 3])
        assert Rotation.from_matrix(U[:3, :3] @ T[:3, :3].T).magnitude() == pytest.approx(abs(yaw + pitch))


def test_a_photo_turned_and_moved_inside_the_prior_gets_its_true_pose(office_model):
    scene, renderer, light = office_model
    rng = np.random.default_rng(3)
    for k in (1, 4, 7):
        view = scene.views[k]
        prior = draw_prior(view.camera.cam_from_world, 0.3, 25.0, rng)
        found = rendered_proposals(renderer, None, view.image, view.camera, prior, np.radians(25.0), [],
                                   RenderedMatchConfig(width=320), light)
        assert found, k
        pos, rot = pose_errors(found[0][0], view.camera.cam_from_world)
        assert pos < 0.02 and rot < 0.3, (k, pos, rot)


def test_a_blank_photo_gets_no_proposal(office_model):
    scene, renderer, light = office_model
    view = scene.views[1]
    blank = np.full_like(view.image, 128)
    assert rendered_proposals(renderer, None, blank, view.camera, view.camera.cam_from_world, np.radians(25.0),
                              [], RenderedMatchConfig(width=320), light) == []
