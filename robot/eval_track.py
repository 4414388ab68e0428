"""Tracking evaluation in any synthetic world: a `SimRobot` drives the world's tour
(`ibr.synthetic.tour_route`, made from its floor plan) while the world-scaled rendered-view
particle filter (`localization.world_mcl`) localises it from its photos and odometry alone;
the simulator's truth is used only to score. Optionally the robot is kidnapped (teleported
without its sensors knowing) mid-run, and the steps the filter needs to recover counted.

Success is a pose error, the same in every world: within the robot's diameter and
`tolerance_rad` of heading, held for `hold_steps` steps. The filter's own claim
("converged": one tight mode) is scored against the truth: a claim with the error beyond
twice the tolerance is "converged wrong" (a confident wrong answer), counted apart. After
a kidnapping the filter cannot know of the teleport until a photo disagrees, so its old
claim is not counted wrong until it first drops it (the steps that takes are reported).

The map the filter renders is the world's ground-truth textured mesh, lit like the photos
(through the likelihood's lean renderer): a near-perfect image-based model, so this
measures the filter, not the model.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ibr.camera import Camera
from ibr.synthetic import SyntheticWorld, tour_route
from localization.level_view_likelihood import LevelViewLikelihood
from localization.motion_models import wrap_angle
from localization.particle_filter import ParticleFilter
from localization.render_likelihood import likelihood_renderer
from localization.view_search import PanoramaIndex
from localization.world_mcl import MCLSettings, WorldMCL, WorldMCLConfig, WorldStep, measure_basin
from robot.sim_robot import SimRobot, SimRobotConfig
from robot.waypoint_follower import follow_waypoints


@dataclass(frozen=True)
class TrackConfig:
    steps: int = 60
    """Legs driven (one photo and one filter step per leg)."""
    kidnap_step: int | None = 30
    """Teleport the robot before this step (None: never)."""
    global_init: bool = True
    """Start from a uniform prior over the free space (else from the true start pose)."""
    n_particles: int | None = None
    """Global particle count; None: from the world (`MCLSettings.for_world`)."""
    tolerance_rad: float = np.radians(10.0)
    """Heading part of the success tolerance (rad); the position part is the robot's
    diameter, a size of the robot, not of the world."""
    hold_steps: int = 3
    """Localised when within the tolerance for this many consecutive steps."""
    search: bool = True
    """Global (re-)initialisations from the photo's best poses (`localization.view_search`),
    else uniform."""


def pose_error(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(position error m, heading error rad) between SE(2) poses."""
    return float(np.hypot(*(estimate[:2] - truth[:2]))), float(abs(wrap_angle(estimate[2] - truth[2])))


def steps_to_localise(ok: np.ndarray, start: int, hold: int) -> int | None:
    """Steps from `start` until `ok` (T,) bool holds for `hold` consecutive steps."""
    for t in range(start, len(ok) - hold + 1):
        if ok[t : t + hold].all():
            return t - start
    return None


def route_pose(route: np.ndarray, s: float) -> np.ndarray:
    """(x, y, theta) at arc length `s` (m, wrapped) along the closed polyline `route`,
    heading along it."""
    seg = np.diff(route, axis=0)
    cum = np.r_[0, np.cumsum(np.hypot(*seg.T))]
    s = s % cum[-1]
    k = min(int(np.searchsorted(cum, s, side="right")) - 1, len(seg) - 1)
    f = (s - cum[k]) / max(cum[k + 1] - cum[k], 1e-12)
    xy = route[k] + f * seg[k]
    return np.array([*xy, np.arctan2(seg[k, 1], seg[k, 0])])


_BASINS: dict = {}
_SEARCHES: dict = {}


def world_filter(world: SyntheticWorld, robot: SimRobot, rng: np.random.Generator, ctx=None,
                 n_particles: int | None = None, search: bool = True) -> WorldMCL:
    """The filter for `world`: the level-view likelihood on the world's mesh (lit like the
    photos, its background where it has no geometry), settings from the measured basin and
    the free area, success tolerance from the robot's size; with `search`, global
    (re-)initialisations from the photo's best poses over the map's panoramas (rendered
    once per world, at the basin's spacing)."""
    lik = LevelViewLikelihood(likelihood_renderer(world.mesh, ctx, world.background), world.light,
                              Camera(robot.intrinsics, *robot.image_size), robot.cam_from_robot)
    key = (world.name, world.seed, robot.free.area)
    if key not in _BASINS:  # a property of the map and the camera: measured once per world
        _BASINS[key] = measure_basin(lik, robot.free, np.random.default_rng(world.seed))
    settings = MCLSettings.for_world(robot.free.area, _BASINS[key])
    if n_particles:
        settings = replace(settings, n_global=n_particles)
    pf = ParticleFilter(robot.free, settings.filter_config(), rng)
    config = WorldMCLConfig(converged_m=2 * robot.config.radius_m)
    if search and key not in _SEARCHES:  # panoramas at a grid as fine as the basin
        _SEARCHES[key] = PanoramaIndex(lik, robot.free, settings.basin.m, config.coarse_size)
    return WorldMCL(pf, lik, settings, config, _SEARCHES[key] if search else None)


