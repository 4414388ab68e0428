"""4-DoF camera poses of the Scenic Route Planner (Mendez et al., Sec. 4.1.1: goal estimation
on a 4-DoF manifold of SE(3), only the yaw sampled): q = (x, y, z, yaw), metres and radians,
world frame z up; the camera looks along yaw, tilted by a fixed pitch (radians, + up).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ibr.camera import Camera, intrinsics_from_fov, rigid


@dataclass(frozen=True)
class CameraModel:
    width: int = 320
    """Image width (pixels)."""
    height: int = 240
    """Image height (pixels)."""
    fov_deg: float = 60.0
    """Horizontal field of view (degrees, the user's unit)."""
    pitch_rad: float = -0.1
    """Fixed camera tilt (radians, positive looks up)."""

    @property
    def K(self) -> np.ndarray:
        return intrinsics_from_fov(self.fov_deg, self.width, self.height)


def world_from_cam_rotations(yaw: np.ndarray, pitch: float) -> np.ndarray:
    """(P, 3, 3) rotations whose columns are the camera's x (right), y (down), z (forward)
    axes in the world, for yaws (P,) radians and a common pitch (radians)."""
    yaw = np.atleast_1d(np.asarray(yaw, float))
    cp, sp = np.cos(pitch), np.sin(pitch)
    z = np.stack([np.cos(yaw) * cp, np.sin(yaw) * cp, np.full_like(yaw, sp)], -1)
    x = np.stack([np.sin(yaw), -np.cos(yaw), np.zeros_like(yaw)], -1)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=-1)


def forward_axes(poses: np.ndarray, pitch: float) -> np.ndarray:
    """(P, 3) unit principal-ray directions of 4-DoF poses (P, 4)."""
    return world_from_cam_rotations(np.asarray(poses)[..., 3], pitch)[..., 2]


def camera_at(q: np.ndarray, model: CameraModel, name: str = "") -> Camera:
    """The pinhole `Camera` of a 4-DoF pose q (4,)."""
    R = world_from_cam_rotations(q[3], model.pitch_rad)[0]
    return Camera(model.K, model.width, model.height, rigid(R.T, -R.T @ np.asarray(q[:3], float)), name)


def pose_distance(a: np.ndarray, b: np.ndarray, yaw_weight_m: float = 1.0) -> np.ndarray:
    """|q_a - q_b| on the 4-DoF manifold: Euclidean in position plus yaw_weight_m metres per
    radian of wrapped yaw difference. Broadcasts over leading axes."""
    dyaw = np.angle(np.exp(1j * (a[..., 3] - b[..., 3])))
    return np.sqrt(np.sum((a[..., :3] - b[..., :3]) ** 2, -1) + (yaw_weight_m * dyaw) ** 2)


def steer(q_near: np.ndarray, q_rand: np.ndarray, step_m: float, yaw_weight_m: float = 1.0) -> np.ndarray:
    """The pose at most step_m (pose distance) from q_near towards q_rand (both (4,))."""
    d = float(pose_distance(q_near, q_rand, yaw_weight_m))
    s = 1.0 if d <= step_m else step_m / d
    dyaw = np.angle(np.exp(1j * (q_rand[3] - q_near[3])))
    out = q_near + s * (q_rand - q_near)
    out[3] = np.angle(np.exp(1j * (q_near[3] + s * dyaw)))
    return out
