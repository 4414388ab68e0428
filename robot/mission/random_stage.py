"""Random exploration: the first stage of Foster, Wang & Grupen's scene capture (section IV-A).

The robot captures *circles* of photos, turning in place at about 10 degree steps and
recording its compass and ultrasonic readings with each photo. When a circle completes it
turns to the compass heading at which the ultrasonic saw the longest range and drives a
random distance before the next circle (the first drive is a short one instead,
`RandomExplorationConfig.first_drive_m`: the first circle is the map's tie to the start).
It does not avoid obstacles: on a bumper hit, or a motor stall the bumper missed, it backs
up, turns a random angle and drives on.

No localisation or mapping happens during this stage (bundle adjustment recovers the photos'
poses afterwards, `robot.mission.map_building`); the pose attached to each photo is compass-aided
dead reckoning (`localization.dead_reckoning`), used only to fix the map's scale and heading.
Frames: world SE(2) poses (x, y, theta), metres and radians.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from localization.dead_reckoning import CompassDeadReckoning
from localization.motion_models import wrap_angle
from robot.protocol import MotionResult, Photo, Robot


@dataclass(frozen=True)
class RandomExplorationConfig:
    """Settings of `random_exploration`."""

    n_photos: int = 100
    """Photos to take in all (the paper's ~100)."""
    circle_step_rad: float = np.radians(10.0)
    """Turn between two photos of a circle (rad)."""
    drive_min_m: float = 0.6
    """Shortest random drive between circles (m)."""
    drive_max_m: float = 2.0
    """Longest random drive between circles (m)."""
    first_drive_m: float | None = 0.6
    """The drive from the first circle to the second (m), in place of a random one (None: a
    random one, as the paper's robot). The first circle, taken at the known start, is the
    only thing that ties the map to the world: when SfM poses none of its photos, the map
    stands at the start by the odometry of the first drive alone, ~15 % of its length off
    (apartments 2, 9 and 14: the whole map 10-25 cm off, SfM had posed none of the photos of
    their start circles, 1.0-1.8 m before the next). A short drive keeps the two circles'
    views overlapping, so SfM links them. `drive_min_m`'s length: the robot's, not a scene's."""
    backup_m: float = 0.2
    """How far to back away from an obstacle (m)."""
    max_bumps_per_drive: int = 4
    """Collisions after which a drive is abandoned and the next circle starts."""


@dataclass(frozen=True)
class ExplorationPhoto:
    """A photo of the random exploration: `photo` (with compass and ultrasonic readings),
    `estimate` (3,) the dead-reckoning world pose when it was taken, `circle` its circle
    index, `bumps` the collisions since the previous photo, `path_m` the distance driven so
    far (odometry, m)."""

    photo: Photo
    estimate: np.ndarray
    circle: int
    bumps: int
    path_m: float


class Body:
    """The robot with its dead reckoning and odometer: every move updates both."""

    def __init__(self, robot: Robot, start_pose: np.ndarray):
        self.robot = robot
        self.est = CompassDeadReckoning(np.asarray(start_pose, dtype=np.float64).copy())
        self.path_m = 0.0
        self.bumps = 0

    def move(self, turn: float = 0.0, drive: float = 0.0) -> MotionResult:
        before = self.robot.odometry()
        motion = self.robot.turn(turn) if turn else self.robot.drive(drive)
        after = self.robot.odometry()
        self.est.update(before, after, self.robot.compass(), in_place=bool(turn))
        self.path_m += float(np.hypot(*(after[:2] - before[:2])))
        self.bumps += motion.blocked
        return motion


def steps_per_circle(config: RandomExplorationConfig) -> int:
    """Photos in a full circle."""
    return max(1, int(round(2 * np.pi / config.circle_step_rad)))


def drive_with_bumps(body: Body, distance_m: float, config: RandomExplorationConfig,
                     rng: np.random.Generator) -> None:
    """Drive `distance_m` straight; on a collision back up, turn a random angle and drive
    the rest, at most `max_bumps_per_drive` times."""
    left = distance_m
    for _ in range(config.max_bumps_per_drive + 1):
        before = body.robot.odometry()
        motion = body.move(drive=left)
        left -= abs(float(np.hypot(*(body.robot.odometry()[:2] - before[:2]))))
        if not motion.blocked or left <= 0.05:
            return
        body.move(drive=config.backup_m if motion.bumper_rear else -config.backup_m)
        body.move(turn=float(rng.uniform(np.pi / 4, np.pi)) * rng.choice([-1.0, 1.0]))


def random_exploration(robot: Robot, start_pose: np.ndarray,
                       config: RandomExplorationConfig = RandomExplorationConfig(),
                       rng: np.random.Generator | None = None, body: Body | None = None
                       ) -> Iterator[ExplorationPhoto]:
    """Run the random exploration with `robot` from the known `start_pose` (3,), yielding
    each photo as it is taken, until `config.n_photos` photos. `body`: the robot with its
    dead reckoning, to keep using after this stage (made here when None)."""
    rng = rng or np.random.default_rng(0)
    body = body or Body(robot, start_pose)
    n, circle, per_circle = 0, 0, steps_per_circle(config)
    while n < config.n_photos:
        readings = []  # (compass heading, ultrasonic range) per photo of the circle
        for k in range(per_circle):
            if n >= config.n_photos:
                return
            photo = robot.capture()
            readings.append((photo.compass_rad, photo.range_m))
            yield ExplorationPhoto(photo, body.est.pose.copy(), circle, body.bumps, body.path_m)
            body.bumps = 0
            n += 1
            if n >= config.n_photos:
                return  # the robot stays where its last photo was taken
            if k < per_circle - 1:
                body.move(turn=config.circle_step_rad)
        best_heading = max(readings, key=lambda r: r[1])[0]
        body.move(turn=float(wrap_angle(best_heading - robot.compass())) or 1e-3)
        short = circle == 0 and config.first_drive_m is not None
        distance = config.first_drive_m if short else float(rng.uniform(config.drive_min_m, config.drive_max_m))
        drive_with_bumps(body, distance, config, rng)
        circle += 1
