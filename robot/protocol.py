"""The `Robot` protocol every body implements (the simulator, the NXT over a serial port).

Frames: the robot frame has x forward, y left, z up, origin on the floor between the
wheels; a robot pose is SE(2) (x, y, theta) of that frame in the world (metres, radians).
The camera is fixed on the robot: `cam_from_robot` (4x4) is the mount transform.
Odometry poses live in the robot's own odometry frame (where it started), not the world.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from ibr.errors import InputError
from localization.pose_views import forward_camera_mount, robot_camera, se2_matrix  # noqa: F401  (re-exported: the
# geometry of a robot pose and its camera mount lives below the robot package, for the filters)


@dataclass(frozen=True)
class MotionResult:
    """What a drive or turn command reports. odometry_delta: (3,) change of the odometry
    pose (dx, dy, dtheta) in the odometry frame; bumper_front/bumper_rear: a touch
    sensor fired; stalled: the motors were blocked (no bumper saw the obstacle)."""

    odometry_delta: np.ndarray
    bumper_front: bool = False
    bumper_rear: bool = False
    stalled: bool = False

    @property
    def blocked(self) -> bool:
        return self.bumper_front or self.bumper_rear or self.stalled


@dataclass(frozen=True)
class Photo:
    """A photo taken by the robot's camera, with the readings taken with it.

    image: (H, W, 3) uint8. time_s: sensor time (s). odometry: (3,) odometry pose when the
    shutter fired. compass_rad: heading from the compass (rad, world frame, noisy).
    range_m: ultrasonic range (m). index: 0-based photo counter of the session.
    No ground truth here: a simulator keeps it apart (`SimRobot.truth`)."""

    image: np.ndarray
    time_s: float
    odometry: np.ndarray
    compass_rad: float
    range_m: float
    index: int


@runtime_checkable
class Robot(Protocol):
    """A differential-drive robot with a camera, compass, ultrasonic and two bumpers."""

    intrinsics: np.ndarray  # (3, 3) K of the camera, pixels
    image_size: tuple[int, int]  # (width, height) pixels
    cam_from_robot: np.ndarray  # (4, 4) mount transform

    def drive(self, distance_m: float) -> MotionResult: ...
    def turn(self, angle_rad: float) -> MotionResult: ...
    def odometry(self) -> np.ndarray: ...
    def compass(self) -> float: ...
    def ultrasonic(self) -> float: ...
    def bumpers(self) -> tuple[bool, bool]: ...
    def capture(self) -> Photo: ...
    def stop(self) -> None: ...


def check_motion(name: str, value: float) -> None:
    """Every `Robot`'s drive and turn take a finite number: a NaN turn would leave a
    simulated robot at a NaN pose without a word, and fail deep inside a real one's
    encoder arithmetic (or a NaN drive inside either) with a bare ValueError. One
    `InputError` naming the command instead, before anything moves."""
    if not np.isfinite(value):
        raise InputError(f"{name} must be a finite number, got {value}")
