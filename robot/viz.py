"""Rerun logging for robots: `world/robot` (the true pose of a simulated robot, or the
best pose a real one has), `world/robot/camera` (mount + Pinhole + photo) and sensor plots.
(What only the capture mission logs is `robot.mission.viz`.)"""

from __future__ import annotations

import numpy as np
import rerun as rr

from ibr.camera import Camera
from ibr.viz import log_camera
from robot.protocol import Photo, se2_matrix


def log_robot_pose(pose: np.ndarray, path: str = "world/robot") -> None:
    """SE(2) pose (x, y, theta) as the robot's Transform3D."""
    T = se2_matrix(pose)
    rr.log(path, rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]))


def log_robot_body(radius_m: float, path: str = "world/robot") -> None:
    """The robot's footprint and heading arrow, static in the robot frame."""
    rr.log(f"{path}/body", rr.Boxes3D(half_sizes=[[radius_m, radius_m, 0.05]], centers=[[0, 0, 0.05]],
                                      colors=[[230, 120, 30]]), static=True)
    rr.log(f"{path}/heading", rr.Arrows3D(vectors=[[2 * radius_m, 0, 0]], origins=[[0, 0, 0.1]],
                                          colors=[[230, 120, 30]]), static=True)


def log_photo(photo: Photo, K: np.ndarray, size: tuple[int, int], cam_from_robot: np.ndarray,
              path: str = "world/robot/camera") -> None:
    """The photo in the robot's camera (its pose is the mount, relative to world/robot)."""
    # relative to world/robot, so the "world" of this Camera is the robot frame
    log_camera(path, Camera(K, size[0], size[1], cam_from_robot), photo.image)


def log_sensors(photo: Photo) -> None:
    rr.log("plots/ultrasonic_m", rr.Scalars(photo.range_m))
    rr.log("plots/compass_deg", rr.Scalars(np.degrees(photo.compass_rad)))


def set_time(step: int, sensor_time_s: float | None = None) -> None:
    """The timelines of what is logged next: `step` and, when given, `sensor_time` (seconds)."""
    rr.set_time("step", sequence=step)
    if sensor_time_s is not None:
        rr.set_time("sensor_time", duration=sensor_time_s)
