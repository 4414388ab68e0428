"""`SimRobot`: a differential-drive robot with a camera in a synthetic world.

It drives on the world's floor plan (a disc of `radius_m` against `free_space`), reports
noisy odometry (Thrun's alpha1-4 odometry model, the one the particle filter uses), a
noisy compass, an ultrasonic range (rays cast with embree through trimesh), front and rear
bumpers (a contact within the bumper arc) and a motor stall (a contact outside both arcs,
which no bumper sees). `capture()` photographs the world with the world's lighting.
Ground truth is kept apart in `truth` (one record per photo) and `true_pose`, for
evaluation only. Frames: world SE(2) poses (x, y, theta) in metres and radians.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.ops import nearest_points
from trimesh.ray.ray_pyembree import RayMeshIntersector

from ibr.camera import intrinsics_from_fov
from ibr.errors import InputError
from ibr.synthetic import SyntheticWorld
from localization.motion_models import apply_odometry, sample_odometry_noise, wrap_angle
from robot.protocol import MotionResult, Photo, check_motion, forward_camera_mount, robot_camera


@dataclass(frozen=True)
class SimRobotConfig:
    radius_m: float = 0.15
    """Footprint radius of the robot disc (m)."""
    camera_height_m: float = 0.4
    """Height of the camera's optical centre above the floor (m)."""
    camera_tilt_rad: float = 0.0
    """Downward pitch of the camera (rad)."""
    fov_x_rad: float = np.radians(60.0)
    """Horizontal field of view of the camera (rad)."""
    image_size: tuple[int, int] = (320, 240)
    """Camera image (width, height) in pixels."""
    alphas: tuple[float, float, float, float] = (0.02, 0.002, 0.02, 0.002)
    """Thrun's odometry noise alpha1..alpha4 (rot-from-rot, rot-from-trans, trans-from-trans, trans-from-rot)."""
    compass_sigma_rad: float = np.radians(2.0)
    """Standard deviation of the compass heading (rad)."""
    ultrasonic_sigma_m: float = 0.01
    """Standard deviation of the ultrasonic range (m)."""
    ultrasonic_max_m: float = 2.55
    """Largest range the ultrasonic reports (the NXT's 255 cm); farther reads as this."""
    ultrasonic_height_m: float = 0.15
    """Height of the ultrasonic sensor (m)."""
    ultrasonic_half_cone_rad: float = np.radians(10.0)
    """Half-angle of the sensor's cone, sampled by 5 rays in the horizontal plane (rad)."""
    bumper_half_arc_rad: float = np.radians(60.0)
    """A contact within this angle of straight ahead (or behind) presses that bumper (rad)."""
    step_m: float = 0.01
    """Resolution of the collision check along a drive (m)."""
    speed_m_s: float = 0.2
    """Driving speed, for sensor time (m/s)."""
    turn_rate_rad_s: float = 1.0
    """Turning rate in place, for sensor time (rad/s)."""


