"""Adaptive exploration: the second stage of Foster, Wang & Grupen's scene capture (IV-B, IV-C).

From the map of the photos so far (`robot.initial_map`), each round:
1. slices the mesh at the camera height for the free-space boundary and samples random
   candidate poses inside it (`explore.candidates`);
2. scores all candidates in one batched pass of the rendering-quality heuristic
   (`explore.view_quality.ViewQuality`: mean smallest angle between a pixel's desired ray
   and the rays to the source photos that see its point; higher = more to gain);
3. picks the best goals (greedy, spread apart) and stops when the best score is below
   `AdaptiveConfig.min_gain_rad`;
4. drives to each goal: a KDE navigation grid from the above-ground map points, A* and path
   simplification (`explore.nav_grid`, `explore.path_simplify`); the robot follows the path by
   target-node switching within `switch_m` on the estimate of an SE(2) particle filter
   (`robot.mission_localizer`): odometry and compass between nodes, *vision* at the nodes
   (SIFT + RANSAC PnP against the map, `localization.feature_localizer`, as a mixture
   proposal), and an extra photo when the filter's spread grows too large: the plan
   consumes the filter's estimate, never a simulator's truth. On an obstacle it
   backs off, drives a little off the path and re-plans; after `max_obstacles` obstacles it
   gives the goal up and takes the next;
5. photographs at each goal, localises those photos, and rebuilds the map with them
   (triangulation with the localised poses fixed, Poisson mesh).

Algorithm code only: what happens is reported to a `MissionObserver` (the CLI turns it into
rerun logs and progress lines). Frames: world SE(2) poses (x, y, theta), metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from explore.candidates import free_space_from_mesh, sample_candidates
from explore.nav_grid import NavGridConfig, nav_grid_from_points
from explore.path_simplify import plan_path
from explore.view_quality import ViewQuality, ViewQualityConfig
from ibr.camera import Camera
from ibr.errors import InputError
from ibr.triangulation import TriangulationConfig, sift_features
from localization.feature_localizer import FeatureLocalizerConfig, FeatureMap
from localization.motion_models import wrap_angle
from robot.initial_map import (
    MapConfig,
    RobotMap,
    extend_map,
    initial_map,
    stereo_tracks,
)
from robot.mission_localizer import FilteredBody, MissionFilterConfig, MissionLocalizer
from robot.protocol import Photo, Robot, robot_camera
from robot.random_exploration import Body, RandomExplorationConfig, random_exploration


@dataclass(frozen=True)
class AdaptiveConfig:
    """Settings of the adaptive exploration."""

    n_candidates: int = 300
    """Random candidate poses scored per round."""
    clearance_m: float = 0.35
    """Candidates keep this distance from the free-space boundary (m)."""
    goals_per_round: int = 6
    """Goals visited between two map rebuilds."""
    goal_separation_m: float = 0.8
    """Two goals of a round are at least this far apart, or differ by 60 degrees in heading (m)."""
    photos_per_goal: int = 2
    """Photos taken at a goal: the goal view, then side-stepped copies (stereo baselines)."""
    stereo_baseline_m: float = 0.6
    """Side step between the photos of a goal (m): 0.6 m is 5 degrees of parallax at 6.9 m."""
    min_gain_rad: float = 0.05
    """Stop when the best candidate's score (mean angle, rad) is below this."""
    max_rounds: int = 6
    """Most rounds of goal selection and map rebuilding."""
    switch_m: float = 0.3
    """Target-node switching: a path node within this distance counts as passed (m)."""
    reach_m: float = 0.15
    """The goal counts as reached within this distance (m)."""
    leg_m: float = 0.6
    """Longest straight drive on dead reckoning before re-aiming (m)."""
    max_obstacles: int = 5
    """Obstacles on the way to a goal after which it is given up (the paper's k = 5)."""
    backoff_m: float = 0.2
    """How far to back up from an obstacle (m)."""
    off_path_m: float = 0.3
    """How far to drive off the path after an obstacle before re-planning (m)."""
    max_legs_per_goal: int = 40
    """Legs after which a goal is given up (a planner or localisation fault never loops forever)."""
    max_path_cost: float = 0.35
    """Grid cells with a (normalised) KDE cost above this are blocked for A*."""
    max_fix_jump_m: float = 1.0
    """A PnP fix farther than this from the dead-reckoning estimate is rejected (m)."""
    max_fix_height_err_m: float = 0.15
    """A PnP fix whose camera height is off by more than this is rejected (m)."""
    grid: NavGridConfig = field(default_factory=lambda: NavGridConfig(z_floor_margin=0.08, z_max=1.2))
    """Navigation grid (KDE of above-ground points)."""
    view_quality: ViewQualityConfig = field(default_factory=ViewQualityConfig)
    """Rendering-quality heuristic."""
    localizer: FeatureLocalizerConfig = field(default_factory=lambda: FeatureLocalizerConfig(
        triangulation=TriangulationConfig(n_features=1500, neighbours=4, max_epipolar_px=3.0,
                                          max_reprojection_px=3.0), query_features=1500, min_inliers=12))
    """SIFT + RANSAC PnP localiser against the map (its map's features are cached per photo)."""
    map: MapConfig = field(default_factory=MapConfig)
    """Map building (SfM, triangulation, Poisson)."""
    filter: MissionFilterConfig = field(default_factory=MissionFilterConfig)
    """The particle filter of path following."""


