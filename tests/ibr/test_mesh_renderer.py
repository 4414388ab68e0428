import numpy as np
import trimesh

from ibr.camera import Camera, intrinsics_from_fov
from ibr.mesh_renderer import Light, MeshRenderer


def plane_camera(distance, w=64, h=48):
    """A camera `distance` m in front of the z = 0 plane, looking straight at it."""
    return Camera.look_at([0.1, 0.2, distance], [0.1, 0.2, 0], intrinsics_from_fov(60, w, h), w, h,
                          up=(0, 1, 0))


def test_gbuffer_of_a_plane(gl_ctx):
    plane = trimesh.Trimesh([[-9, -9, 0], [9, -9, 0], [9, 9, 0], [-9, 9, 0]], [[0, 1, 2], [0, 2, 3]])
    g = MeshRenderer(plane, gl_ctx).render(plane_camera(2.5))
    assert g.mask.all()
    np.testing.assert_allclose(g.depth, 2.5, rtol=1e-5)
    np.testing.assert_allclose(g.world[..., 2], 0, atol=1e-5)
    np.testing.assert_allclose(np.abs(g.normal[..., 2]), 1, atol=1e-5)


def test_background_and_mask(gl_ctx):
    box = trimesh.creation.box((0.2, 0.2, 0.2))
    g = MeshRenderer(box, gl_ctx, background=(0, 0, 1)).render(plane_camera(3))
    assert 0 < g.mask.mean() < 0.5
    assert (g.color[~g.mask] == [0, 0, 255]).all()
    assert (g.depth[~g.mask] == 0).all()


def test_batched_views_equal_single_views(gl_ctx, office):
    renderer = office.renderer(gl_ctx)
    cams = [c.scaled(0.1) for c in office.default_cameras(7)]
    colors, depths = renderer.render_batch(cams)
    for c, col, dep in zip(cams, colors, depths):
        g = renderer.render(c)
        diff = np.abs(col.astype(int) - g.color)  # texture-filter rounding: a few levels
        assert diff.max() <= 3 and (diff > 0).mean() < 0.005
        np.testing.assert_allclose(dep, g.depth, rtol=1e-5)


def test_lighting_brightens_towards_the_light_and_highlights_shiny(gl_ctx):
    plane = trimesh.Trimesh([[-9, -9, 0], [9, -9, 0], [9, 9, 0], [-9, 9, 0]], [[0, 1, 2], [0, 2, 3]])
    plane.visual.face_colors = [100, 100, 100, 255]
    cam = plane_camera(2.0, 65, 49)
    dull = MeshRenderer(plane, gl_ctx).render(cam, Light(position=(0.1, 0.2, 1.0))).color
    plane.vertex_attributes["specular"] = np.ones(4)
    shiny = MeshRenderer(plane, gl_ctx).render(cam, Light(position=(0.1, 0.2, 1.0))).color
    centre, corner = dull[24, 32].astype(int), dull[0, 0].astype(int)
    assert (centre > corner).all()
    assert shiny[24, 32].sum() > dull[24, 32].sum()


def test_released_renderer_leaves_the_context_usable(gl_ctx):
    """`release` frees the renderer's framebuffers while one is bound; the next renderer on
    the shared context draws the same picture without a GL error (checked by conftest)."""
    cam = Camera.look_at((0, -5, 0), (0, 0, 0), intrinsics_from_fov(60, 64, 48), 64, 48)
    first = MeshRenderer(trimesh.creation.box(), gl_ctx)
    before = first.render(cam).depth
    first.release()
    np.testing.assert_array_equal(MeshRenderer(trimesh.creation.box(), gl_ctx).render(cam).depth, before)