def run_tracking(world: SyntheticWorld, seed: int, config: TrackConfig = TrackConfig(),
                 on_step: Callable | None = None, ctx=None) -> dict:
    """One seeded run from a random point of the world's tour. `on_step(step, report,
    robot, photo, mcl)` is called after each filter step (for logging). Returns per-step
    errors and the localisation figures."""
    rng = np.random.default_rng(seed)
    route = tour_route(world)
    length = float(np.hypot(*np.diff(route, axis=0).T).sum())
    s0 = rng.uniform(0, length)
    start = route_pose(route, s0)
    robot = SimRobot(world, SimRobotConfig(), np.random.default_rng(rng.integers(2**32)), ctx, start)
    # the panoramas serve global (re-)initialisations: from a uniform prior or a kidnapping
    search = config.search and (config.global_init or config.kidnap_step is not None)
    mcl = world_filter(world, robot, np.random.default_rng(rng.integers(2**32)), ctx, config.n_particles, search)
    if config.global_init:
        mcl.start_global()
    else:
        mcl.pf.init_gaussian(start, [0.05, 0.05, np.radians(2)])
    legs = _drive_from(robot, route, s0, length, seed)
    errors, claims, odom = [], [], robot.odometry()
    try:
        for step in range(config.steps):
            if step == config.kidnap_step:
                robot.kidnap(_far_route_pose(robot, route, length, rng))
                legs = _drive_from(robot, route, None, length, seed + 1)
            if next(legs, None) is None:
                break
            photo = robot.capture()
            report: WorldStep = mcl.step(odom, photo.odometry, photo.image)
            odom = photo.odometry
            errors.append(pose_error(report.estimate, robot.true_pose))
            claims.append(report.converged)
            if on_step:
                on_step(step, report, robot, photo, mcl)
    finally:  # each trial's likelihood renderer holds atlases of thousands of views
        mcl.lik.model.release()
    s = mcl.settings
    return {"seed": seed, **score_run(np.array(errors), np.array(claims, bool), config, mcl.config.converged_m),
            "settings": {"n_global": s.n_global, "basin_m": round(s.basin.m, 4),
                         "basin_deg": round(float(np.degrees(s.basin.rad)), 2),
                         "tolerance_m": mcl.config.converged_m,
                         "tolerance_deg": float(np.degrees(config.tolerance_rad))}}


def score_run(errors: np.ndarray, claims: np.ndarray, config: TrackConfig, tol_m: float) -> dict:
    """A run's figures from per-step errors (T, 2) (m, rad) and the filter's convergence
    claims (T,): steps to converge (before the kidnapping) and to recover (after it), each
    the first step from which a claim with the error within (tol_m, config.tolerance_rad)
    holds for `hold_steps`; the steps claimed with the error beyond twice the tolerance
    (not counted: after the kidnapping, until the filter first drops its old claim, whose
    delay is `steps_to_notice_kidnap`); tracking errors over the steps after convergence
    and after recovery."""
    tol_rad = config.tolerance_rad
    within = (errors[:, 0] < tol_m) & (errors[:, 1] < tol_rad)
    wrong = claims & ((errors[:, 0] > 2 * tol_m) | (errors[:, 1] > 2 * tol_rad))
    k = config.kidnap_step if config.kidnap_step is not None and config.kidnap_step < len(errors) else None
    noticed = None
    if k is not None:  # the old claim stands until a photo disagrees: not counted wrong till then
        dropped = np.flatnonzero(~claims[k:])
        noticed = int(dropped[0]) if len(dropped) else None
        wrong[k : k + (noticed if noticed is not None else len(errors) - k)] = False
    good = claims & within
    end = k if k is not None else len(errors)
    converged = steps_to_localise(good[:end], 0, config.hold_steps)
    recovery = steps_to_localise(good, k, config.hold_steps) if k is not None else None
    tracked = []
    if converged is not None and converged < end:
        tracked.append(errors[converged:end])
    if recovery is not None:
        tracked.append(errors[k + recovery:])
    tracked = np.concatenate(tracked) if tracked else errors[:0]
    return {"steps_to_converge": converged, "steps_to_recover": recovery,
            "steps_to_notice_kidnap": noticed,
            "converged_wrong_steps": int(wrong.sum()),
            "median_tracking_error_m": float(np.median(tracked[:, 0])) if len(tracked) else None,
            "median_tracking_error_deg": float(np.degrees(np.median(tracked[:, 1]))) if len(tracked) else None,
            "error_m": errors[:, 0].round(4).tolist(),
            "error_deg": np.degrees(errors[:, 1]).round(3).tolist(),
            "claimed": claims.astype(int).tolist()}


def _drive_from(robot: SimRobot, route: np.ndarray, s: float | None, length: float, seed: int):
    """Legs along the tour from arc length `s` (None: the route point nearest the robot),
    round and round. The simulated driver (compass-aided dead reckoning, not the filter)
    starts at the true pose, as the robot's route-following would after a kidnapping in a
    scene it drives through; the filter is told nothing (the odometry does not see a
    teleport)."""
    if s is None:
        dense = np.array([route_pose(route, t)[:2] for t in np.linspace(0, length, 400, endpoint=False)])
        s = float(np.argmin(np.hypot(*(dense - robot.true_pose[:2]).T))) * length / 400
    ahead = np.array([route_pose(route, s + t)[:2] for t in np.arange(0.5, 20 * length, 0.5)])
    return follow_waypoints(robot, ahead, robot.true_pose, rng=np.random.default_rng(seed))


def _far_route_pose(robot: SimRobot, route: np.ndarray, length: float, rng: np.random.Generator) -> np.ndarray:
    """A pose on the tour (heading along it) farther from the robot than half the tour's
    points are: far in the world's own terms, whatever its size."""
    cand = np.array([route_pose(route, t) for t in rng.uniform(0, length, 64)])
    d = np.hypot(*(cand[:, :2] - robot.true_pose[:2]).T)
    far = cand[d >= np.median(d)]
    return far[rng.integers(len(far))]
