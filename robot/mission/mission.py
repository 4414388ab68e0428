"""The scene-capture mission of Foster, Wang & Grupen, start to end: random exploration
(`robot.mission.random_stage`), the initial map (`robot.mission.map_building`), then adaptive
rounds (`robot.mission.adaptive`) until the gain runs out or the photo budget is spent.
`run_mission` resumes from a journal (`robot.mission.journal`) when given one;
`run_random_only` is the baseline that spends the whole budget on random exploration.
Progress goes to this module's logger; everything else is reported to a `MissionObserver`.
Frames: world SE(2) poses (x, y, theta), metres, radians.
"""

from __future__ import annotations

import itertools
import logging
import math
import shutil
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ibr.errors import InputError
from robot.mission.adaptive import AdaptiveConfig, AdaptiveMission, start_filter
from robot.mission.journal import MissionJournal, restore_adaptive
from robot.mission.localizer import FilteredBody, MissionLocalizer
from robot.mission.circles import circle_ids
from robot.mission.map_building import MapConfig, MapError, RobotMap, capture_model, forget_model, initial_map
from robot.mission.observer import MissionObserver, MissionPhoto
from robot.mission.random_stage import Body, RandomExplorationConfig, random_exploration, steps_per_circle
from robot.mission.watchdog import watchdog
from robot.protocol import Robot

log = logging.getLogger(__name__)


@dataclass
class MissionResult:
    """photos: every photo in order; robot_map: the final map, meshed as the capture's model
    (`map_building.capture_model`); path_m: distance driven (m, odometry); rounds: adaptive
    rounds run; goals: (G, 3) goals reached; given_up: goals abandoned; fixes/failed_fixes:
    PnP localisations accepted / failed or rejected; failure_reasons: the failed ones'
    count per reason (`adaptive.FIX_FAILURES`); stop_reason: why the adaptive stage ended,
    in words."""

    photos: list[MissionPhoto]
    robot_map: RobotMap | None
    path_m: float = 0.0
    rounds: int = 0
    goals: list = field(default_factory=list)
    given_up: int = 0
    obstacles_met: dict[str, int] = field(default_factory=dict)
    """Drives a bumper or a stall stopped, by the drive (`adaptive.OBSTACLE_DRIVES`)."""
    fixes: int = 0
    tilted_fixes: int = 0
    """Of `fixes`, those only the tilted retry found (`AdaptiveConfig.retry_tilts`)."""
    weak_fixes: int = 0
    """Of `fixes`, those too weak to pose their photo (`AdaptiveConfig.max_seed_m_per_px`)."""
    failed_fixes: int = 0
    failure_reasons: dict[str, int] = field(default_factory=dict)
    stop_reason: str = ""
    stopped_because: str = ""
    """complete | budget | no reachable goal (`adaptive_rounds`)."""
    final_spread_m: float | None = None
    """The particle filter's position spread at the end (m; None without a filter)."""
    localised: bool | None = None
    """Whether the robot knows where it is at the end: the spread within
    `MissionFilterConfig.relocalise_std_m` (None without a filter). Lost, the poses of its
    last photos are guesses: a report says so instead of passing them off as a capture."""

    start_anchored: bool | None = None
    """Whether SfM posed a photo of the start circle, so the map's place in the world rests
    on photos taken at the known start (`start_anchored`; None: no first map this run, or
    a resumed one, whose first map the journal does not keep)."""

    first_map_photos: frozenset[int] | None = None
    """The photos (indices into `photos`) the first map posed, whose cameras later steps keep:
    the map's own scale is theirs (`evaluation.map_scale_error` over them). Photos a
    re-posing adds carry their own position errors (None: a resumed run, as above)."""

    @property
    def model_photos(self) -> list[MissionPhoto]:
        """The photos of the model (random + goal; not those taken only to localise)."""
        return [p for p in self.photos if p.stage != "localise"]


