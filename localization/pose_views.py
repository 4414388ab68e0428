"""Views of many poses at once, as the batched renderer wants them: world -> GL clip
matrices (N, 4, 4) and camera centres (N, 3), built with array operations (no Camera
object per particle). The projection comes from one template `Camera`, the only code
that knows GL's conventions."""

from __future__ import annotations

import numpy as np

from ibr.camera import Camera, rigid


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


def se2_matrix(pose: np.ndarray) -> np.ndarray:
    """4x4 `world_from_robot` of an SE(2) pose (x, y, theta) on the floor (z = 0)."""
    x, y, th = pose
    c, s = np.cos(th), np.sin(th)
    return rigid(np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]), [x, y, 0.0])


def forward_camera_mount(height_m: float, forward_m: float = 0.05,
                         tilt_down_rad: float = 0.0) -> np.ndarray:
    """`cam_from_robot` of a camera `height_m` above the floor, `forward_m` ahead of the
    axle, looking along the robot's x axis, pitched down by `tilt_down_rad`."""
    c, s = np.cos(tilt_down_rad), np.sin(tilt_down_rad)
    # camera axes in robot coordinates: x_cam = -y_robot, z_cam = x_robot pitched down
    z = np.array([c, 0, -s])
    x = np.array([0, -1.0, 0])
    robot_from_cam = rigid(np.stack([x, np.cross(z, x), z], axis=1), [forward_m, 0, height_m])
    return np.linalg.inv(robot_from_cam)


def robot_camera(robot_pose: np.ndarray, K: np.ndarray, size: tuple[int, int],
                 cam_from_robot: np.ndarray, name: str = "") -> Camera:
    """The world `Camera` of a robot at SE(2) pose `robot_pose`."""
    robot_from_world = np.linalg.inv(se2_matrix(robot_pose))
    return Camera(K, size[0], size[1], cam_from_robot @ robot_from_world, name)
