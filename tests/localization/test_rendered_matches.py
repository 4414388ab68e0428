"""Pose proposals from features of rendered views (`localization.rendered_matches`) against
known answers: the office's photos and its true mesh, so a proposal's truth is the photo's pose."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ibr.scene import load_scene
from localization.eval import draw_prior
from localization.feature_localizer import pose_errors
from localization.rendered_matches import RenderedMatchConfig, near_map_views, rendered_proposals, turned
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


def test_map_photos_near_the_prior_are_those_that_could_see_its_view(office_model):
    scene = office_model[0]
    cams = scene.cameras
    T = cams[3].cam_from_world
    near = near_map_views(T, 0.3, np.radians(30.0), cams, 6)
    assert np.array_equal(near[0], T)  # the photo at the prior itself, nearest first
    for U in near:  # each within twice the position spread, facing within 30 deg + half the field of view
        assert np.all(np.abs(np.linalg.inv(U)[:3, 3] - cams[3].center) <= 0.6 + 1e-9)
        assert U[2, :3] @ T[2, :3] >= np.cos(np.radians(60.0))
    behind = turned(T, np.pi, 0.0)  # a prior facing the other way shares no photo's view
    assert not any(np.array_equal(U, T) for U in near_map_views(behind, 0.3, np.radians(30.0), cams, 6))
    assert len(near_map_views(T, 0.3, np.radians(30.0), cams, 1)) == 1


def test_a_map_photo_near_the_photo_proposes_its_pose_from_a_prior_too_far_off_to_see_it(office_model):
    """A new photo 20 cm and 10 degrees from map photo 4; the prior is turned 70 degrees
    away, with no turned views, so its own view shares nothing with the photo. Map photo 4's
    pose does."""
    scene, renderer, light = office_model
    near = scene.cameras[4]
    T = turned(near.cam_from_world, np.radians(10.0), 0.0)
    T[:3, 3] = -T[:3, :3] @ (near.center + np.array([0.2, 0.0, 0.0]))
    camera = near.with_pose(T, "query")
    image = scene.world.photograph(camera)
    prior = turned(T, np.radians(70.0), 0.0)
    config = RenderedMatchConfig(width=320, turn_fraction=0.0, rounds=1)
    assert not rendered_proposals(renderer, None, image, camera, prior, 0.0, [], config, light)
    found = rendered_proposals(renderer, None, image, camera, prior, 0.0, [], config, light,
                               [near.cam_from_world])
    assert found
    pos, rot = pose_errors(found[0][0], T)
    assert pos < 0.02 and rot < 0.3, (pos, rot)