class RandomStage:
    """The random exploration as the mission runs it: photos taken (or replayed from the
    `journal`: on a simulator checked against the log, on a real robot not retaken, going on
    from the last logged estimate) up to a count by `take`, and more later from where the
    robot stands when the first map asks for them (`_first_map`), as if the stage had been
    planned that long. At most `budget` photos."""

    def __init__(self, robot: Robot, start_pose: np.ndarray, rcfg: RandomExplorationConfig,
                 rng: np.random.Generator, obs: MissionObserver, journal, budget: int):
        self.logged = journal.resumed_photos(lambda r, ph: MissionPhoto(ph, np.asarray(r["pose"], float), "random"))
        self.photos: list[MissionPhoto] = []
        self.obs, self.journal, self.per_circle = obs, journal, steps_per_circle(rcfg)
        start, path_m = start_pose, 0.0
        if self.logged and not journal.replayable:
            state = journal.last_state() or {}
            start, path_m = np.asarray(state.get("estimate", self.logged[-1].estimate), float), state.get("path_m", 0.0)
            self.photos, self.logged = self.logged, []
            log.info(f"random exploration: resuming after {len(self.photos)} logged photos")
        elif self.logged:
            log.info(f"random exploration: replaying {len(self.logged)} logged photos")
        self.body = Body(robot, start)
        self.body.path_m = path_m
        self.shots = random_exploration(robot, start, replace(rcfg, n_photos=max(budget - len(self.photos), 0)), rng,
                                        self.body)

    @property
    def n_logged(self) -> int:
        """Random photos the journal held (all of them replayed or kept)."""
        return max(len(self.logged), len(self.photos))

    def take(self, n: int) -> None:
        """Photos up to `n` in all (fewer when the budget runs out)."""
        for shot in itertools.islice(self.shots, max(n - len(self.photos), 0)):
            k = len(self.photos)
            if k < len(self.logged):
                self.journal.check_replay(self.logged[k], shot)
                self.photos.append(self.logged[k])
                continue
            self.photos.append(MissionPhoto(shot.photo, shot.estimate, "random"))
            self.obs.photo(self.photos[-1])
            self.obs.estimate(shot.estimate, "odometry")
            self.journal.random_photo_done(self.body)
            if len(self.photos) % 10 == 0:
                log.info(f"random exploration: {len(self.photos)}/{n} photos, {self.body.path_m:.1f} m driven")


def run_random_stage(robot: Robot, start_pose: np.ndarray, n_random: int, rcfg: RandomExplorationConfig,
                     rng: np.random.Generator, obs: MissionObserver, journal) -> tuple[list[MissionPhoto], Body]:
    """Random exploration up to `n_random` photos, after those the journal kept (replayed on
    a simulator, checked; a real robot goes on from its last logged estimate)."""
    stage = RandomStage(robot, start_pose, rcfg, rng, obs, journal, n_random)
    stage.take(n_random)
    return stage.photos, stage.body


def _first_map(stage: RandomStage, robot: Robot, n_random: int, config: AdaptiveConfig,
               work: Path | None = None) -> RobotMap:
    """The initial map of the random stage's `n_random` photos. While SfM cannot map them or
    the floor cannot check the map's scale (`RobotMap.floor_scaled`: no two stops saw a
    common floor, as in a map of one spot, or the pairs disagree, as in a wrong layout), the
    stage goes on for another circle and the map is built again, at most
    `config.extra_random_circles` times within the budget; then the last map, or its error.
    A resumed stage first takes the whole circles the journal holds photos of. Every build
    runs in the SfM workspace `work` (None: a temporary one each), so a build after another
    circle extracts and matches only that circle's photos (`initial_map`)."""
    per_circle = stage.per_circle
    stage.take(n_random + per_circle * _circles_beyond(stage.n_logged, n_random, per_circle))
    while True:
        photos = stage.photos
        rmap, error = _map_or_error(photos, robot, config, work)
        if rmap is not None and rmap.floor_scaled is not False:
            return rmap
        why = (f"SfM failed ({error})" if rmap is None else
               "the floor did not check its scale (too few pairs of photos from two stops, or pairs that disagree)")
        before = len(photos)
        if _circles_beyond(before, n_random, per_circle) < config.extra_random_circles:
            stage.take(before + per_circle)
        if len(stage.photos) == before:  # no circle left to take
            if rmap is None:
                raise error
            log.warning(f"initial map: {why}; going on with it")
            return rmap
        log.warning(f"initial map: {why}; took another circle of {len(stage.photos) - before} random photos")


def _map_or_error(photos: list[MissionPhoto], robot: Robot, config: AdaptiveConfig, work: Path | None = None
                  ) -> tuple[RobotMap | None, MapError | None]:
    """(`initial_map` of the random `photos` in the SfM workspace `work`, None), or (None, its MapError)."""
    log.info(f"initial map: SfM of {len(photos)} photos")
    try:
        return initial_map([p.photo.image for p in photos], robot.intrinsics, np.array([p.estimate for p in photos]),
                           np.array([p.photo.compass_rad for p in photos]), robot.cam_from_robot, config.map,
                           np.array([p.photo.range_m for p in photos]), work), None
    except MapError as e:
        return None, e