@dataclass
class MissionPhoto:
    """A photo of the mission: `photo`; `estimate` (3,) the robot's pose estimate when it was
    taken; `stage` "random", "goal" or "localise" (taken to localise, not part of the model);
    `camera` its posed camera once SfM or PnP posed it (None: unposed); `dead_reckoning` (3,)
    the compass-aided dead-reckoning pose then (the baseline the filter is compared with)."""

    photo: Photo
    estimate: np.ndarray
    stage: str
    camera: Camera | None = None
    dead_reckoning: np.ndarray | None = None


class MissionObserver:
    """What the mission reports; every method does nothing here (subclass to log)."""

    def photo(self, mp: MissionPhoto) -> None: ...
    def estimate(self, pose: np.ndarray, source: str) -> None: ...
    def particles(self, particles: np.ndarray, weights: np.ndarray) -> None: ...
    def map(self, robot_map: RobotMap, free_space) -> None: ...
    def candidates(self, poses: np.ndarray, scores: np.ndarray, goals: np.ndarray) -> None: ...
    def grid(self, grid) -> None: ...
    def path(self, xy: np.ndarray) -> None: ...
    def progress(self, text: str) -> None: ...


@dataclass
class MissionResult:
    """photos: every photo in order; robot_map: the final map; path_m: distance driven (m,
    odometry); rounds: adaptive rounds run; goals: (G, 3) goals reached; given_up: goals
    abandoned; fixes/failed_fixes: PnP localisations accepted / failed or rejected;
    stop_reason: why the adaptive stage ended."""

    photos: list[MissionPhoto]
    robot_map: RobotMap | None
    path_m: float = 0.0
    rounds: int = 0
    goals: list = field(default_factory=list)
    given_up: int = 0
    fixes: int = 0
    failed_fixes: int = 0
    stop_reason: str = ""

    @property
    def model_photos(self) -> list[MissionPhoto]:
        """The photos of the model (random + goal; not those taken only to localise)."""
        return [p for p in self.photos if p.stage != "localise"]


def pick_goals(poses: np.ndarray, scores: np.ndarray, k: int, separation_m: float) -> np.ndarray:
    """Indices of up to `k` best-scoring poses (N, 3), each at least `separation_m` from, or
    60 degrees in heading away from, every better one picked."""
    chosen: list[int] = []
    for i in np.argsort(-scores):
        if len(chosen) == k:
            break
        if all(np.hypot(*(poses[i, :2] - poses[j, :2])) >= separation_m
               or abs(wrap_angle(poses[i, 2] - poses[j, 2])) >= np.radians(60) for j in chosen):
            chosen.append(int(i))
    return np.array(chosen, dtype=int)


