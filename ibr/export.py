"""Exports in formats users already have tools for: a COLMAP model folder (COLMAP's GUI,
nerfstudio's `ns-process-data`, hloc) and a mesh file (.ply or .obj, textured or coloured).

A COLMAP export folder holds the model where `pycolmap.Reconstruction(folder)` reads it,
the photos beside it, and the scene's mesh, so `ibr.scene.load_scene(folder)` gives the
scene back (same cameras, same mesh):

    FOLDER/cameras.bin, images.bin, points3D.bin     PINHOLE cameras, poses, points with tracks
    FOLDER/images/NAME.png                           the photos, lossless
    FOLDER/mesh.ply                                  the mesh (proxy or the scene's own)

A capture session's final model (`write_model`, what `ibrnav demo` writes into `model/`) is
the same without `images/`: its photos are the session's `photos/`.

A point's track is every photo that sees it: in front, inside the image, and not hidden by
the mesh (a depth test). Frames: world metres; COLMAP's pixel convention through
`Camera.to_pycolmap`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

from ibr.camera import Camera
from ibr.colmap import observations, to_reconstruction
from ibr.errors import InputError
from ibr.scene import IMAGE_SUFFIXES, MODEL_MESH, Scene

MESH_SUFFIXES = (".ply", ".obj")


class ExportError(InputError):
    """An export that cannot be written (bad file type, a file where a folder should be)."""


def image_file_name(name: str) -> str:
    """The file a view is exported as: `name` when it has an image suffix, else `name.png`."""
    return name if Path(name).suffix.lower() in IMAGE_SUFFIXES else f"{name}.png"


def mesh_depths(mesh: trimesh.Trimesh | None, cameras: list[Camera]) -> list[np.ndarray] | None:
    """Camera-z depth maps (H, W) metres of `mesh` in each camera (0: nothing), None without a mesh."""
    if mesh is None or len(mesh.faces) == 0:
        return None
    from ibr.mesh_renderer import MeshRenderer

    renderer = MeshRenderer(mesh)
    try:
        return [renderer.render(c).depth for c in cameras]
    finally:
        renderer.release()


def reconstruction_of(cameras: list[Camera], names: list[str], points: np.ndarray | None,
                      colors: np.ndarray | None, mesh: trimesh.Trimesh | None):
    """The `pycolmap.Reconstruction` of posed cameras and points, with tracks from
    `ibr.colmap.observations` (depth-tested against `mesh` when given)."""
    seen = None
    if points is not None and len(points):
        seen = observations(cameras, np.asarray(points, float), mesh_depths(mesh, cameras))
    return to_reconstruction(cameras, names, points, colors, seen)


def _check_folder(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise ExportError(f"{out}: a file is there; the COLMAP export is a folder")
    if not out.parent.is_dir():
        raise ExportError(f"{out}: its parent folder {out.parent} does not exist")


def export_colmap(scene: Scene, out: str | Path, mesh: trimesh.Trimesh | None = None,
                  points: np.ndarray | None = None, colors: np.ndarray | None = None) -> Path:
    """Write `scene` as a COLMAP model folder `out` (see the module docstring): its cameras,
    its photos, `points` (N, 3) with `colors` (default the scene's points) and `mesh`
    (default the scene's). Returns `out`."""
    out = Path(out)
    _check_folder(out)
    mesh = scene.mesh if mesh is None else mesh
    points, colors = (scene.points, scene.point_colors) if points is None else (points, colors)
    names = [image_file_name(v.name) for v in scene.views]
    (out / "images").mkdir(parents=True, exist_ok=True)
    for name, view in zip(names, scene.views):
        Image.fromarray(view.image).save(out / "images" / name, **({"quality": 95} if name.lower().endswith(
            (".jpg", ".jpeg")) else {}))
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
    keeps its texture: .obj with its .mtl and the texture image beside it; .ply with texture
    coordinates and the image beside it, named in a `comment TextureFile` header line
    (MeshLab's convention, which trimesh also reads). Otherwise vertex colours go with it."""
    path = Path(path)
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise ExportError(f"{path}: unknown mesh type; use one of {', '.join(MESH_SUFFIXES)}")
    if not path.parent.is_dir():
        raise ExportError(f"{path}: folder {path.parent} does not exist")
    image = getattr(getattr(mesh.visual, "material", None), "image", None)
    if path.suffix.lower() == ".obj":
        mesh.export(path)  # trimesh writes the .mtl and the texture beside it
        return path
    mesh = mesh.copy()
    mesh.vertex_attributes.clear()  # renderer-only attributes (e.g. trust) are not part of the file
    data = trimesh.exchange.ply.export_ply(mesh, encoding="binary")
    if image is not None:
        texture = path.with_name(f"{path.stem}_texture.png")
        image.save(texture)
        data = data.replace(b"\nelement vertex", f"\ncomment TextureFile {texture.name}\nelement vertex".encode(), 1)
    path.write_bytes(data)
    return path