def _circles_beyond(n_photos: int, n_random: int, per_circle: int) -> int:
    """Circles of random photos begun beyond the first `n_random` of `n_photos`."""
    return math.ceil(max(n_photos - n_random, 0) / per_circle)


def start_anchored(cameras: dict, photos: list[MissionPhoto], config: MapConfig = MapConfig()) -> bool:
    """Whether the map's `cameras` {photo index: Camera} hold a photo of the random stage's
    first circle, taken at the known start (the `photos`' dead reckoning tells the circles
    apart, `circle_ids`). When none does, `place_models` put the map at the start by the
    odometry of the drives alone: apartments 2 and 9 had their whole first map 16-27 cm off
    the world, and every later fix with it (SfM had posed no photo of their start circles;
    PnP of those photos against the map found 1 of 36 and 0 of 36). The random stage's short
    first drive (`RandomExplorationConfig.first_drive_m`) makes it rare: none of 20
    apartments' first maps missed their start circle with it, 4 of 20 without."""
    random = [i for i, p in enumerate(photos) if p.stage == "random"]
    circle = circle_ids(np.array([photos[i].estimate for i in random]).reshape(-1, 3), config.circles)
    return any(i in cameras for i, c in zip(random, circle) if c == 0)


def _warn_unanchored(rmap: RobotMap, photos: list[MissionPhoto], config: MapConfig) -> bool:
    """`start_anchored` of the first map, with a warning naming the odometry it rests on when
    it is not."""
    if start_anchored(rmap.cameras, photos, config):
        return True
    start = photos[0].estimate[:2]
    d = min(float(np.hypot(*(photos[i].estimate[:2] - start))) for i in rmap.cameras)
    log.warning(f"initial map: SfM posed no photo of the start circle; the map stands at the known start by "
                f"{d:.1f} m of odometry, so its place in the world may be off by about "
                f"{100 * config.circles.odometry_drift * d:.0f} cm")
    return False


def _start_adaptive(robot: Robot, start_pose: np.ndarray, n_random: int, photo_budget: int,
                    rcfg: RandomExplorationConfig, config: AdaptiveConfig, rng: np.random.Generator,
                    obs: MissionObserver, journal) -> tuple[AdaptiveMission, MissionResult]:
    """Random exploration, the initial map (`_first_map`) and the first vision fix;
    committed as round 0. The first map's SfM workspace becomes the adaptive stage's
    (`AdaptiveMission.repose`), its model forgotten: the re-posings map afresh as before,
    but extract and match only the photos and pairs the random stage's lack."""
    stage = RandomStage(robot, start_pose, rcfg, rng, obs, journal, photo_budget)
    work = Path(tempfile.mkdtemp(prefix="ibrnav_sfm_"))
    try:
        rmap = _first_map(stage, robot, n_random, config, work)
        forget_model(work)
        photos, body = stage.photos, stage.body
        for i, cam in rmap.cameras.items():
            photos[i].camera = cam
        log.info(f"initial map: {rmap.registered}/{len(photos)} photos posed, {len(rmap.points)} points, "
                 f"{len(rmap.mesh.faces)} faces")
        result = MissionResult(photos, rmap, start_anchored=_warn_unanchored(rmap, photos, config.map),
                               first_map_photos=frozenset(rmap.cameras))
        mission = AdaptiveMission(robot, start_filter(robot, body, photos, rmap, config, rng), photos, rmap,
                                  config, rng, obs, sfm_work=work)  # removed with the mission from now on
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise
    mission.take_photo("localise")
    journal.round_done(mission, result)
    return mission, result


