"""The `drive` loop: a robot drives a route and photographs it, and can be killed at any
moment and resumed. It drives leg by leg (`robot.waypoint_follower`), takes a photo after
every leg, and writes each leg's motion, readings, photo and pose estimate to a capture
session (`robot.session`), ending the leg with a commit record that holds everything
resuming needs.

Determinism on resume: every leg's random numbers come from generators seeded with
(seed, leg), not from one stream, and a simulated robot's state (true pose, odometry, clock,
photo counter: `SimRobot.state()`) is saved in each commit and restored from the last one;
so a run killed and resumed writes the same records and photos as one left alone. A real
robot resumes from where it physically is, with the logged pose estimate.
Poses: world SE(2) (x, y, theta), metres and radians.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from robot.protocol import MotionResult, Photo, Robot
from robot.session import CaptureSession
from robot.waypoint_follower import FollowerConfig, Leg, follow_waypoints

FOLLOWER_STREAM, ROBOT_STREAM = 1, 2  # sub-streams of the per-leg seed


@dataclass(frozen=True)
class DriveLeg:
    """One finished, committed leg: the follower's `Leg` and the photo taken after it."""

    leg: Leg
    photo: Photo
    resumed: bool  # the first leg after a resume


def _reseed(rng: np.random.Generator, seed: int, stream: int, leg: int) -> None:
    rng.bit_generator.state = np.random.default_rng([seed, stream, leg]).bit_generator.state


def _motion(m: MotionResult) -> dict:
    return {"odometry_delta": m.odometry_delta, "bumper_front": m.bumper_front,
            "bumper_rear": m.bumper_rear, "stalled": m.stalled}


def run_drive(robot: Robot, session: CaptureSession, waypoints: np.ndarray,
                        start_pose: np.ndarray, seed: int, config: FollowerConfig = FollowerConfig(),
                        is_sim: bool | None = None) -> Iterator[DriveLeg]:
    """Drive `robot` through `waypoints` (M, 2) from `start_pose` (3,), logging to
    `session` (opened with rollback=True when resuming); yields each committed leg.
    Resumes after the session's last commit. `is_sim`: restore the simulator state from
    the commit (default: the robot has a `true_pose`)."""
    is_sim = hasattr(robot, "true_pose") if is_sim is None else is_sim
    done, w0, est = 0, 0, np.asarray(start_pose, dtype=np.float64)
    last = session.last_commit
    if last is not None:
        done, w0 = last["step"] + 1, last["state"]["waypoint"]
        est = np.asarray(last["state"]["estimate"], dtype=np.float64)
        if is_sim:
            robot.restore(last["state"]["sim"])
    else:
        session.append("start", start_pose=est, seed=seed, waypoints=waypoints)
    follower_rng = np.random.default_rng(0)
    legs = follow_waypoints(robot, np.asarray(waypoints)[w0:], est,
                            replace(config, max_legs=config.max_legs - done), follower_rng)
    k = done
    while True:
        _reseed(follower_rng, seed, FOLLOWER_STREAM, k)
        if hasattr(robot, "rng"):
            _reseed(robot.rng, seed, ROBOT_STREAM, k)
        leg = next(legs, None)
        if leg is None:
            return
        leg = replace(leg, index=k, waypoint=leg.waypoint + w0)
        session.append("motion", step=k, waypoint=leg.waypoint, **_motion(leg.motion))
        photo = robot.capture()
        session.append("sensors", step=k, time_s=photo.time_s, odometry=photo.odometry,
                       compass_rad=photo.compass_rad, range_m=photo.range_m, bumpers=list(robot.bumpers()))
        session.add_photo(photo, pose=leg.estimate, step=k)
        session.append("estimate", step=k, pose=leg.estimate)
        state = {"waypoint": leg.waypoint, "estimate": leg.estimate}
        if is_sim:
            state["sim"] = robot.state()
        session.commit(k, state)
        yield DriveLeg(leg, photo, resumed=k == done and done > 0)
        k += 1
