"""Exports in formats users already have tools for: a COLMAP model folder (COLMAP's GUI,
nerfstudio's `ns-process-data`, hloc) and a mesh file (.ply or .obj, textured or coloured).

A COLMAP export folder holds the model where `pycolmap.Reconstruction(folder)` reads it,
the photos beside it, and the scene's mesh, so `ibr.scene.load_scene(folder)` gives the
scene back (same cameras, same mesh):

    FOLDER/cameras.bin, images.bin, points3D.bin     PINHOLE cameras, poses, points with tracks
    FOLDER/images/NAME                               the photos, lossless (copied, or PNG)
    FOLDER/mesh.ply                                  the mesh (proxy or the scene's own)

A capture session's final model (`write_model`, what `ibrnav demo` writes into `model/`) is
the same without `images/`: its photos are the session's `photos/`.

A point's track is every photo that sees it: in front, inside the image, and not hidden by
the mesh (a depth test). Frames: world metres; COLMAP's pixel convention through
`Camera.to_pycolmap`.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

from ibr.camera import Camera
from ibr.colmap import observations, to_reconstruction
from ibr.errors import InputError
from ibr.scene import IMAGE_SUFFIXES, MODEL_MESH, Scene, SceneError, read_image

MESH_SUFFIXES = (".ply", ".obj")


class ExportError(InputError):
    """An export that cannot be written (bad file type, a file where a folder should be)."""


def image_file_name(name: str) -> str:
    """The file a view is exported as: `name` when it has an image suffix, else `name.png`."""
    return name if Path(name).suffix.lower() in IMAGE_SUFFIXES else f"{name}.png"


def reconstruction_of(cameras: list[Camera], names: list[str], points: np.ndarray | None,
                      colors: np.ndarray | None, mesh: trimesh.Trimesh | None):
    """The `pycolmap.Reconstruction` of posed cameras and points, with tracks from
    `ibr.colmap.observations` (depth-tested against `mesh`, rendered per camera, when given)."""
    seen = None
    if points is not None and len(points):
        renderer = None
        if mesh is not None and len(mesh.faces):
            from ibr.mesh_renderer import MeshRenderer

            renderer = MeshRenderer(mesh)
        try:
            depth_of = (lambda n: renderer.render(cameras[n]).depth) if renderer is not None else None
            seen = observations(cameras, np.asarray(points, float), depth_of)
        finally:
            if renderer is not None:
                renderer.release()
    return to_reconstruction(cameras, names, points, colors, seen)


def _check_folder(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise ExportError(f"{out}: a file is there; the COLMAP export is a folder")
    if not out.parent.is_dir():
        raise ExportError(f"{out}: its parent folder {out.parent} does not exist")


def write_photo(view, folder: Path) -> str:
    """Write a view's photo into `folder` without loss; returns its file name. The original
    file is copied when it decodes to the view's pixels (e.g. a Strecha JPEG); otherwise
    (an undistorted or synthetic photo) it is written as PNG."""
    name = image_file_name(view.name)
    src = view.path
    if src is not None and Path(src).is_file() and Path(src).suffix.lower() == Path(name).suffix.lower():
        try:
            same = np.array_equal(read_image(src), view.image)
        except SceneError:
            same = False
        if same:
            shutil.copyfile(src, folder / name)
            return name
    name = f"{Path(name).stem}.png"
    Image.fromarray(view.image).save(folder / name)
    return name


def export_colmap(scene: Scene, out: str | Path, mesh: trimesh.Trimesh | None = None,
                  points: np.ndarray | None = None, colors: np.ndarray | None = None) -> Path:
    """Write `scene` as a COLMAP model folder `out` (see the module docstring): its cameras,
    its photos, `points` (N, 3) with `colors` (default the scene's points) and `mesh`
    (default the scene's). Returns `out`."""
    out = Path(out)
    _check_folder(out)
    mesh = scene.mesh if mesh is None else mesh
    points, colors = (scene.points, scene.point_colors) if points is None else (points, colors)
    (out / "images").mkdir(parents=True, exist_ok=True)
    names = [write_photo(view, out / "images") for view in scene.views]
    reconstruction_of(scene.cameras, names, points, colors, mesh).write(str(out))
    if mesh is not None:
        export_mesh(mesh, out / MODEL_MESH)
    return out


def write_model(folder: str | Path, cameras: list[Camera], mesh: trimesh.Trimesh | None,
                points: np.ndarray | None = None, colors: np.ndarray | None = None) -> Path:
    """A capture session's final model into `folder/model`: COLMAP model of `cameras` (named
    after their photos, `NAME.png` in the session's `photos/`), `points`, and `mesh.ply`."""
    out = Path(folder) / "model"
    out.mkdir(exist_ok=True)
    names = [image_file_name(c.name) for c in cameras]
    reconstruction_of(cameras, names, points, colors, mesh).write(str(out))
    if mesh is not None:
        export_mesh(mesh, out / MODEL_MESH)
    return out


def export_mesh(mesh: trimesh.Trimesh, path: str | Path) -> Path:
    """Write `mesh` as .ply or .obj. A textured mesh (trimesh `TextureVisuals` with an image)
    keeps its texture: .obj with `STEM.mtl` and `STEM.png` beside it; .ply with texture
    coordinates and the image beside it, named in a `comment TextureFile` header line
    (MeshLab's convention, which trimesh also reads). Otherwise vertex colours go with it."""
    path = Path(path)
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise ExportError(f"{path}: unknown mesh type; use one of {', '.join(MESH_SUFFIXES)}")
    if not path.parent.is_dir():
        raise ExportError(f"{path}: folder {path.parent} does not exist")
    image = getattr(getattr(mesh.visual, "material", None), "image", None)
    mesh = mesh.copy()
    if path.suffix.lower() == ".obj":
        if image is not None:  # the .mtl and the texture beside it, named after the file
            mesh.visual.material.name = path.stem
        text, files = trimesh.exchange.obj.export_obj(mesh, return_texture=True, mtl_name=f"{path.stem}.mtl")
        path.write_text(text)
        for name, data in files.items():
            (path.parent / name).write_bytes(data)
        return path
    mesh.vertex_attributes.clear()  # renderer-only attributes (e.g. trust) are not part of the file
    data = trimesh.exchange.ply.export_ply(mesh, encoding="binary")
    if image is not None:
        texture = path.with_name(f"{path.stem}_texture.png")
        image.save(texture)
        data = data.replace(b"\nelement vertex", f"\ncomment TextureFile {texture.name}\nelement vertex".encode(), 1)
    path.write_bytes(data)
    return path
