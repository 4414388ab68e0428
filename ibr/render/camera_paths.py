"""Camera paths for fly-throughs: cameras interpolated between posed views, centres along
straight lines and rotations slerped (scipy), with the first view's intrinsics."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from ibr.camera import Camera, rigid
from ibr.errors import InputError
from ibr.scene import Scene


class CameraPathError(InputError):
    """A path that cannot be flown (fewer than two views)."""


def interpolate_cameras(a: Camera, b: Camera, n: int) -> list[Camera]:
    """n cameras from a to b (b excluded): centres linear, rotations slerped, a's intrinsics."""
    R = Rotation.from_matrix(np.stack([a.world_from_cam[:3, :3], b.world_from_cam[:3, :3]]))
    slerp = Slerp([0.0, 1.0], R)
    cams = []
    for t in np.arange(n) / n:
        world_from_cam = rigid(slerp([t]).as_matrix()[0], (1 - t) * a.center + t * b.center)
        cams.append(a.with_pose(np.linalg.inv(world_from_cam), name=f"{a.name}->{b.name}@{t:.2f}"))
    return cams


def fly_through(scene: Scene, names: list[str], frames_per_segment: int) -> list[Camera]:
    """Cameras along the named views in order (the last one included)."""
    if len(names) < 2:
        raise CameraPathError("--path needs at least two view names")
    views = [scene.view(n).camera for n in names]
    cams = [c for a, b in zip(views, views[1:]) for c in interpolate_cameras(a, b, frames_per_segment)]
    return cams + [views[-1]]
