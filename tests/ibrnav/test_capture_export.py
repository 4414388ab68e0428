"""A capture folder is a scene, and scenes export: a robot's session folder (written here by
`robot.session` from photos of the synthetic office, with a map like the mission's) loads
with `load_scene` with and without its final model, every command that takes SCENE runs on
it, and `ibrnav export` writes a COLMAP model and a mesh that load back unchanged."""

from __future__ import annotations

import io
import json
import shutil

import numpy as np
import pycolmap
import pytest
import trimesh

from ibr.camera import intrinsics_from_fov
from ibr.errors import InputError
from ibr.export import export_colmap, export_mesh
from ibr.scene import SceneError, load_scene
from robot.protocol import Photo, forward_camera_mount, robot_camera
from robot.session import CaptureSession, load_session_scene

SIZE = (160, 120)


def _poses(stops: int = 4) -> np.ndarray:
    """Robot poses along one wall of the office's loop, three headings per stop."""
    xs = np.linspace(-1.5, 1.5, stops)
    return np.array([(x, -2.5, np.pi / 2 + dh) for x in xs for dh in (-0.35, 0.0, 0.35)])


@pytest.fixture(scope="module")
def session(tmp_path_factory, office, gl_ctx):
    """A session folder: photos of the office at logged poses and a map file like the
    mission's (`maps/round_00.npz`: the true mesh and points on it)."""
    folder = tmp_path_factory.mktemp("capture") / "session"
    K, mount = intrinsics_from_fov(70, *SIZE), forward_camera_mount(1.0)
    poses = _poses()
    with CaptureSession.create(folder, K, SIZE, mount, {"test": 1}) as s:
        for i, pose in enumerate(poses):
            cam = robot_camera(pose, K, SIZE, mount)
            s.add_photo(Photo(office.photograph(cam), float(i), pose, pose[2], 1.0, i), pose=pose)
    points = trimesh.sample.sample_surface_even(office.mesh, 800, seed=1)[0]
    buf = io.BytesIO()
    np.savez(buf, points=points, colors=np.full((len(points), 3), 200, np.uint8), vertices=office.mesh.vertices,
             faces=office.mesh.faces)
    (folder / "maps").mkdir()
    (folder / "maps" / "round_00.npz").write_bytes(buf.getvalue())
    return folder, [robot_camera(p, K, SIZE, mount) for p in poses]


def test_session_without_model_is_a_scene_at_the_logged_poses(session, office):
    folder, cams = session
    scene = load_scene(folder)
    assert scene.meta["poses"] == "filter" and scene.meta["map"] == "round_00.npz"
    assert [v.name for v in scene] == [f"photo_{i:05d}" for i in range(len(cams))]
    for v, c in zip(scene, cams):
        np.testing.assert_allclose(v.camera.cam_from_world, c.cam_from_world, atol=1e-9)
    np.testing.assert_allclose(scene.mesh.vertices, office.mesh.vertices)
    assert len(scene.points) == 800


def test_session_with_model_loads_the_model(session, tmp_path):
    folder, cams = session
    copy = tmp_path / "with_model"
    shutil.copytree(folder, copy)
    moved = [c.with_pose(np.r_[c.cam_from_world[:3] + np.c_[np.zeros((3, 3)), [0.01 * i, 0, 0]], [[0, 0, 0, 1]]],
                         name=f"photo_{i:05d}") for i, c in enumerate(cams)]  # model poses differ from the log
    scene = load_scene(folder)
    with CaptureSession.open(copy) as s:
        s.write_model(moved[:-1], scene.mesh, scene.points, scene.point_colors)  # last photo not in the model
    loaded = load_scene(copy)
    assert loaded.meta["poses"] == "model"
    assert len(load_session_scene(copy)) == len(cams)  # the raw session: every photo at its logged pose
    assert [v.name for v in loaded] == [c.name for c in moved[:-1]]
    for v, c in zip(loaded, moved):
        np.testing.assert_allclose(v.camera.K, c.K, atol=1e-6)
        np.testing.assert_allclose(v.camera.cam_from_world, c.cam_from_world, atol=1e-6)
    np.testing.assert_allclose(loaded.mesh.vertices, scene.mesh.vertices, atol=1e-6)
    assert np.array_equal(loaded.mesh.faces, scene.mesh.faces)
    assert 0 < len(loaded.points) <= 800  # points no photo sees are no COLMAP points