class AdaptiveMission:
    """The adaptive stage's state: the robot and its dead reckoning (`body`), the photos, the
    map and the localiser. `run_mission` drives it; the methods are its steps."""

    def __init__(self, robot: Robot, body: Body, photos: list[MissionPhoto], robot_map: RobotMap,
                 config: AdaptiveConfig, rng: np.random.Generator, observer: MissionObserver):
        self.robot, self.body, self.photos, self.map = robot, body, photos, robot_map
        self.config, self.rng, self.obs = config, rng, observer
        w, h = robot.image_size
        self.template = Camera(robot.intrinsics, w, h, np.eye(4))
        self.cam_height = float(np.linalg.inv(robot.cam_from_robot)[2, 3])
        self._features: dict[int, object] = {}
        self.fixes = self.failed = self.given_up = 0
        self.goals_reached: list[np.ndarray] = []
        self.tracks = stereo_tracks(self._model_cameras(), self._feats, config.localizer.triangulation)
        self.fmap = self._feature_map()

    # --- localisation -------------------------------------------------------------------
    def _feats(self, i: int):
        """SIFT features of photo i (computed once per mission)."""
        if i not in self._features:
            self._features[i] = sift_features(self.photos[i].photo.image, self.config.localizer.triangulation.n_features)
        return self._features[i]

    def _model_cameras(self) -> dict[int, Camera]:
        return {i: p.camera for i, p in enumerate(self.photos) if p.camera is not None and p.stage != "localise"}

    def _feature_map(self) -> FeatureMap:
        """SIFT + PnP map of the tracks so far (built once, then grown by `rebuild`)."""
        return FeatureMap(self.tracks.points, self.tracks.descriptors, self.tracks.owner, self.config.localizer)

    def pose_of_camera(self, cam_from_world: np.ndarray) -> np.ndarray:
        """SE(2) robot pose of a camera pose (the mount undone)."""
        world_from_robot = np.linalg.inv(cam_from_world) @ self.robot.cam_from_robot
        return np.array([world_from_robot[0, 3], world_from_robot[1, 3],
                         np.arctan2(world_from_robot[1, 0], world_from_robot[0, 0])])

    def localise_photo(self, photo: Photo):
        """PnP result (`PnPResult`) of a photo against the map if it passes the sanity
        checks (camera height; within `max_fix_jump_m` of the estimate, or 3 spreads), else None."""
        c = self.config
        res = self.fmap.localize(photo.image, self.template) if len(self.fmap) >= c.localizer.min_inliers else None
        if res is not None:
            centre = np.linalg.inv(res.cam_from_world)[:3, 3]
            pose = self.pose_of_camera(res.cam_from_world)
            if (abs(centre[2] - self.cam_height) < c.max_fix_height_err_m
                    and np.hypot(*(pose[:2] - self.body.est.pose[:2])) < max(c.max_fix_jump_m, 3 * self._spread())):
                self.fixes += 1
                return res
        self.failed += 1
        return None

    def _spread(self) -> float:
        return self.body.est.spread_m if isinstance(self.body, FilteredBody) else 0.0

    def take_photo(self, stage: str) -> MissionPhoto:
        """Capture, localise by vision: a good fix is the particle filter's measurement (a
        plain `Body` takes it as its estimate). A goal photo is posed by its fix, or, when
        PnP failed, at the filter's estimate."""
        photo = self.robot.capture()
        res = self.localise_photo(photo)
        fixed = res is not None
        cam = res.camera if fixed else None
        if fixed and isinstance(self.body, FilteredBody):
            self.body.est.update_pnp(self.pose_of_camera(res.cam_from_world), res.n_inliers)
        elif fixed:
            self.body.est.pose = self.pose_of_camera(res.cam_from_world)
        if not fixed and stage == "goal":
            cam = robot_camera(self.body.est.pose, self.robot.intrinsics, self.robot.image_size,
                               self.robot.cam_from_robot)
        if cam is not None:
            cam = cam.with_pose(cam.cam_from_world, name=f"photo_{len(self.photos):05d}")
        dr = self.body.est.dead_reckoning.pose.copy() if isinstance(self.body, FilteredBody) else None
        mp = MissionPhoto(photo, self.body.est.pose.copy(), stage, cam, dr)
        self.photos.append(mp)
        self.obs.photo(mp)
        self.obs.estimate(self.body.est.pose, "pnp" if fixed else "odometry")
        self.log_particles()
        return mp

    def log_particles(self) -> None:
        if isinstance(self.body, FilteredBody):
            self.obs.particles(self.body.est.pf.particles, self.body.est.pf.weights)

    # --- goals ----------------------------------------------------------------------------
    def choose_goals(self) -> tuple[np.ndarray, float, object]:
        """(goals (G, 3) best first, best score, free space) of this round."""
        c = self.config
        cams = [p.camera for p in self.photos if p.camera is not None and p.stage != "localise"]
        xy = np.array([cam.center[:2] for cam in cams])
        free = free_space_from_mesh(self.map.mesh, self.cam_height, xy)
        cand = sample_candidates(free, c.n_candidates, self.rng, c.clearance_m)
        vq = ViewQuality(self.map.mesh, cams, config=c.view_quality)
        try:
            scores = vq.score_poses(cand, self.template, self.robot.cam_from_robot)
        finally:
            vq.release()
        pick = pick_goals(cand, scores, c.goals_per_round, c.goal_separation_m)
        self.obs.map(self.map, free)
        self.obs.candidates(cand, scores, cand[pick])
        return cand[pick], float(scores.max(initial=0.0)), free

    def nav_grid(self, free):
        cams = np.array([p.estimate[:2] for p in self.photos])
        lo = np.minimum(cams.min(0), np.asarray(free.bounds[:2])) - 0.5
        hi = np.maximum(cams.max(0), np.asarray(free.bounds[2:])) + 0.5
        grid = nav_grid_from_points(self.map.points, (*lo, *hi), self.config.grid)
        self.obs.grid(grid)
        return grid

    # --- path following -----------------------------------------------------------------------
    def _aim_and_drive(self, target: np.ndarray):
        est = self.body.est.pose
        d = target - est[:2]
        turn = wrap_angle(np.arctan2(d[1], d[0]) - est[2])
        if abs(turn) > 1e-3:
            self.body.move(turn=float(turn))
        return self.body.move(drive=float(min(self.config.leg_m, np.hypot(*d))))

    def _recover(self, motion) -> None:
        """Back off an obstacle, turn away and drive a little off the path."""
        c = self.config
        self.body.move(drive=c.backoff_m if motion.bumper_rear else -c.backoff_m)
        self.body.move(turn=float(self.rng.uniform(np.pi / 4, np.pi / 2) * self.rng.choice([-1.0, 1.0])))
        self.body.move(drive=c.off_path_m)

    def go_to(self, goal: np.ndarray, grid) -> bool:
        """Drive to goal (3,) on the plan; True when reached."""
        c = self.config
        obstacles, legs = 0, 0
        while obstacles <= c.max_obstacles and legs < c.max_legs_per_goal:
            path = plan_path(grid, self.body.est.pose[:2], goal[:2], max_cost=c.max_path_cost)
            if path is None:
                return False
            self.obs.path(path)
            t, blocked = 1, False
            while t < len(path) and legs < c.max_legs_per_goal:
                last = t == len(path) - 1
                if np.hypot(*(path[t] - self.body.est.pose[:2])) < (c.reach_m if last else c.switch_m):
                    if last:
                        self.take_photo("localise")  # check the arrival by vision
                        if np.hypot(*(path[t] - self.body.est.pose[:2])) < c.reach_m + 0.05:
                            return True
                        legs += 1
                        continue
                    t += 1
                    self.take_photo("localise")  # vision fix at every path node
                    continue
                motion = self._aim_and_drive(path[t])
                legs += 1
                if motion.blocked:
                    obstacles += 1
                    self._recover(motion)
                    blocked = True
                    break
                self.log_particles()
                if isinstance(self.body, FilteredBody) and self.body.est.needs_fix():
                    self.take_photo("localise")  # the filter's spread grew: look before going on
            if not blocked:
                return legs < c.max_legs_per_goal
            self.take_photo("localise")
        return False

    def _face(self, heading: float) -> None:
        turn = wrap_angle(heading - self.body.est.pose[2])
        if abs(turn) > 1e-3:
            self.body.move(turn=float(turn))

    def capture_at(self, goal: np.ndarray, budget: int) -> list[MissionPhoto]:
        """A stereo pair at the goal (at most `budget` photos): one photo facing the goal
        heading, then one after a side step of `stereo_baseline_m` (to the other side when
        the first is blocked), so what the goal sees is seen from two directions."""
        c = self.config
        self._face(goal[2])
        out = [self.take_photo("goal")]
        for k in range(1, min(c.photos_per_goal, budget)):
            side = goal[2] + (np.pi / 2 if k % 2 else -np.pi / 2)
            self._face(side)
            motion = self.body.move(drive=c.stereo_baseline_m * k)
            if motion.blocked:
                self.body.move(drive=-c.backoff_m)
            self._face(goal[2])
            out.append(self.take_photo("goal"))
        return out

    def rebuild(self, new: list[MissionPhoto]) -> None:
        """Add the new posed photos' tracks to the map (mesh rebuilt) and the localiser."""
        cams = self._model_cameras()
        new_ids = {i for i in cams if any(self.photos[i] is q for q in new)}
        if not new_ids:
            return
        tracks = stereo_tracks(cams, self._feats, self.config.localizer.triangulation, only=new_ids)
        self.map = extend_map(self.map, {i: cams[i] for i in new_ids}, tracks, self.config.map)
        self.tracks = self.tracks + tracks
        self.fmap = self._feature_map()