@dataclass
class SimRobot:
    """A simulated robot; implements `robot.protocol.Robot`. `ctx` is the GL context photos
    are rendered with (the shared one by default)."""

    world: SyntheticWorld
    config: SimRobotConfig = field(default_factory=SimRobotConfig)
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))
    ctx: object | None = None
    start_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        c = self.config
        self.free = self.world.free_space.buffer(-c.radius_m)
        shapely.prepare(self.free)
        self.true_pose = np.asarray(self.start_pose, dtype=np.float64)
        if not shapely.contains_xy(self.free, *self.true_pose[:2]):
            raise InputError(f"start pose {self.start_pose} is not in the free space of "
                             f"{self.world.name} (robot radius {c.radius_m} m)")
        self._odometry = np.zeros(3)
        self.time_s = 0.0
        self.truth: list[dict] = []
        self._contact = (False, False)
        self._n_photos = 0
        self._rays = RayMeshIntersector(self.world.mesh)
        self.intrinsics = intrinsics_from_fov(np.degrees(c.fov_x_rad), *c.image_size)
        self.image_size = c.image_size
        self.cam_from_robot = forward_camera_mount(c.camera_height_m, tilt_down_rad=c.camera_tilt_rad)

    # --- motion -------------------------------------------------------------------
    def drive(self, distance_m: float) -> MotionResult:
        """Drive straight `distance_m` (negative: backwards) until done or blocked."""
        check_motion("SimRobot: drive distance_m", distance_m)
        c = self.config
        n = max(1, int(np.ceil(abs(distance_m) / c.step_m)))
        s = np.linspace(0, distance_m, n + 1)[1:]
        x, y, th = self.true_pose
        xs, ys = x + s * np.cos(th), y + s * np.sin(th)
        inside = shapely.contains_xy(self.free, xs, ys)
        blocked = not inside.all()
        k = int(np.argmin(inside)) if blocked else n  # substeps completed
        travelled = float(s[k - 1]) if k > 0 else 0.0
        if k > 0:
            self.true_pose = np.array([xs[k - 1], ys[k - 1], th])
        front = rear = stalled = False
        if blocked:
            front, rear, stalled = self._classify_contact(np.array([xs[k], ys[k]]))
        self._contact = (front, rear)
        self.time_s += abs(travelled) / c.speed_m_s
        return MotionResult(self._move_odometry(np.array([0.0, travelled, 0.0])), front, rear, stalled)

    def turn(self, angle_rad: float) -> MotionResult:
        """Turn in place by `angle_rad` (counter-clockwise positive); a disc always can."""
        check_motion("SimRobot: turn angle_rad", angle_rad)
        self.true_pose = np.array([*self.true_pose[:2], wrap_angle(self.true_pose[2] + angle_rad)])
        self._contact = (False, False)
        self.time_s += abs(angle_rad) / self.config.turn_rate_rad_s
        return MotionResult(self._move_odometry(np.array([angle_rad, 0.0, 0.0])))

    def _move_odometry(self, u: np.ndarray) -> np.ndarray:
        """Report the true motion u through the noisy odometry; returns the odometry delta."""
        noisy = sample_odometry_noise(u, self.config.alphas, 1, self.rng)[0]
        before = self._odometry
        self._odometry = apply_odometry(before, noisy)[0]
        delta = self._odometry - before
        delta[2] = wrap_angle(delta[2])
        return delta

    def _classify_contact(self, blocked_xy: np.ndarray) -> tuple[bool, bool, bool]:
        """Which bumper (front, rear) the contact at the blocked position presses, or a
        stall (no bumper) when the obstacle touches the side of the robot."""
        p = shapely.Point(*blocked_xy)
        wall = nearest_points(self.world.free_space.boundary, p)[0]
        bearing = wrap_angle(np.arctan2(wall.y - p.y, wall.x - p.x) - self.true_pose[2])
        arc = self.config.bumper_half_arc_rad
        front = abs(bearing) <= arc
        rear = abs(wrap_angle(bearing - np.pi)) <= arc
        return front, rear, not (front or rear)

    # --- sensors ------------------------------------------------------------------
    def odometry(self) -> np.ndarray:
        """Odometry pose (3,) in the odometry frame (the start pose is the origin)."""
        return self._odometry.copy()

    def compass(self) -> float:
        """Heading (rad) in the world frame, with Gaussian noise."""
        return float(wrap_angle(self.true_pose[2] + self.rng.normal(0, self.config.compass_sigma_rad)))

    def ultrasonic(self) -> float:
        """Range (m) to the nearest surface in the sensor's cone, capped at the maximum."""
        c = self.config
        x, y, th = self.true_pose
        angles = th + np.linspace(-c.ultrasonic_half_cone_rad, c.ultrasonic_half_cone_rad, 5)
        dirs = np.c_[np.cos(angles), np.sin(angles), np.zeros(5)]
        origins = np.tile([x, y, c.ultrasonic_height_m], (5, 1))
        hits, idx, _ = self._rays.intersects_location(origins, dirs, multiple_hits=False)
        r = np.linalg.norm(hits - origins[idx], axis=1).min() if len(hits) else c.ultrasonic_max_m
        return float(np.clip(r + self.rng.normal(0, c.ultrasonic_sigma_m), 0, c.ultrasonic_max_m))

    def bumpers(self) -> tuple[bool, bool]:
        """(front, rear) touch sensors: pressed while the last move ended in contact."""
        return self._contact

    def capture(self) -> Photo:
        """Photograph the world from the camera; the true pose goes to `truth` only."""
        cam = robot_camera(self.true_pose, self.intrinsics, self.image_size, self.cam_from_robot,
                           name=f"photo_{self._n_photos:04d}")
        photo = Photo(self.world.photograph(cam, self.ctx), self.time_s, self.odometry(),
                      self.compass(), self.ultrasonic(), self._n_photos)
        self.truth.append({"index": photo.index, "time_s": self.time_s, "pose": self.true_pose.copy()})
        self._n_photos += 1
        return photo

    def kidnap(self, pose: np.ndarray) -> None:
        """Teleport the robot to `pose` without telling its sensors (evaluation of
        relocalisation). The odometry does not see it; that is the point."""
        if not shapely.contains_xy(self.free, pose[0], pose[1]):
            raise InputError(f"kidnap pose {pose} is not in the free space")
        self.true_pose = np.asarray(pose, dtype=np.float64).copy()
        self._contact = (False, False)

    def stop(self) -> None:
        """Motors off. A simulated robot moves only inside drive/turn, so nothing runs on."""

    # --- simulator state (to resume a killed run exactly) ---------------------------
    def state(self) -> dict:
        """The simulator state its next moves depend on (ground truth included: it is kept only
        to resume the simulation): true pose, odometry, clock, contact, photo counter. The noise
        generator `rng` is not included (its owner saves or reseeds it)."""
        return {"true_pose": self.true_pose.copy(), "odometry": self._odometry.copy(), "time_s": self.time_s,
                "contact": list(self._contact), "n_photos": self._n_photos}

    def restore(self, state: dict) -> None:
        """Put the simulator back to a `state()` (e.g. read back from JSON)."""
        self.true_pose = np.asarray(state["true_pose"], dtype=np.float64)
        self._odometry = np.asarray(state["odometry"], dtype=np.float64)
        self.time_s = float(state["time_s"])
        self._contact = tuple(state["contact"])
        self._n_photos = int(state["n_photos"])
