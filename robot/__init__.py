"""robot: bodies. The `Robot` protocol, `SimRobot` in synthetic worlds, the LEGO NXT over a
serial port (`robot.nxt`), capture sessions written to disk as they happen, waypoint
following and the `drive` loop; `robot.mission` is Foster, Wang & Grupen's scene-capture
mission."""

from robot.protocol import MotionResult, Photo, Robot

__all__ = ["MotionResult", "Photo", "Robot"]