def _resume_adaptive(robot: Robot, state: dict, config: AdaptiveConfig, rng: np.random.Generator,
                     obs: MissionObserver, journal) -> tuple[AdaptiveMission, MissionResult]:
    """The adaptive stage as committed after `state["rounds"]` rounds (`robot.mission.journal`)."""
    rmap, cams = journal.load_map(state)
    photos = journal.resumed_photos(lambda r, ph: MissionPhoto(ph, np.asarray(r["pose"], float), r["stage"],
                                                               cams.get(int(r["index"])), fixed=r.get("fixed")))
    xy = np.array([c.center[:2] for c in rmap.cameras.values()])
    loc = MissionLocalizer(np.asarray(state["dead_reckoning"], float), xy, config.filter, rng)
    loc.set_particles(state["particles"], state["log_w"])
    restore_adaptive(journal, state, robot, rng)  # after the filter's set-up drew from rng
    mission = AdaptiveMission(robot, FilteredBody(robot, loc, state["path_m"]), photos, rmap, config, rng, obs,
                              unfixed={int(i) for i in state.get("unfixed", [])},
                              reposed={int(i) for i in state.get("reposed", [])})
    mission.fixes, mission.failed, mission.given_up = state["fixes"], state["failed"], state["given_up"]
    mission.failure_reasons.update(state.get("failure_reasons", {}))
    mission.tilted_fixes = state.get("tilted_fixes", 0)
    mission.weak_fixes = state.get("weak_fixes", 0)
    mission.failed_at_repose = state.get("failed_at_repose", 0)
    mission.goals_reached = [np.asarray(g, float) for g in state["goals"]]
    mission.given_up_goals = [np.asarray(g, float) for g in state.get("given_up_goals", [])]
    mission.bumps = [np.asarray(b, float) for b in state.get("bumps", [])]
    mission.obstacles_met.update(state.get("obstacles_met", {}))
    mission.trail = [np.asarray(s, float) for s in state.get("trail", [])]
    mission.swept = [np.asarray(s, float) for s in state.get("swept", [])]
    mission.sonar_readings = [np.asarray(s, float) for s in state.get("sonar_readings", [])]
    if state.get("stepped_from") is not None:  # the last round ended on a stereo pair's side step
        mission.stepped_from = np.asarray(state["stepped_from"], float)
    result = MissionResult(photos, rmap, rounds=state["rounds"])
    log.info(f"resumed after adaptive round {state['rounds']}: {len(result.model_photos)} photos, "
                 f"{len(rmap.points)} map points")
    return mission, result


def run_mission(robot: Robot, start_pose: np.ndarray, n_random: int, photo_budget: int,
                config: AdaptiveConfig = AdaptiveConfig(), rng: np.random.Generator | None = None,
                observer: MissionObserver | None = None,
                random_config: RandomExplorationConfig | None = None, journal=None) -> MissionResult:
    """The whole capture mission: random exploration (`n_random` photos), the initial map,
    then adaptive rounds until no reachable candidate gains more than `config.min_gain_rad`,
    none is reachable, the model holds `photo_budget` photos, or after `config.max_rounds`
    (when set; `adaptive_rounds`). `start_pose` (3,) is known.
    `journal` (`robot.mission.journal.SessionJournal`): commit each step to a capture session
    and resume from what it holds (default: neither)."""
    rng = rng or np.random.default_rng(0)
    obs = observer or MissionObserver()
    journal = journal or MissionJournal()
    if n_random > photo_budget:
        raise InputError(f"{n_random} random photos exceed the photo budget of {photo_budget}")
    state = journal.adaptive_state()
    if state is None:
        mission, result = _start_adaptive(robot, start_pose, n_random, photo_budget,
                                          random_config or RandomExplorationConfig(), config, rng, obs, journal)
    else:
        mission, result = _resume_adaptive(robot, state, config, rng, obs, journal)
    adaptive_rounds(mission, result, photo_budget, journal)
    result.robot_map, result.path_m = capture_model(mission.map, config.map), mission.body.path_m
    log.info(f"the capture's model: {len(result.robot_map.mesh.faces)} faces over {len(mission.map.points)} map "
             f"points (the map's proxy: {len(mission.map.mesh.faces)})")
    result.goals, result.given_up = mission.goals_reached, mission.given_up
    result.obstacles_met = dict(mission.obstacles_met)
    result.fixes, result.failed_fixes, result.tilted_fixes = mission.fixes, mission.failed, mission.tilted_fixes
    result.failure_reasons, result.weak_fixes = dict(mission.failure_reasons), mission.weak_fixes
    tried = mission.fixes + mission.failed
    tilted = f" ({mission.tilted_fixes} by the tilted retry)" if mission.config.retry_tilts else ""
    weak = f", {mission.weak_fixes} too weak to pose their photo" if mission.config.max_seed_m_per_px else ""
    log.info(f"vision fixes: {mission.fixes} of {tried} photos{tilted}{weak}; failed: "
             + ", ".join(f"{reason} {n}" for reason, n in mission.failure_reasons.items()))
    if isinstance(mission.body, FilteredBody):
        say_if_lost(result, mission.body.est)
    return result


