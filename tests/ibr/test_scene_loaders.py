import shutil

import numpy as np
import pycolmap
import pytest
from PIL import Image

from ibr.camera import Camera, intrinsics_from_fov
from ibr.scene import SceneError, load_colmap, load_scene


def write_strecha(folder, cameras, images):
    (folder / "images").mkdir(parents=True)
    (folder / "cameras").mkdir()
    for cam, img in zip(cameras, images):
        Image.fromarray(img).save(folder / "images" / cam.name)
        (folder / "cameras" / f"{cam.name}.camera").write_text(cam.to_strecha_text())


@pytest.fixture
def strecha_folder(tmp_path):
    rng = np.random.default_rng(0)
    K = intrinsics_from_fov(60, 64, 48)
    cams = [Camera.look_at([i, -3, 1], [i, 0, 1], K, 64, 48, name=f"{i:04d}.png") for i in range(3)]
    imgs = [rng.integers(0, 255, (48, 64, 3), dtype=np.uint8) for _ in cams]
    write_strecha(tmp_path / "s", cams, imgs)
    return tmp_path / "s", cams, imgs


def test_strecha_folder_loads(strecha_folder):
    folder, cams, imgs = strecha_folder
    scene = load_scene(folder)
    assert [v.name for v in scene] == [c.name for c in cams]
    np.testing.assert_array_equal(scene.views[1].image, imgs[1])
    np.testing.assert_allclose(scene.views[2].camera.cam_from_world, cams[2].cam_from_world, atol=1e-9)


def test_missing_camera_file_is_named(strecha_folder):
    folder, cams, _ = strecha_folder
    (folder / "cameras" / "0001.png.camera").unlink()
    with pytest.raises(SceneError, match=r"0001\.png\.camera: camera file missing"):
        load_scene(folder)


def test_truncated_image_is_named(strecha_folder, tmp_path):
    folder, cams, imgs = strecha_folder
    jpg = folder / "images" / "0002.png"
    data = jpg.read_bytes()
    jpg.write_bytes(data[: len(data) // 2])
    with pytest.raises(SceneError, match=r"0002\.png: unreadable or truncated"):
        load_scene(folder)


def test_garbage_image_is_named(strecha_folder):
    folder, _, _ = strecha_folder
    (folder / "images" / "0000.png").write_bytes(b"not an image at all")
    with pytest.raises(SceneError, match=r"0000\.png: unreadable or truncated"):
        load_scene(folder)


def test_size_mismatch_is_named(strecha_folder):
    folder, _, _ = strecha_folder
    Image.fromarray(np.zeros((40, 60, 3), np.uint8)).save(folder / "images" / "0001.png")
    with pytest.raises(SceneError, match=r"0001\.png: image is 60x40 but its camera says 64x48"):
        load_scene(folder)


def test_nan_pose_is_named(strecha_folder):
    folder, _, _ = strecha_folder
    f = folder / "cameras" / "0002.png.camera"
    rows = f.read_text().splitlines()
    rows[7] = "nan 0 1"
    f.write_text("\n".join(rows))
    with pytest.raises(SceneError, match=r"0002\.png\.camera: .*NaN"):
        load_scene(folder)


def test_not_a_scene_and_missing_folder(tmp_path):
    with pytest.raises(SceneError, match="no such scene folder"):
        load_scene(tmp_path / "nope")
    with pytest.raises(SceneError, match="not a scene folder"):
        load_scene(tmp_path)
    with pytest.raises(SceneError, match="synthetic:NAME"):
        load_scene("synthetic:moon")


def test_colmap_model_roundtrip(tmp_path, strecha_folder):
    """A model written by pycolmap (with distortion-free and radial cameras) loads back
    with the same cameras and points."""
    folder, cams, imgs = strecha_folder
    rec = pycolmap.Reconstruction()
    K = cams[0].K
    # COLMAP's principal point is half a pixel further (pixel (0, 0) is a corner there)
    rec.add_camera_with_trivial_rig(pycolmap.Camera(
        model="PINHOLE", width=64, height=48, params=[K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5],
        camera_id=1))
    for i, cam in enumerate(cams, start=1):
        image = pycolmap.Image(name=cam.name, camera_id=1, image_id=i)
        rec.add_image_with_trivial_frame(image, pycolmap.Rigid3d(cam.cam_from_world[:3, :]))
    pts = np.random.default_rng(1).normal(0, 1, (10, 3))
    for p in pts:
        rec.add_point3D(p, pycolmap.Track(), np.array([10, 20, 30], np.uint8))
    model = tmp_path / "colmap" / "sparse" / "0"
    model.mkdir(parents=True)
    rec.write(str(model))
    shutil.copytree(folder / "images", tmp_path / "colmap" / "images")
    scene = load_scene(tmp_path / "colmap")
    assert [v.name for v in scene] == [c.name for c in cams]
    for v, c in zip(scene, cams):
        np.testing.assert_allclose(v.camera.K, c.K, atol=1e-6)
        np.testing.assert_allclose(v.camera.cam_from_world, c.cam_from_world, atol=1e-6)
    np.testing.assert_array_equal(scene.views[0].image, imgs[0])
    assert sorted(map(tuple, np.round(scene.points, 6))) == sorted(map(tuple, np.round(pts, 6)))
    assert (scene.point_colors == [10, 20, 30]).all()


def test_colmap_without_images_is_named(tmp_path):
    model = tmp_path / "m"
    model.mkdir()
    rec = pycolmap.Reconstruction()
    rec.write(str(model))
    with pytest.raises(SceneError, match="no images/ folder"):
        load_colmap(model)


def test_synthetic_spec(gl_ctx):
    scene = load_scene("synthetic:office?seed=2&views=3&width=64&height=48")
    assert len(scene) == 3 and scene.mesh is not None
    assert scene.views[0].image.shape == (48, 64, 3)
    assert scene.world.seed == 2


def test_parse_scene_spec_is_the_one_reader_of_scene():
    from ibr.scene import parse_scene_spec

    spec = parse_scene_spec("synthetic:office?seed=3&views=5")
    assert (spec.world, spec.params, spec.path) == ("office", {"seed": 3, "views": 5}, None)
    assert spec.seed(7) == 3 and parse_scene_spec("synthetic:courtyard").seed(7) == 7
    assert parse_scene_spec("some/folder").path.name == "folder"
    for bad, match in [("synthetic:nosuch?seed=3", "nosuch"), ("synthetic:office?seed=x", "bad query"),
                       ("synthetic:office?color=1", "color")]:
        with pytest.raises(SceneError, match=match):
            parse_scene_spec(bad)
    with pytest.raises(SceneError, match="views"):
        parse_scene_spec("synthetic:office?views=3", allowed=("seed",))
    with pytest.raises(SceneError, match="needs a synthetic world"):
        parse_scene_spec("some/folder", synthetic_only=True)
