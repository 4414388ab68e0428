"""Photometric Gauss-Newton alignment (`localization.direct_alignment`) against known answers:
the office's photos rendered from its mesh, so the alignment's optimum is the true pose."""

import cv2
import numpy as np
import pytest
from scipy.ndimage import map_coordinates

from ibr.scene import load_scene
from localization.direct_alignment import observed_at, photometric_jacobian, refine_pose, render_terms, se3_step
from localization.feature_localizer import pose_errors
from localization.pose6_filter import apply_offsets, cam_from_world_of, particles_from_cam_from_world
from localization.render_likelihood import LikelihoodConfig, comparison_camera, likelihood_renderer


@pytest.fixture(scope="module")
def office_model(gl_ctx):
    scene = load_scene("synthetic:office?views=10&width=320&height=240")
    return scene, likelihood_renderer(scene.mesh, gl_ctx), scene.world.light


def offset_pose(T, offset):
    return cam_from_world_of(apply_offsets(particles_from_cam_from_world(T), np.array([offset])))[0]


def test_gauss_newton_converges_from_several_cm_and_degrees(office_model):
    scene, renderer, light = office_model
    for k, offset in ((3, [0.05, -0.03, 0.04, 0.02, -0.01, 0.015]), (6, [-0.04, 0.05, 0.0, -0.015, 0.02, 0.0])):
        view = scene.views[k]
        start = offset_pose(view.camera.cam_from_world, offset)
        result = refine_pose(renderer, view.image, view.camera, start, (48, 96, 192), light=light)
        pos, rot = pose_errors(result.cam_from_world, view.camera.cam_from_world)
        assert pose_errors(start, view.camera.cam_from_world)[0] > 0.05
        assert pos < 0.01 and rot < 0.2, (k, pos, rot)
        assert result.explained > 0.9


def test_the_jacobian_matches_finite_differences_of_the_photo(office_model):
    """For a small step along each of the 6 pose axes, J xi predicts how the (blurred) photo's
    luminance at the model's pixels changes when the pixels' 3-D points move by the step."""
    scene, renderer, light = office_model
    view = scene.views[3]
    cam = comparison_camera(view.camera, 96)
    o = cv2.GaussianBlur(observed_at(view.image, cam), (0, 0), 1.0)
    grad = (cv2.Sobel(o, cv2.CV_32F, 1, 0, ksize=3) / 8, cv2.Sobel(o, cv2.CV_32F, 0, 1, ksize=3) / 8)
    _, depth, w = render_terms(renderer, cam, light, LikelihoodConfig())
    v, u = np.nonzero(w > 0)
    z = depth[v, u].astype(float)
    J = photometric_jacobian(cam, grad, u, v, z)
    X = (np.linalg.inv(cam.K) @ np.c_[u, v, np.ones(len(u))].T) * z
    for axis in range(6):
        xi = np.zeros(6)
        xi[axis] = 1e-3 if axis < 3 else 3e-4
        step = se3_step(xi)
        Xm = step[:3, :3] @ X + step[:3, 3:4]
        uv = (cam.K @ Xm)[:2] / Xm[2]
        actual = map_coordinates(o, [uv[1], uv[0]], order=1, mode="nearest") - o[v, u]
        predicted = J @ xi
        assert np.corrcoef(predicted, actual)[0, 1] > 0.85, (axis, np.corrcoef(predicted, actual)[0, 1])
