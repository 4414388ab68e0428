"""Buehler et al.'s sparse blending field (`UlrConfig.blending="field"`) against the per-pixel
ULR on a scene with ground truth, its triangle packing, and the GPU push-pull against numpy."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from ibr.camera import Camera, intrinsics_from_fov
from ibr.mesh_renderer import MeshRenderer
from ibr.render.blending_field import triangle_weights
from ibr.render.eval import psnr
from ibr.render.hole_filling import GLPushPull, push_pull
from ibr.render.ulr import UlrConfig, UlrRenderer, fill_depth_holes
from ibr.scene import Scene, View


@pytest.fixture(scope="module")
def wall_scene(gl_ctx, textured):
    """A textured wall 6 m ahead with a textured box in front of it, photographed by seven
    cameras on an arc (several sources per pixel, occlusion edges), each photo with its own
    exposure (gain 0.7 .. 1.3, so that the blending weights show in the colours), and a
    virtual camera between two of them with its true photo (gain 1)."""
    wall = textured(trimesh.creation.box((10, 0.2, 6)).apply_translation((0, 6, 0)), 1)
    box = textured(trimesh.creation.box((1.0, 1.0, 1.5)).apply_translation((0.3, 3.5, -0.5)), 2)
    world = trimesh.util.concatenate([wall, box])
    K = intrinsics_from_fov(60, 200, 150)
    renderer = MeshRenderer(world, gl_ctx)

    def cam(x, name):
        return Camera.look_at((x, 0.2 * abs(x), 0.3), (0.4 * x, 6, 0), K, 200, 150, name=name)

    xs, gains = np.linspace(-2.4, 2.4, 7), np.linspace(0.7, 1.3, 7)
    views = [View(c, np.clip(renderer.render(c).color * g, 0, 255).astype(np.uint8))
             for c, g in zip((cam(x, f"s{x:.1f}") for x in xs), gains)]
    virtual = cam(0.55, "virtual")
    truth = renderer.render(virtual)
    renderer.release()
    return Scene("wall", views, mesh=world), virtual, truth.color


def test_field_matches_per_pixel_ulr(gl_ctx, wall_scene):
    """Same PSNR against the true photo within 0.3 dB (the issue's bound on Strecha), and
    nearly the same image: the field differs only where interpolated weights differ."""
    scene, virtual, truth = wall_scene
    frames = {}
    for blending in ("field", "pixel"):
        r = UlrRenderer(scene, scene.mesh, gl_ctx, config=UlrConfig(k=3, blending=blending))
        frames[blending] = r.render_frame(virtual)
        r.release()
    f, p = frames["field"], frames["pixel"]
    both = f.covered & p.covered
    assert both.mean() > 0.9 and abs(f.covered.mean() - p.covered.mean()) < 0.01
    assert psnr(p.image, truth, both) > 25.0
    assert abs(psnr(f.image, truth, both) - psnr(p.image, truth, both)) < 0.3
    assert np.abs(f.image.astype(float) - p.image).mean() < 1.5  # measured 0.55


def test_coarse_field_without_vertices_is_worse(gl_ctx, wall_scene):
    """Control: a 2 x 2-cell grid and no vertex samples interpolate the weights across the
    box's edges and the exposures, so the image departs from the per-pixel one (the test
    above can fail)."""
    scene, virtual, truth = wall_scene
    images = []
    for cfg in (UlrConfig(k=3, blending="pixel"), UlrConfig(k=3, field_grid_cells=2, field_vertex_cells=1)):
        r = UlrRenderer(scene, scene.mesh, gl_ctx, config=cfg)
        images.append(r.render_frame(virtual).image.astype(float))
        r.release()
    assert np.abs(images[0] - images[1]).mean() > 3.0  # measured 4.3


def test_triangle_weights_pack_strongest_sources_first():
    weights = np.array([[0.7, 0.3, 0.0, 0.0], [0.0, 0.5, 0.5, 0.0], [0.0, 0.0, 0.0, 1.0], [0, 0, 0, 0]])
    out = triangle_weights(np.array([[0, 1, 2], [0, 1, 3]]), weights, 6)
    assert out.shape == (2, 6, 4)
    np.testing.assert_array_equal(out[0, :, 3], [3, 0, 1, 2, -1, -1])   # by max weight: 1, .7, .5, .5
    np.testing.assert_allclose(out[0, 0, :3], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(out[0, 1, :3], [0.7, 0.0, 0.0])
    np.testing.assert_allclose(out[0, 2, :3], [0.3, 0.5, 0.0])
    np.testing.assert_array_equal(out[1, :, 3], [0, 1, 2, -1, -1, -1])  # vertex 3 has no weights


@pytest.mark.parametrize("size", [(64, 48), (37, 23)])
def test_gl_push_pull_matches_numpy(gl_ctx, size):
    import moderngl

    W, H = size
    rng = np.random.default_rng(W)
    image = rng.integers(0, 256, (H, W, 3)).astype(np.uint8)
    known = rng.random((H, W)) > 0.4
    known[H // 4: H // 2, W // 4: W // 2] = False
    tex = gl_ctx.texture((W, H), 4, np.dstack([image, known * 255]).astype(np.uint8).tobytes())
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    pp = GLPushPull(gl_ctx, (W, H), depth=False)
    out = np.frombuffer(pp.fill(tex).read(), np.uint8).reshape(H, W, 4)
    ref = np.clip(np.round(push_pull(image.astype(float), known)), 0, 255)
    assert np.abs(out[..., :3] - ref).max() <= 1  # float32 rounding
    np.testing.assert_array_equal(out[..., 3], known * 255)
    z = ((rng.random((H, W)) * 5 + 1) * known).astype(np.float32)
    ztex = gl_ctx.texture((W, H), 1, z.tobytes(), dtype="f4")
    ztex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    pd = GLPushPull(gl_ctx, (W, H), depth=True)
    filled = np.frombuffer(pd.fill(ztex).read(), np.float32).reshape(H, W)
    np.testing.assert_allclose(filled, fill_depth_holes(z), rtol=1e-5)
    for obj in (pp, pd, tex, ztex):
        obj.release()
