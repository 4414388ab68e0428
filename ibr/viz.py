"""Rerun logging for ibr: cameras, images, meshes, points, whole scenes. Entity paths follow
docs/ARCHITECTURE.md: `world/cameras/<name>`, `world/map/mesh`, `world/map/points`. (The
rerun command-line set-up every `ibrnav` command shares is `ibrnav.recording`.)"""

from __future__ import annotations

import re

import numpy as np
import rerun as rr
import trimesh

from ibr.camera import Camera


def camera_archetypes(camera: Camera) -> tuple[rr.Pinhole, rr.Transform3D]:
    """The rerun Pinhole (OpenCV axes: RDF) and Transform3D (parent from camera) of `camera`."""
    W = camera.world_from_cam
    pinhole = rr.Pinhole(image_from_camera=camera.K, resolution=[camera.width, camera.height],
                         camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=0.3)
    return pinhole, rr.Transform3D(translation=W[:3, 3], mat3x3=W[:3, :3])


def entity_name(name: str) -> str:
    """A camera/image name made safe as one rerun path component."""
    return re.sub(r"[^A-Za-z0-9_\-]", "_", name) or "camera"


def log_camera(path: str, camera: Camera, image: np.ndarray | None = None,
               static: bool = False) -> None:
    """Pinhole + pose at `path`, and the image in it when given."""
    pinhole, transform = camera_archetypes(camera)
    rr.log(path, transform, static=static)
    rr.log(path, pinhole, static=static)
    if image is not None:
        rr.log(f"{path}/image", rr.Image(image).compress(jpeg_quality=85), static=static)


def log_mesh(path: str, mesh: trimesh.Trimesh, static: bool = True) -> None:
    """A trimesh (textured or vertex-coloured) as rr.Mesh3D."""
    kwargs = {}
    visual = mesh.visual
    if isinstance(visual, trimesh.visual.TextureVisuals) and visual.uv is not None:
        img = getattr(visual.material, "image", None)
        if img is not None:
            uv = np.asarray(visual.uv, dtype=np.float32)
            kwargs = {"vertex_texcoords": np.c_[uv[:, 0], 1 - uv[:, 1]],  # rerun: v down
                      "albedo_texture": np.asarray(img.convert("RGB"))}
    elif visual.kind == "vertex":
        kwargs = {"vertex_colors": visual.vertex_colors}
    rr.log(path, rr.Mesh3D(vertex_positions=mesh.vertices, triangle_indices=mesh.faces,
                           vertex_normals=mesh.vertex_normals, **kwargs), static=static)


def log_points(path: str, points: np.ndarray, colors: np.ndarray | None = None,
               radius: float = 0.01, static: bool = True) -> None:
    rr.log(path, rr.Points3D(points, colors=colors, radii=radius), static=static)


def log_scene(scene, max_image_side: int = 640) -> None:
    """Everything in a `Scene`, static: cameras with images, mesh, points."""
    import cv2

    for view in scene.views:
        img = view.image
        s = max_image_side / max(img.shape[:2])
        cam = view.camera
        if s < 1:
            img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
            cam = cam.scaled(img.shape[1] / cam.width)
        log_camera(f"world/cameras/{entity_name(view.name)}", cam, img, static=True)
    if scene.mesh is not None:
        log_mesh("world/map/mesh", scene.mesh)
    if scene.points is not None and len(scene.points):
        log_points("world/map/points", scene.points, scene.point_colors)