def test_colmap_export_round_trip(session, tmp_path):
    folder, _ = session
    scene = load_scene(folder)
    out = export_colmap(scene, tmp_path / "colmap")
    rec = pycolmap.Reconstruction(str(out))
    assert rec.num_reg_images() == len(scene) and rec.num_points3D() > 100
    assert rec.compute_mean_reprojection_error() < 1e-6  # keypoints are the points' projections
    back = load_scene(out)
    assert [v.name for v in back] == [f"{v.name}.png" for v in scene]
    for a, b in zip(back, scene):
        np.testing.assert_allclose(a.camera.K, b.camera.K, atol=1e-6)
        np.testing.assert_allclose(a.camera.cam_from_world, b.camera.cam_from_world, atol=1e-6)
        assert np.array_equal(a.image, b.image)
    np.testing.assert_allclose(back.mesh.vertices, scene.mesh.vertices, atol=1e-6)
    assert np.array_equal(back.mesh.faces, scene.mesh.faces)


def test_pycolmap_projects_where_ibrnav_does_plus_half_a_pixel(session):
    """COLMAP's pixel (0, 0) is the top-left pixel's corner, ibrnav's its centre."""
    _, cams = session
    cam = cams[0]
    xyz = cam.center + 2.0 * cam.forward + np.array([0.3, -0.2, 0.1])
    uv, _ = cam.project(xyz[None])
    colmap_uv = cam.to_pycolmap().img_from_cam(cam.to_camera_frame(xyz[None])[0])
    np.testing.assert_allclose(colmap_uv, uv[0] + 0.5, atol=1e-9)


@pytest.mark.parametrize("suffix", [".ply", ".obj"])
def test_mesh_export_textured_and_plain(tmp_path, suffix, gl_ctx):
    box = trimesh.creation.box((1.0, 2.0, 0.5))
    plain = export_mesh(box, tmp_path / f"plain{suffix}")
    back = trimesh.load(plain, process=False, force="mesh")
    np.testing.assert_allclose(np.unique(back.vertices, axis=0), np.unique(box.vertices, axis=0), atol=1e-6)
    atlas = np.zeros((8, 8, 3), np.uint8)
    atlas[:, 4:] = 255
    from PIL import Image

    uv = np.c_[(box.vertices[:, 0] > 0) * 0.9 + 0.05, np.full(len(box.vertices), 0.5)]
    tex = box.copy()
    tex.visual = trimesh.visual.TextureVisuals(uv=uv, image=Image.fromarray(atlas))
    back = trimesh.load(export_mesh(tex, tmp_path / f"tex{suffix}"), process=False, force="mesh")
    assert (tmp_path / ("tex.png" if suffix == ".obj" else "tex_texture.png")).is_file()  # named after the file
    assert isinstance(back.visual, trimesh.visual.TextureVisuals)
    colors = back.visual.to_color().vertex_colors[:, :3]  # the texture read back at each vertex
    white = back.vertices[:, 0] > 0
    assert (colors[white] == 255).all() and (colors[~white] == 0).all()