def start_filter(robot: Robot, body: Body, photos: list[MissionPhoto], rmap: RobotMap,
                 config: AdaptiveConfig, rng: np.random.Generator) -> FilteredBody:
    """The adaptive stage's body: the particle filter starts at the last random photo's SfM
    pose when SfM posed it (the robot has not moved since), else at the dead reckoning."""
    last = len(photos) - 1
    start, std = body.est.pose, None
    if last in rmap.cameras:
        w2r = rmap.cameras[last].world_from_cam @ robot.cam_from_robot
        start = np.array([w2r[0, 3], w2r[1, 3], np.arctan2(w2r[1, 0], w2r[0, 0])])
        std = np.array([0.1, 0.1, np.radians(3.0)])
    xy = np.array([c.center[:2] for c in rmap.cameras.values()] or [start[:2]])
    loc = MissionLocalizer(start, np.r_[xy, start[None, :2]], config.filter, rng, std)
    return FilteredBody(robot, loc, body.path_m)


def _random_stage(robot: Robot, start_pose: np.ndarray, n_random: int, rcfg: RandomExplorationConfig,
                  rng: np.random.Generator, obs: MissionObserver, journal) -> tuple[list[MissionPhoto], Body]:
    """Random exploration up to `n_random` photos, after those the journal kept (replayed on
    a simulator, checked; a real robot goes on from its last logged estimate)."""
    photos = journal.resumed_photos(lambda r, ph: MissionPhoto(ph, np.asarray(r["pose"], float), "random"))
    skip, start, path_m = len(photos), start_pose, 0.0
    if skip and not journal.replayable:
        state = journal.last_state() or {}
        start, path_m = np.asarray(state.get("estimate", photos[-1].estimate), float), state.get("path_m", 0.0)
        rcfg, skip = replace(rcfg, n_photos=n_random - len(photos)), 0
    else:
        rcfg = replace(rcfg, n_photos=n_random)
    body = Body(robot, start)
    body.path_m = path_m
    if len(photos):
        obs.progress(f"random exploration: resuming after {len(photos)} logged photos")
    for k, shot in enumerate(random_exploration(robot, start, rcfg, rng, body) if len(photos) < n_random
                             or journal.replayable else ()):
        if k < skip:
            journal.check_replay(photos[k], shot)
            continue
        photos.append(MissionPhoto(shot.photo, shot.estimate, "random"))
        obs.photo(photos[-1])
        obs.estimate(shot.estimate, "odometry")
        journal.random_photo_done(body)
        if len(photos) % 10 == 0:
            obs.progress(f"random exploration: {len(photos)}/{n_random} photos, {body.path_m:.1f} m driven")
    return photos, body


