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
    """(Trilinear: the anisotropic filter's tap count is a step function of the uv
    derivatives, which the two paths round differently at a few pixels.)"""
    renderer = office.renderer(gl_ctx)
    cams = [c.scaled(0.1) for c in office.default_cameras(7)]
    renderer.anisotropy = 1.0
    try:
        colors, depths = renderer.render_batch(cams)
        for c, col, dep in zip(cams, colors, depths):
            g = renderer.render(c)
            diff = np.abs(col.astype(int) - g.color)  # texture-filter rounding: a few levels
            assert diff.max() <= 3 and (diff > 0).mean() < 0.005
            np.testing.assert_allclose(dep, g.depth, rtol=1e-5)
    finally:
        renderer.anisotropy = 8.0


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


def striped_floor() -> trimesh.Trimesh:
    """A 20 x 20 m floor at z = 0 textured with 1-texel (1 cm) stripes across x (a 2048 x 2048 image)."""
    stripes = np.zeros((2048, 2048, 3), np.uint8)
    stripes[:, ::2] = 255
    floor = trimesh.Trimesh([[-10, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0]], [[0, 1, 2], [0, 2, 3]],
                            process=False)
    floor.visual = trimesh.visual.TextureVisuals(uv=[[0, 0], [1, 0], [1, 1], [0, 1]],
                                                 image=__import__("PIL").Image.fromarray(stripes))
    return floor


def test_the_anisotropic_filter_keeps_detail_a_trilinear_one_blurs(gl_ctx):
    """A floor seen at a grazing angle, its stripes running away from the camera: the
    footprint of a pixel is long along the view and narrow across it, so trilinear sampling
    (the mip level of the long axis) greys the stripes out while the anisotropic filter
    (`MeshRenderer.anisotropy`, the shader's taps along the long axis) keeps them: 3 m
    ahead a pixel spans ~1 texel across and ~8 along."""
    cam = Camera.look_at([0.0, -3.0, 0.4], [0.0, 3.0, 0.0], intrinsics_from_fov(60, 320, 240), 320, 240)
    renderer = MeshRenderer(striped_floor(), gl_ctx)
    contrast = {}
    for taps in (1.0, 8.0):
        renderer.anisotropy = taps
        g = renderer.render(cam)
        band = g.color[150:170, 100:220, 0].astype(float)  # the floor a few metres ahead
        contrast[taps] = np.abs(np.diff(band, axis=1)).mean()
    assert contrast[8.0] > 2 * contrast[1.0], contrast


def test_a_view_that_stalled_llvmpipe_renders_in_seconds():
    """A capture mission's photo (apartment seed 8, looking down the corridor) that GL's own
    anisotropic sampler did not finish in 10 minutes on llvmpipe. Rendered in a child
    process, so a regression fails on the timeout instead of hanging the suite."""
    import subprocess
    import sys

    code = (
        "import numpy as np\n"
        "from ibr.synthetic import WORLDS\n"
        "from robot.protocol import forward_camera_mount, robot_camera\n"
        "from ibr.camera import intrinsics_from_fov\n"
        "pose = np.array([1.5177320953658036, 0.09373033363095533, -2.930092867599994])\n"
        "cam = robot_camera(pose, intrinsics_from_fov(60.0, 320, 240), (320, 240), forward_camera_mount(0.4))\n"
        "img = WORLDS['apartment'](seed=8).photograph(cam)\n"
        "assert img.shape == (240, 320, 3) and img.std() > 1\n"
    )
    done = subprocess.run([sys.executable, "-c", code], timeout=120, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
