"""robot: bodies — the `Robot` protocol, `SimRobot` in synthetic worlds, the NXT over a
serial port, and capture sessions written to disk as they happen."""

from robot.protocol import MotionResult, Photo, Robot

__all__ = ["MotionResult", "Photo", "Robot"]