def _start_adaptive(robot: Robot, start_pose: np.ndarray, n_random: int, rcfg: RandomExplorationConfig,
                    config: AdaptiveConfig, rng: np.random.Generator, obs: MissionObserver,
                    journal) -> tuple[AdaptiveMission, MissionResult]:
    """Random exploration, the initial map and the first vision fix; committed as round 0."""
    photos, body = _random_stage(robot, start_pose, n_random, rcfg, rng, obs, journal)
    obs.progress(f"initial map: SfM of {len(photos)} photos")
    rmap = initial_map([p.photo.image for p in photos], robot.intrinsics, np.array([p.estimate for p in photos]),
                       np.array([p.photo.compass_rad for p in photos]), robot.cam_from_robot, config.map)
    for i, cam in rmap.cameras.items():
        photos[i].camera = cam
    obs.progress(f"initial map: {rmap.registered}/{len(photos)} photos posed, {len(rmap.points)} points, "
                 f"{len(rmap.mesh.faces)} faces")
    result = MissionResult(photos, rmap)
    mission = AdaptiveMission(robot, start_filter(robot, body, photos, rmap, config, rng), photos, rmap,
                              config, rng, obs)
    mission.take_photo("localise")
    journal.round_done(mission, result)
    return mission, result


def _resume_adaptive(robot: Robot, state: dict, config: AdaptiveConfig, rng: np.random.Generator,
                     obs: MissionObserver, journal) -> tuple[AdaptiveMission, MissionResult]:
    """The adaptive stage as committed after `state["rounds"]` rounds (`robot.mission_journal`)."""
    from robot.mission_journal import restore_adaptive

    rmap, cams = journal.load_map(state)
    photos = journal.resumed_photos(lambda r, ph: MissionPhoto(ph, np.asarray(r["pose"], float), r["stage"],
                                                               cams.get(int(r["index"]))))
    xy = np.array([c.center[:2] for c in rmap.cameras.values()])
    loc = MissionLocalizer(np.asarray(state["dead_reckoning"], float), xy, config.filter, rng)
    loc.pf.particles, loc.pf.log_w = np.asarray(state["particles"], float), np.asarray(state["log_w"], float)
    loc._update_estimate()
    restore_adaptive(journal, state, robot, rng)  # after the filter's set-up drew from rng
    mission = AdaptiveMission(robot, FilteredBody(robot, loc, state["path_m"]), photos, rmap, config, rng, obs)
    mission.fixes, mission.failed, mission.given_up = state["fixes"], state["failed"], state["given_up"]
    mission.goals_reached = [np.asarray(g, float) for g in state["goals"]]
    result = MissionResult(photos, rmap, rounds=state["rounds"])
    obs.progress(f"resumed after adaptive round {state['rounds']}: {len(result.model_photos)} photos, "
                 f"{len(rmap.points)} map points")
    return mission, result