def test_commands_run_on_a_capture_folder(session, tmp_path, ibrnav_command, capsys):
    folder, _ = session
    assert ibrnav_command("render", folder, "--proxy", "mesh", "--from-view", "photo_00004", "--hold-out",
                          "--out", tmp_path / "r.png") == 0
    assert (tmp_path / "r.png").is_file()
    assert ibrnav_command("eval-ibr", folder, "--json", tmp_path / "e.json", "--proxy", "mesh", "--max-views", 1,
                          "--methods", "nearest") == 0
    assert json.loads((tmp_path / "e.json").read_text())["methods"]["nearest"]["psnr_mean"] > 15
    capsys.readouterr()
    assert ibrnav_command("export", folder, "--colmap", tmp_path / "c", "--mesh", tmp_path / "m.obj") == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["views"] == 12 and summary["textured"] and (tmp_path / "m.obj").is_file()
    assert pycolmap.Reconstruction(str(tmp_path / "c")).num_reg_images() == 12
    assert ibrnav_command("scene", "show", folder, "--save", tmp_path / "s.rrd") == 0


def test_localize_pnp_on_a_capture_folder(session, tmp_path, ibrnav_command, capsys, caplog):
    folder, cams = session
    caplog.set_level("INFO")
    rc = ibrnav_command("localize", folder, "--query", folder / "photos" / "photo_00004.png", "--method", "pnp",
                        "--save", tmp_path / "l.rrd")
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["method"] == "pnp" and out["localized"]
    assert "pnp map from 11 photos" in caplog.text  # the query, one of the session's photos, is left out
    spacing = np.linalg.norm(cams[3].center - cams[0].center)  # between neighbouring stops
    assert np.linalg.norm(np.array(out["center_m"]) - cams[4].center) < 0.05 * spacing  # left out of the map


def test_neither_scene_nor_session_is_named(tmp_path):
    (tmp_path / "photos").mkdir()
    with pytest.raises(SceneError, match=f"{tmp_path}: not a scene folder.*capture folder"):
        load_scene(tmp_path)
    (tmp_path / "session.json").write_text("{not json")
    with pytest.raises(InputError, match="session.json: corrupt"):
        load_scene(tmp_path)


def test_colmap_export_copies_jpeg_photos_unchanged(tmp_path):
    """A Strecha folder's JPEGs go into the export as they are (re-encoding would change them)."""
    from PIL import Image

    from ibr.camera import Camera

    K = intrinsics_from_fov(60, 64, 48)
    rng = np.random.default_rng(2)
    for d in ("images", "cameras"):
        (tmp_path / "s" / d).mkdir(parents=True)
    for i in range(3):
        cam = Camera.look_at([i, -3, 1], [i, 0, 1], K, 64, 48, name=f"{i:04d}.jpg")
        Image.fromarray(rng.integers(0, 255, (48, 64, 3), dtype=np.uint8)).save(tmp_path / "s" / "images" / cam.name)
        (tmp_path / "s" / "cameras" / f"{cam.name}.camera").write_text(cam.to_strecha_text())
    scene = load_scene(tmp_path / "s")
    out = export_colmap(scene, tmp_path / "c")
    for v in scene:
        assert (out / "images" / v.name).read_bytes() == v.path.read_bytes()
    back = load_scene(out)
    assert [v.name for v in back] == [v.name for v in scene]
    assert all(np.array_equal(a.image, b.image) for a, b in zip(back, scene))
    assert back.mesh is None and len(back.points) == 0  # no mesh, no points given: none written


def test_export_refine_reports_how_far_the_poses_moved(session, tmp_path, ibrnav_command, capsys):
    folder, cams = session
    assert ibrnav_command("export", folder, "--refine", "--colmap", tmp_path / "c") == 0
    summary = json.loads(capsys.readouterr().out)
    report = summary["refinement"]
    assert summary["poses"] == "filter + refined" and report["cameras"] == len(cams)
    exported = load_scene(tmp_path / "c")
    moved = [np.linalg.norm(v.camera.center - c.center) for v, c in zip(exported, cams)]
    assert max(moved) == pytest.approx(report["moved_m_max"], abs=1e-6)  # the export holds the refined poses
    spacing = np.linalg.norm(cams[3].center - cams[0].center)
    assert report["moved_m_max"] < 0.05 * spacing  # the logged poses were exact: little to move
