"""Tracking evaluation in a synthetic world: a `SimRobot` drives the loop route while the
render-likelihood particle filter localises it from its photos and odometry alone; the
simulator's truth is used only to score. Optionally the robot is kidnapped (teleported
without its sensors knowing) mid-run, and the steps the filter needs to recover counted.

The map the filter renders is the world's ground-truth textured mesh, lit like the photos
(through the likelihood's lean renderer: trilinear texture filtering where the photos use
anisotropic): a near-perfect image-based model, so this measures the filter, not the model.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ibr.camera import Camera
from ibr.synthetic import SyntheticWorld, loop_route
from localization.motion_models import wrap_angle
from localization.particle_filter import ParticleFilter, ParticleFilterConfig, sample_free_poses
from localization.render_likelihood import BatchedLikelihood, LikelihoodConfig, likelihood_renderer
from localization.render_mcl import RenderMCL, StepReport
from robot.sim_robot import SimRobot, SimRobotConfig
from robot.waypoint_follower import follow_waypoints


@dataclass(frozen=True)
class TrackConfig:
    steps: int = 50
    """Legs driven (one photo and one filter step per leg)."""
    kidnap_step: int | None = 20
    """Teleport the robot before this step (None: never)."""
    global_init: bool = True
    """Start from a uniform prior over the free space (else from the true start pose)."""
    n_particles: int = 1500
    """Initial particle count, and the count of a global re-initialisation."""
    n_max: int = 3000
    """Most particles KLD-sampling may ask for."""
    recovered_m: float = 0.25
    """Localised when the position error is below this (m) ..."""
    recovered_rad: float = np.radians(10.0)
    """... and the heading error below this (rad) ..."""
    hold_steps: int = 3
    """... for this many consecutive steps."""


def pose_error(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(position error m, heading error rad) between SE(2) poses."""
    return float(np.hypot(*(estimate[:2] - truth[:2]))), float(abs(wrap_angle(estimate[2] - truth[2])))


def steps_to_localise(errors: np.ndarray, start: int, config: TrackConfig) -> int | None:
    """Steps from `start` until the errors (T, 2) stay within bounds for `hold_steps`."""
    ok = (errors[:, 0] < config.recovered_m) & (errors[:, 1] < config.recovered_rad)
    for t in range(start, len(ok) - config.hold_steps + 1):
        if ok[t : t + config.hold_steps].all():
            return t - start
    return None


def run_tracking(world: SyntheticWorld, seed: int, config: TrackConfig = TrackConfig(),
                 on_step: Callable | None = None, ctx=None) -> dict:
    """One seeded run. `on_step(step, report, robot, photo, mcl)` is called after each
    filter step (for logging). Returns per-step errors and the localisation figures."""
    rng = np.random.default_rng(seed)
    route = loop_route(world)
    start = np.array([*route[0], 0.0])
    robot = SimRobot(world, SimRobotConfig(), np.random.default_rng(rng.integers(2**32)), ctx, start)
    pf = ParticleFilter(robot.free, ParticleFilterConfig(n_particles=config.n_particles, n_max=config.n_max),
                        np.random.default_rng(rng.integers(2**32)))
    if config.global_init:
        pf.init_uniform()
    else:
        pf.init_gaussian(start, [0.05, 0.05, np.radians(2)])
    likelihood = BatchedLikelihood(likelihood_renderer(world.mesh, ctx, world.background),
                                   LikelihoodConfig(), world.light)
    mcl = RenderMCL(pf, likelihood, Camera(robot.intrinsics, *robot.image_size), robot.cam_from_robot)
    errors, odom = [], robot.odometry()
    legs = follow_waypoints(robot, np.tile(route, (100, 1)), start, rng=np.random.default_rng(seed))
    for step in range(config.steps):
        if step == config.kidnap_step:
            robot.kidnap(_far_pose(robot, rng))
            legs = _drive_on_from(robot, route, seed)
        if next(legs, None) is None:
            break
        photo = robot.capture()
        report: StepReport = mcl.step(odom, photo.odometry, photo.image)
        odom = photo.odometry
        errors.append(pose_error(report.estimate, robot.true_pose))
        if on_step:
            on_step(step, report, robot, photo, mcl)
    errors = np.array(errors)
    converged = steps_to_localise(errors, 0, config)
    k = config.kidnap_step
    recovery = steps_to_localise(errors, k, config) if k is not None and k < len(errors) else None
    tracked = errors[converged:k] if converged is not None else errors[:0]
    return {"seed": seed, "steps_to_converge": converged, "steps_to_recover": recovery,
            "median_tracking_error_m": float(np.median(tracked[:, 0])) if len(tracked) else None,
            "median_tracking_error_deg": float(np.degrees(np.median(tracked[:, 1]))) if len(tracked) else None,
            "error_m": errors[:, 0].round(4).tolist(),
            "error_deg": np.degrees(errors[:, 1]).round(3).tolist()}


def _drive_on_from(robot: SimRobot, route: np.ndarray, seed: int):
    """The drive after a kidnapping: the route again, from the waypoint nearest the new
    pose. The simulated driver (compass-aided dead reckoning, not the filter) is restarted
    at the true pose, as the robot's route-following would be in a scene it drives
    through; otherwise it steers by its old belief into a wall and stalls there, facing
    a blank close-up no localiser could place. The filter is told nothing: it gets the
    odometry, which does not see the teleport, and the photos."""
    k = int(np.argmin(np.hypot(*(route - robot.true_pose[:2]).T)))
    waypoints = np.tile(np.r_[route[k:], route[1:k + 1]], (100, 1))
    return follow_waypoints(robot, waypoints, robot.true_pose, rng=np.random.default_rng(seed + 1))


def _far_pose(robot: SimRobot, rng: np.random.Generator, min_m: float = 2.0) -> np.ndarray:
    """A random free pose at least `min_m` from where the robot is."""
    while True:
        pose = sample_free_poses(robot.free, 1, rng)[0]
        if np.hypot(*(pose[:2] - robot.true_pose[:2])) >= min_m:
            return pose