def run_mission(robot: Robot, start_pose: np.ndarray, n_random: int, photo_budget: int,
                config: AdaptiveConfig = AdaptiveConfig(), rng: np.random.Generator | None = None,
                observer: MissionObserver | None = None,
                random_config: RandomExplorationConfig | None = None, journal=None) -> MissionResult:
    """The whole capture mission: random exploration (`n_random` photos), the initial map,
    then adaptive rounds until the best candidate's gain is below `config.min_gain_rad`, the
    model holds `photo_budget` photos, or `config.max_rounds`. `start_pose` (3,) is known.
    `journal` (`robot.mission_journal.SessionJournal`): commit each step to a capture session
    and resume from what it holds (default: neither)."""
    from robot.mission_journal import MissionJournal

    rng = rng or np.random.default_rng(0)
    obs = observer or MissionObserver()
    journal = journal or MissionJournal()
    if n_random > photo_budget:
        raise InputError(f"{n_random} random photos exceed the photo budget of {photo_budget}")
    state = journal.adaptive_state()
    if state is None:
        mission, result = _start_adaptive(robot, start_pose, n_random, random_config or RandomExplorationConfig(),
                                          config, rng, obs, journal)
    else:
        mission, result = _resume_adaptive(robot, state, config, rng, obs, journal)
    result.stop_reason = "max rounds"
    for r in range(result.rounds, config.max_rounds):
        left = photo_budget - len(result.model_photos)
        if left <= 0:
            result.stop_reason = "photo budget"
            break
        goals, best, free = mission.choose_goals()
        obs.progress(f"round {r + 1}: best candidate gain {np.degrees(best):.1f} deg, {len(goals)} goals, "
                     f"{len(result.model_photos)} photos")
        if best < config.min_gain_rad or len(goals) == 0:
            result.stop_reason = f"gain {np.degrees(best):.2f} deg below threshold"
            break
        _adaptive_round(mission, result, goals, mission.nav_grid(free), photo_budget, r, obs)
        result.rounds = r + 1
        journal.round_done(mission, result)
    result.robot_map, result.path_m = mission.map, mission.body.path_m
    result.goals, result.given_up = mission.goals_reached, mission.given_up
    result.fixes, result.failed_fixes = mission.fixes, mission.failed
    return result


