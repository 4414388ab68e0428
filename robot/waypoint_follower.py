"""Drive a robot through 2-D waypoints on its own pose estimate: turn towards the next
waypoint, drive a short leg, re-estimate, repeat. On a bumper hit or a stall it backs off
and turns a little before trying again. World frame, metres and radians."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from localization.dead_reckoning import CompassDeadReckoning
from localization.motion_models import wrap_angle
from robot.protocol import MotionResult, Robot


@dataclass(frozen=True)
class FollowerConfig:
    leg_m: float = 0.25
    """Longest straight leg between two estimates (m)."""
    reached_m: float = 0.12
    """A waypoint within this distance of the estimate counts as reached (m)."""
    backoff_m: float = 0.15
    """How far to back up after a collision (m)."""
    max_legs: int = 400
    """Give up after this many legs, whatever remains."""


@dataclass(frozen=True)
class Leg:
    """One leg: index, the estimate after it (3,), its motion result, the waypoint index."""

    index: int
    estimate: np.ndarray
    motion: MotionResult
    waypoint: int


def follow_waypoints(robot: Robot, waypoints: np.ndarray, start_pose: np.ndarray,
                     config: FollowerConfig = FollowerConfig(),
                     rng: np.random.Generator | None = None) -> Iterator[Leg]:
    """Yield a `Leg` after every straight leg while driving `robot` through `waypoints`
    (M, 2), starting from the known `start_pose` (3,). The estimate is compass-aided dead
    reckoning (`localization.dead_reckoning`)."""
    rng = rng or np.random.default_rng(0)
    est = CompassDeadReckoning(np.asarray(start_pose, dtype=np.float64))
    k, w = 0, 0
    while w < len(waypoints) and k < config.max_legs:
        d = waypoints[w] - est.pose[:2]
        if np.linalg.norm(d) < config.reached_m:
            w += 1
            continue
        _drive(robot, est, turn=wrap_angle(np.arctan2(d[1], d[0]) - est.pose[2]))
        motion = _drive(robot, est, drive=min(config.leg_m, float(np.linalg.norm(d))))
        if motion.blocked:
            back = config.backoff_m if motion.bumper_rear else -config.backoff_m
            _drive(robot, est, drive=back)
            _drive(robot, est, turn=float(rng.uniform(-0.6, 0.6)))
        yield Leg(k, est.pose.copy(), motion, w)
        k += 1


def _drive(robot: Robot, est: CompassDeadReckoning, turn: float = 0.0, drive: float = 0.0) -> MotionResult:
    before = robot.odometry()
    motion = robot.turn(turn) if turn else robot.drive(drive)
    est.update(before, robot.odometry(), robot.compass())
    return motion

