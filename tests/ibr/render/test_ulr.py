"""Unstructured lumigraph rendering: reproduces a held-out synthetic photo, matches its numpy
reference, and does not ghost occluders thanks to the shadow-map visibility test."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from ibr.camera import Camera, intrinsics_from_fov
from ibr.render.eval import psnr
from ibr.mesh_renderer import MeshRenderer
from ibr.render.nearest_view import NearestViewRenderer, nearest_source
from ibr.scene import Scene, View, load_scene
from ibr.render.ulr import UlrConfig, UlrRenderer, fill_depth_holes, k_nearest_weights, ulr_blend_numpy


@pytest.fixture(scope="module")
def office_scene():
    return load_scene("synthetic:office?views=21&width=320&height=240")


@pytest.fixture(scope="module")
def held_out(office_scene):
    held = office_scene.views[10]
    return held, office_scene.without(held.name)


@pytest.fixture(scope="module")
def ulr(gl_ctx, office_scene, held_out):
    r = UlrRenderer(held_out[1], office_scene.mesh, gl_ctx, k=4)
    yield r
    r.release()


def test_ulr_reproduces_held_out_photo(ulr, held_out):
    """20 photos of the office + its true mesh as proxy: > 30 dB on the covered pixels (the
    default light is low-specular; the view is not of the shiny cabinet)."""
    held, _ = held_out
    image, covered = ulr.render(held.camera)
    assert covered.mean() > 0.8
    assert psnr(image, held.image, covered) > 30.0


def test_ulr_beats_nearest_view(gl_ctx, ulr, office_scene, held_out):
    held, sources = held_out
    nearest = NearestViewRenderer(sources, office_scene.mesh, gl_ctx, source_depths=ulr.source_depths)
    img_n, cov_n = nearest.render(held.camera)
    img_u, cov_u = ulr.render(held.camera)
    nearest.release()
    assert cov_u.mean() > cov_n.mean()
    both = cov_u & cov_n
    assert psnr(img_u, held.image, both) > psnr(img_n, held.image, both)


def test_shader_blend_matches_numpy_reference(ulr, held_out):
    held, sources = held_out
    cam = held.camera
    view_depth = fill_depth_holes(ulr.proxy_depth(cam))
    rgba = ulr.blend(cam, view_depth).reshape(-1, 4)
    z = np.abs(view_depth).ravel()
    m = z > 0
    P = cam.unproject(cam.pixel_grid()[m], z[m])
    images = np.stack([v.image for v in sources.views])
    rgb, ok = ulr_blend_numpy(P, view_depth.ravel()[m] > 0, cam.center, ulr.sources.matrices,
                              ulr.sources.centres, images, ulr.source_depths, ulr.cfg)
    gl_ok = rgba[m, 3] > 127
    assert (ok == gl_ok).mean() > 0.999
    both = ok & gl_ok
    assert np.abs(rgb[both] - rgba[m][both, :3]).mean() < 0.5


def test_k_nearest_weights_are_smooth_and_epipole_consistent():
    pen = np.array([[0.0, 0.1, 0.2, 0.3, 0.4], [0.1, 0.2, np.inf, 0.3, 0.5]])
    w = k_nearest_weights(pen, k=3, eps=1e-6)
    np.testing.assert_allclose(w.sum(axis=1), 1.0)
    assert w[0, 0] > 0.999            # a source on the desired ray takes all the weight
    assert w[1, 2] == 0 and w[1, 4] == 0  # invalid and (k+1)-th get none
    assert w[1, 0] > w[1, 1] > w[1, 3] > 0


def _quad(x0, x1, z0, z1, y, color):
    """A vertical rectangle at depth y (metres) facing -y, vertex-coloured."""
    xs, zs = np.meshgrid(np.linspace(x0, x1, 9), np.linspace(z0, z1, 9))
    grid = np.c_[xs.ravel(), np.full(xs.size, y), zs.ravel()]
    idx = np.arange(81).reshape(9, 9)
    faces = np.concatenate([np.c_[idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel()],
                            np.c_[idx[:-1, :-1].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()]])
    return trimesh.Trimesh(grid, faces, vertex_colors=np.tile([*color, 255], (81, 1)), process=False)


def _occluder_scene(gl_ctx):
    """A green wall 5 m ahead; source B (close to the virtual camera) has a red board right in
    front of its lens; source A (farther off) sees the wall freely."""
    wall = _quad(-4, 4, -3, 3, 5.0, (0, 200, 0))
    board = _quad(0.2, 0.45, -0.12, 0.12, 0.35, (255, 0, 0))
    world = trimesh.util.concatenate([wall, board])
    K = intrinsics_from_fov(40, 160, 120)
    look = lambda x, name: Camera.look_at((x, 0, 0), (x, 5, 0), K, 160, 120, up=(0, 0, 1), name=name)  # noqa: E731
    renderer = MeshRenderer(world, gl_ctx)
    views = [View(c, renderer.render(c).color) for c in (look(-1.2, "A"), look(0.32, "B"))]
    assert (views[1].image[60, 80] == [255, 0, 0]).all()  # B really is blocked
    return Scene("occluder", views, mesh=world), wall, look(0.0, "virtual")


def test_occluder_does_not_ghost(gl_ctx):
    scene, wall, virtual = _occluder_scene(gl_ctx)
    r = UlrRenderer(scene, scene.mesh, gl_ctx, config=UlrConfig(k=2, fill_holes=False))
    image, covered = r.render(virtual)
    r.release()
    assert covered.mean() > 0.6  # the wall right of centre is seen by B only, through the board
    assert image[covered][:, 0].max() < 10          # no red from the board
    assert image[covered][:, 1].mean() > 190        # the wall's green


def test_without_visibility_the_occluder_ghosts(gl_ctx):
    """Control: with depth maps of the wall alone (no shadow-map test against the board) the
    red board bleeds into the render, so the test above can fail."""
    scene, wall, virtual = _occluder_scene(gl_ctx)
    depths = MeshRenderer(wall, gl_ctx).render_batch(scene.cameras)[1]
    r = UlrRenderer(scene, scene.mesh, gl_ctx, config=UlrConfig(k=2, fill_holes=False), source_depths=depths)
    image, covered = r.render(virtual)
    r.release()
    assert image[covered][:, 0].max() > 100


def test_nearest_source_prefers_close_and_aligned():
    K = intrinsics_from_fov(60, 64, 48)
    cams = [Camera.look_at((x, 0, 0), (x, 5, 0), K, 64, 48) for x in (-1.0, 0.3, 2.0)]
    turned = Camera.look_at((0.25, 0, 0), (5, 0, 0), K, 64, 48)
    assert nearest_source(Camera.look_at((0, 0, 0), (0, 5, 0), K, 64, 48), cams, 5.0) == 1
    assert nearest_source(turned, cams + [Camera.look_at((1, 0, 0), (9, 0, 0), K, 64, 48)], 5.0) == 3