def _adaptive_round(mission: AdaptiveMission, result: MissionResult, goals: np.ndarray, grid, photo_budget: int,
                    r: int, obs: MissionObserver) -> None:
    """Visit the round's goals (photos at each one reached) and rebuild the map."""
    new = []
    for g in goals:
        left = photo_budget - len(result.model_photos)
        if left <= 0:
            break
        if mission.go_to(g, grid):
            new += mission.capture_at(g, left)
            mission.goals_reached.append(g)
        else:
            mission.given_up += 1
            obs.progress(f"round {r + 1}: gave up a goal at ({g[0]:.2f}, {g[1]:.2f})")
    mission.rebuild(new)


def run_random_only(robot: Robot, start_pose: np.ndarray, photo_budget: int,
                    rng: np.random.Generator | None = None, observer: MissionObserver | None = None,
                    random_config: RandomExplorationConfig | None = None) -> MissionResult:
    """The baseline: random exploration for the whole photo budget (no map, no goals)."""
    obs = observer or MissionObserver()
    body = Body(robot, start_pose)
    photos = []
    rcfg = replace(random_config or RandomExplorationConfig(), n_photos=photo_budget)
    for shot in random_exploration(robot, start_pose, rcfg, rng or np.random.default_rng(0), body):
        photos.append(MissionPhoto(shot.photo, shot.estimate, "random"))
        obs.photo(photos[-1])
        if len(photos) % 20 == 0:
            obs.progress(f"random exploration: {len(photos)}/{photo_budget} photos")
    return MissionResult(photos, None, path_m=body.path_m, stop_reason="photo budget")
