import numpy as np
import pytest
import trimesh

from ibr.camera import Camera, CameraError, intrinsics_from_fov, rigid
from ibr.mesh_renderer import MeshRenderer


def random_camera(rng, w=160, h=120, target=(0, 0, 0)):
    eye = rng.uniform(-1, 1, 3)
    eye = 3.0 * eye / np.linalg.norm(eye)
    K = intrinsics_from_fov(rng.uniform(40, 80), w, h)
    K[0, 2] += rng.uniform(-5, 5)
    K[1, 1] *= rng.uniform(0.95, 1.05)
    return Camera.look_at(eye, np.asarray(target) + rng.normal(0, 0.1, 3), K, w, h)


def test_project_unproject_roundtrip():
    rng = np.random.default_rng(0)
    cam = random_camera(rng)
    uv = rng.uniform(0, 100, (50, 2))
    d = rng.uniform(0.5, 5, 50)
    uv2, d2 = cam.project(cam.unproject(uv, d))
    np.testing.assert_allclose(uv2, uv, atol=1e-9)
    np.testing.assert_allclose(d2, d, atol=1e-9)


def test_look_at_points_optical_axis_at_target_with_image_up_along_z():
    K = intrinsics_from_fov(60, 64, 48)
    cam = Camera.look_at([4, 1, 2], [0, 1, 1], K, 64, 48)
    np.testing.assert_allclose(cam.center, [4, 1, 2])
    uv, z = cam.project(np.array([[0, 1, 1.0], [0, 1, 2.0]]))
    np.testing.assert_allclose(uv[0], K[:2, 2], atol=1e-9)
    assert uv[1, 1] < uv[0, 1]  # higher in the world is higher (smaller v) in the image
    assert z[0] == pytest.approx(np.sqrt(17))


def test_scaled_camera_sees_points_at_scaled_pixels():
    rng = np.random.default_rng(1)
    cam = random_camera(rng, 640, 480)
    small = cam.scaled(0.25)
    assert (small.width, small.height) == (160, 120)
    p = rng.normal(0, 0.3, (20, 3))
    uv, _ = cam.project(p)
    uv_s, _ = small.project(p)
    np.testing.assert_allclose(uv_s, 0.25 * (uv + 0.5) - 0.5, atol=1e-9)


def test_strecha_text_roundtrip(tmp_path):
    cam = random_camera(np.random.default_rng(2))
    f = tmp_path / "x.jpg.camera"
    f.write_text(cam.to_strecha_text())
    back = Camera.from_strecha_file(f)
    np.testing.assert_allclose(back.K, cam.K, atol=1e-9)
    np.testing.assert_allclose(back.cam_from_world, cam.cam_from_world, atol=1e-9)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_pose_is_rejected(bad):
    T = np.eye(4)
    T[0, 3] = bad
    with pytest.raises(CameraError, match="NaN or infinite"):
        Camera(np.eye(3), 10, 10, T, "cam7")


def test_non_rotation_is_rejected():
    with pytest.raises(CameraError, match="not a rotation"):
        Camera(np.eye(3), 10, 10, rigid(2 * np.eye(3), [0, 0, 0]))


def test_gl_render_lands_where_project_says(gl_ctx):
    """Each covered pixel's rendered world point projects back onto that pixel's centre."""
    rng = np.random.default_rng(3)
    box = trimesh.creation.box((1.5, 1.0, 0.8))
    renderer = MeshRenderer(box, gl_ctx)
    for _ in range(5):
        cam = random_camera(rng)
        g = renderer.render(cam)
        assert g.mask.sum() > 200
        v, u = np.nonzero(g.mask)
        uv, z = cam.project(g.world[v, u])
        err = np.linalg.norm(uv - np.c_[u, v], axis=1)
        assert err.max() < 0.5, err.max()
        np.testing.assert_allclose(g.depth[v, u], z, rtol=1e-4)


def test_gl_point_lands_on_projected_pixel(gl_ctx):
    """A square 1.2 px across centred on a 3-D point covers exactly the pixel centres within
    0.6 px of where Camera.project puts the point, the nearest one among them."""
    rng = np.random.default_rng(4)
    for _ in range(10):
        cam = random_camera(rng)
        p = rng.normal(0, 0.3, 3)
        uv, z = cam.project(p[None])
        r = 0.6 * z[0] / cam.K[0, 0]  # 0.6 px at the point's depth
        x, y = cam.world_from_cam[:3, 0], cam.world_from_cam[:3, 1]
        corners = [p - r * x - r * y, p + r * x - r * y, p + r * x + r * y, p - r * x + r * y]
        quad = trimesh.Trimesh(corners, [[0, 1, 2], [0, 2, 3]], process=False)
        hit = np.argwhere(MeshRenderer(quad, gl_ctx).render(cam).mask)[:, ::-1]  # (u, v)
        assert np.abs(hit - uv[0]).max() < 0.61
        assert np.round(uv[0]).astype(int).tolist() in hit.tolist()