def say_if_lost(result: MissionResult, localizer: MissionLocalizer) -> None:
    """Set `result.final_spread_m` and `result.localised` from the mission's filter at the
    end, with a warning when the robot is lost."""
    result.final_spread_m = localizer.spread_m
    result.localised = not localizer.needs_fix()
    if not result.localised:
        log.warning(f"the robot is lost at the end: its filter's spread is {result.final_spread_m:.2f} m "
                    f"(localised within {localizer.config.relocalise_std_m:.2f} m); the poses of its last "
                    f"photos are dead reckoning, not fixes")


def adaptive_rounds(mission: AdaptiveMission, result: MissionResult, photo_budget: int, journal=None) -> None:
    """Adaptive rounds from `result.rounds` on until the mission stops on its own; sets
    `result.stopped_because` ("complete": no reachable candidate gains more than
    `min_gain_rad` and no frontier goal is left; "budget": the photo budget or `max_rounds`
    (when set) is spent; "no reachable goal": no candidate is left that the robot can drive
    to) and `result.stop_reason` (in words).
    Each step runs under the watchdog (`AdaptiveConfig.step_limit_s`)."""
    config = mission.config
    journal = journal or MissionJournal()
    result.stopped_because, result.stop_reason = "budget", f"{config.max_rounds} rounds"
    rounds = itertools.count(result.rounds) if config.max_rounds is None else range(result.rounds, config.max_rounds)
    for r in rounds:
        if photo_budget - len(result.model_photos) <= 0:
            result.stop_reason = f"photo budget of {photo_budget} reached"
            break
        with watchdog(f"round {r + 1}: choosing goals", config.step_limit_s):
            goals, best, grid = mission.choose_goals()
        log.info(f"round {r + 1}: best reachable candidate gains {np.degrees(best):.1f} deg, {len(goals)} goals "
                 f"({mission.n_frontier_goals} at frontiers), {len(result.model_photos)} photos")
        if len(goals) == 0 and mission.n_candidates == 0:
            result.stopped_because, result.stop_reason = "no reachable goal", "no candidate the robot can reach"
            break
        if len(goals) == 0:
            result.stopped_because = "complete"
            result.stop_reason = (f"best reachable gain {np.degrees(best):.2f} deg below "
                                  f"{np.degrees(config.min_gain_rad):.2f} deg, no frontier left")
            break
        _adaptive_round(mission, result, goals, grid, photo_budget, r)
        result.rounds = r + 1
        journal.round_done(mission, result)
    log.info(f"adaptive stage stopped: {result.stopped_because} ({result.stop_reason})")


def _adaptive_round(mission: AdaptiveMission, result: MissionResult, goals: np.ndarray, grid, photo_budget: int,
                    r: int) -> None:
    """Visit the round's goals (photos at each one reached) and rebuild the map. A goal
    given up is remembered (`AdaptiveMission.given_up_goals`): none is drawn near it again,
    and this round's goals near it are skipped (apartment 3: five goals in one bed, each
    given up in turn). The log line of a goal given up says the filter's spread then (m)."""
    new, limit = [], mission.config.step_limit_s
    for k, g in enumerate(goals):
        left = photo_budget - len(result.model_photos)
        if left <= 0:
            break
        if mission.near_given_up(g[None, :2])[0]:  # this round gave up a goal next to it
            log.info(f"round {r + 1}: skipped a goal at ({g[0]:.2f}, {g[1]:.2f}) next to one given up")
            continue
        with watchdog(f"round {r + 1}: driving to goal {k + 1} at ({g[0]:.2f}, {g[1]:.2f})", limit):
            reached = mission.go_to(g, grid)
            if reached:
                if k >= len(goals) - mission.n_frontier_goals:  # the round's last goals are its frontiers'
                    mission.sweep_ultrasonic()
                new += mission.capture_at(g, left)
            mission.grow_tracks()
        if reached:
            mission.goals_reached.append(g)
        else:
            mission.given_up += 1
            mission.given_up_goals.append(np.asarray(g, float))
            est, spread = mission.body.est.pose, mission.spread()
            log.info(f"round {r + 1}: gave up a goal at ({g[0]:.2f}, {g[1]:.2f}) ({mission.give_up_reason}; "
                     f"estimate ({est[0]:.2f}, {est[1]:.2f}), spread {spread:.2f} m)")
    with watchdog(f"round {r + 1}: rebuilding the map with {len(new)} photos", limit):
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
            log.info(f"random exploration: {len(photos)}/{photo_budget} photos")
    return MissionResult(photos, None, path_m=body.path_m, stop_reason="photo budget", stopped_because="budget")
