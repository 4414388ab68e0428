"""Model trust (`localization.model_trust`) against known answers: the office's true geometry,
seen by rendered photos and backed by points sampled on the true surface, is trusted; the
same mesh moved 0.3 m off the surface is not (its patches disagree between photos and no
point supports it); flat patches cannot be judged, but flat against textured disagrees; support falls off in pixels."""

import numpy as np
import pytest
import trimesh

from ibr.camera import Camera, intrinsics_from_fov
from ibr.synthetic import make_world
from localization.model_trust import TrustConfig, geometric_support, patch_agreement
from localization.photo_texture import PhotoTexture, PhotoTextureConfig


@pytest.fixture(scope="module")
def office_photos(gl_ctx):
    world = make_world("office", 0)
    cams = world.default_cameras(24, 320, 240)  # neighbours overlap: faces seen twice
    photos = [world.photograph(c, gl_ctx) for c in cams]
    mesh = trimesh.Trimesh(*trimesh.remesh.subdivide_to_size(world.mesh.vertices, world.mesh.faces, 0.3),
                           process=False)
    points = trimesh.sample.sample_surface(world.mesh, 200000, seed=0)[0]
    return world, cams, photos, mesh, points


def test_true_geometry_is_trusted_and_a_displaced_copy_is_not(office_photos, gl_ctx):
    world, cams, photos, mesh, points = office_photos
    config = PhotoTextureConfig(cell_width=320)
    true = PhotoTexture(mesh, cams, photos, config, gl_ctx, points=points)
    seen_twice = (true.score > 0).sum(axis=1) >= 2
    moved = mesh.copy()
    moved.vertices = moved.vertices + moved.vertex_normals * 0.3  # off the surface, into the room or out
    off = PhotoTexture(moved, cams, photos, config, gl_ctx, points=points)
    seen_off = (off.score > 0).sum(axis=1) >= 2
    assert np.median(true.trust[seen_twice]) > 0.4  # flat walls score 0.5: they cannot tell
    assert np.median(off.trust[seen_off]) < 0.1
    assert (true.trust[~seen_twice] == 0).all()  # nothing confirms a face seen once


def test_flat_patches_score_a_half_and_textured_ones_their_ncc():
    rng = np.random.default_rng(0)
    textured = rng.uniform(0, 1, (5, 49))
    flat = np.full((5, 49), 0.4) + rng.normal(scale=0.001, size=(5, 49))
    np.testing.assert_allclose(patch_agreement(flat, flat[::-1] + 0.1, 0.02), 0.5)
    # texture in one photo and none in the other (sky behind a face, wall in front of it)
    np.testing.assert_allclose(patch_agreement(flat, textured, 0.02), 0.0)
    np.testing.assert_allclose(patch_agreement(textured, flat, 0.02), 0.0)
    np.testing.assert_allclose(patch_agreement(textured, 0.5 * textured + 0.2, 0.02), 1.0, atol=1e-6)
    assert (patch_agreement(textured, rng.uniform(0, 1, (5, 49)), 0.02) < 0.5).all()


def test_support_is_measured_in_pixels_of_the_best_photo():
    cam = Camera.look_at((0, 0, 0), (0, 10, 0), intrinsics_from_fov(60, 384, 288), 384, 288)
    f = cam.K[0, 0]
    centroids = np.array([[0, 10, 0], [0, 10, 0], [0, 10, 0]], float)
    # the nearest point 1 px, 5 px and 10 px away at 10 m
    offsets = np.array([1.0, 5.0, 10.0]) * 10 / f
    support = [geometric_support(centroids[:1], np.ones((1, 1)), [cam], centroids[:1] + [d, 0, 0], TrustConfig())[0]
               for d in offsets]
    np.testing.assert_allclose(support, [1.0, 0.5, 0.0], atol=1e-6)
