"""Compass-aided dead reckoning: the simplest pose estimate a robot has without vision.

The signed distance driven (from the odometry, Thrun's rot1-trans-rot2 decomposition) is
integrated along the compass heading (world frame) instead of the odometry heading, so
heading error does not accumulate; position error still grows with distance. SE(2) poses
(x, y, theta) in metres and radians, world frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from localization.motion_models import odometry_decomposition


@dataclass
class CompassDeadReckoning:
    """pose: the current estimate (3,), initialised at the known start pose."""

    pose: np.ndarray

    def update(self, odom_before: np.ndarray, odom_after: np.ndarray, compass_rad: float,
               in_place: bool = False) -> np.ndarray:
        """Advance by the motion between two odometry poses, along the compass heading
        (rad); returns the new estimate (3,). `in_place`: the robot was commanded to turn in
        place, so it stays where it was (`motion_models.turn_in_place`)."""
        _, trans, _ = odometry_decomposition(odom_before, odom_after)
        trans = 0.0 if in_place else trans
        self.pose = np.array([self.pose[0] + trans * np.cos(compass_rad),
                              self.pose[1] + trans * np.sin(compass_rad), compass_rad])
        return self.pose.copy()
