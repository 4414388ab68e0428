"""Views of many poses at once, as the batched renderer wants them: world -> GL clip
matrices (N, 4, 4) and camera centres (N, 3), built with array operations (no Camera
object per particle). The projection comes from one template `Camera`, the only code
that knows GL's conventions."""

from __future__ import annotations

import numpy as np

from ibr.camera import Camera


def se2_robot_from_world(poses: np.ndarray) -> np.ndarray:
    """(N, 4, 4) robot_from_world of SE(2) poses (N, 3) (x, y, theta) on the floor."""
    x, y, th = np.asarray(poses, dtype=np.float64).T
    c, s = np.cos(th), np.sin(th)
    T = np.zeros((len(c), 4, 4))
    T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = c, s, -s, c
    T[:, 2, 2] = T[:, 3, 3] = 1.0
    T[:, 0, 3] = -(c * x + s * y)
    T[:, 1, 3] = s * x - c * y
    return T


def se2_views(poses: np.ndarray, template: Camera, cam_from_robot: np.ndarray,
              near: float = 0.05, far: float = 1000.0) -> tuple[np.ndarray, np.ndarray]:
    """Clip matrices (N, 4, 4) and centres (N, 3) of a robot camera (intrinsics and size of
    `template`, mount `cam_from_robot`) at SE(2) poses (N, 3)."""
    cam_from_world = cam_from_robot @ se2_robot_from_world(poses)
    clip = template.gl_projection(near, far) @ cam_from_world
    R, t = cam_from_world[:, :3, :3], cam_from_world[:, :3, 3]
    centres = -np.einsum("nji,nj->ni", R, t)
    return clip, centres
