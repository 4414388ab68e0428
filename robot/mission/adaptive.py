"""Adaptive exploration: the second stage of Foster, Wang & Grupen's scene capture (IV-B, IV-C).

From the map of the photos so far (`robot.mission.map_building`), each round:
1. slices the mesh at the camera height for the free-space boundary and samples random
   candidate poses inside it (`explore.candidates`), keeping those some photo saw through
   (`ViewQuality.seen_free`: not behind a wall of the map nor inside furniture), that the
   robot can reach on the navigation grid, and not near a goal given up before;
2. scores all candidates in one batched pass of the rendering-quality heuristic
   (`explore.view_quality.ViewQuality`: mean smallest angle between a pixel's desired ray
   and the rays to the source photos that see its point; higher = more to gain);
3. picks the best goals (greedy, spread apart; optionally, `far_goals_per_round` of them
   look the farthest across open space instead, `far_goals`), adds goals at the frontiers of the
   ultrasonic's occupancy grid (`explore.frontier`: beyond doorways into rooms the map has
   no points of, where no candidate is drawn), and stops when the best score is below
   `AdaptiveConfig.min_gain_rad` and no frontier is left;
4. drives to each goal: a KDE navigation grid from the above-ground map points, A* and path
   simplification (`explore.nav_grid`, `explore.path_simplify`); the robot follows the path by
   target-node switching within `switch_m` on the estimate of an SE(2) particle filter
   (`robot.mission.localizer`): odometry and compass between nodes, *vision* at the nodes
   (SIFT + RANSAC PnP against the map, `localization.feature_localizer`, as a mixture
   proposal, only when level, `max_fix_tilt_px`, and turned from the compass-held estimate by at
   most `max_fix_turn_deg`; a localise photo first turns to the map's
   points, `robot.mission.look_heading`; after a failed fix it looks the way the
   nearest map photo looked and tries again (`LookConfig.occlude`, off by default: both
   headings count only the points the map's mesh does not hide); photos without a fix, or
   fixed only where the filter was lost, stay out of the map's tracks), and an extra photo when the filter's
   spread grows too large: the plan consumes the filter's estimate, never a simulator's
   truth. On an obstacle it marks the contact point blocked on the grid (for this goal;
   dear for every later one), backs off, drives a little off the path and re-plans; after
   `max_obstacles` obstacles it gives the goal up and takes the next (`keep_off_surfaces`,
   off by default: the grid is dear where the robot would touch a surface the ultrasonic
   met, and the drive off the path goes to the side clear of them);
5. photographs at each goal and localises those photos; after every goal, the photos a fix
   posed since (goal and localise photos) add their tracks to what PnP matches against
   (`grow_tracks`), and after the round the map is rebuilt with the goal photos
   (triangulation with the localised poses fixed, Poisson mesh, `rebuild`; with `bundle`, the
   photos posed since the first map are bundle-adjusted first, `adjust`).

Algorithm code only: what happens is reported to a `MissionObserver`
(`robot.mission.observer`); `robot.mission.mission.run_mission` runs the rounds. Frames: world SE(2) poses (x, y, theta), metres, radians.
"""

from __future__ import annotations

import logging
import shutil
import tempfile
import time
import weakref
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np
from trimesh.ray.ray_pyembree import RayMeshIntersector

from explore.candidates import free_space_from_mesh, sample_candidates
from explore.frontier import SonarConfig, SonarGrid, frontiers, revealed, sonar_grid, toward_unknown
from explore.nav_grid import NavGridConfig, nav_grid_from_points, near_segments, reachable_at, reachable_mask
from explore.path_simplify import plan_path
from explore.view_run import view_runs
from explore.view_quality import ViewQuality, ViewQualityConfig
from ibr.camera import Camera
from ibr.errors import InputError
from ibr.proxy.triangulation import TriangulationConfig, sift_features
from localization.feature_localizer import FeatureLocalizerConfig, FeatureMap
from localization.motion_models import wrap_angle
from robot.mission.bundle import BundleConfig, PairMatches, adjust_grown
from robot.mission.fix_precision import bias_sensitivity
from robot.mission.localizer import FilteredBody, MissionFilterConfig, MissionLocalizer
from robot.mission.look_heading import LookConfig, Occluder, hidden_by, look_heading, retry_heading
from robot.mission.map_building import (MapConfig, RobotMap, Tracks, at_mount_height, extend_map, robot_pose,
                                        stereo_tracks)
from robot.mission.observer import MissionObserver, MissionPhoto
from robot.mission.random_stage import Body
from robot.mission.repose import ReposeConfig, odometry_held, repose_photos
from robot.protocol import Photo, Robot, robot_camera

log = logging.getLogger(__name__)

PRECISE_SEEDS_M_PER_PX = 0.075
"""`AdaptiveConfig.max_seed_m_per_px` with `explore --precise-seeds`: the issue's
95th-percentile bar (15 cm) over a shared error of a map's points of 2 px (the true camera
reprojected the inliers of the fixes right to 5 cm at 1.5 px at the median on apartments 2
and 6, traced). There it would have kept 14 of apartment 2's 51 posed fixes 10-22 cm off
from posing their photos (among them the goal photo that began its 17 cm-off bedroom) and 9
of the 176 right to 5 cm; on apartment 6, 4 of 33 and 4 of 128. A camera's pixel and the
issue's bar, not a scene's length."""

ASIFT_TILTS = (0.5, 2**-0.5, 1.0, 2**0.5, 2.0)
"""The tilts of `AdaptiveConfig.retry_tilts` (the default; `explore --no-retry-tilts`: none):
ASIFT's steps of sqrt 2 up to t = 2 (a surface turned 60 degrees), both ways; SIFT's affine
limit, not a scene's.

Why (analysis, stop of 2026-11-30): at nodes where both localise photos failed, PnP from the
*true* pose at 16 headings found a pose within 10 cm for 37 of apartment 6's 320 photos and
20 of apartment 2's 320 with plain SIFT, 71 and 69 with these tilts (wrong poses 12 -> 19 and
2 -> 7 before the mission's checks). The map's points lay within 2 cm of the true surfaces;
its unmatched walls were seen 45-70 degrees away from the map photos' view. In missions
(apartments 0-14, office 0; one run each, against main): the share of adaptive photos fixed
rose on 14 of 16 worlds (mean +5.9 points), the tilted fixes were as close as the plain ones
(apartment 10: median 2.9 cm over 43), goals given up 112 -> 95, worlds with p95 <= 15 cm
2 -> 4, the mean p95 -3.0 cm, seconds -5 % (two missions at a time; a retry costs about
0.25 s per failed photo). But alone the p95 fell on only 8 of 16 worlds: most of it came
from rooms the first map lacks (apartment 10: later regions p95 80 cm against 13.6 cm in the
first map's), where no map point is in view and no description of the photo helps. With the
map grown after every goal (`AdaptiveMission.grow_tracks`) from fixes the filter vouches for
(`take_photo`, `max_fix_jump_m`), it is on by default (stop of 2026-11-30, seventh)."""

FIX_FAILURES = ("no pose", "height", "jump", "heading", "tilt")
"""Why a photo's fix failed (`AdaptiveMission.localise_photo`): PnP found no pose (too few
inliers against the map); or its pose was rejected for the camera's height, for a jump from
the estimate, for a heading turned from the compass-held estimate, or for a camera tilted
out of level (a photo is counted once, by its last try's reason). Of apartments 2 and 3's 913 and 1,186
adaptive photos, 710 and 886 found no pose while the rejected were 13 and 12 (SIFT at 0.04,
`AdaptiveConfig.localizer`): the map and the features, not the checks, left them unfixed."""

OBSTACLE_DRIVES = ("path", "side step", "recovery")
"""The drives that can meet an obstacle (`AdaptiveMission.obstacles_met`): a leg of a planned
path (`go_to`), a stereo pair's side step (`capture_at`), a recovery's back-off or drive off
the path (`_recover`)."""


@dataclass(frozen=True)
class AdaptiveConfig:
    """Settings of the adaptive exploration."""

    n_candidates: int = 300
    """Random candidate poses scored per round."""
    clearance_m: float = 0.35
    """Candidates keep this distance from the free-space boundary (m)."""
    goals_per_round: int = 6
    """Goals visited between two map rebuilds."""
    frontier_goals_per_round: int = 2
    """Frontier goals added to a round's goals (`explore.frontier`: where the ultrasonic's
    free space meets space no reading reached), largest frontier first. They lead the robot
    through doorways into rooms the map has no points of, where no candidate is drawn."""
    far_goals_per_round: int = 0
    """Of a round's `goals_per_round`, goals that look the farthest across open space
    (`far_goals`, `explore.view_run`): the views that see the upper walls and ceiling,
    which the heuristic's close views miss. Off (0) by default. One a round (`ibrnav
    explore --far-goals 1`; chosen on the true poses of apartments 0 and 3 and office 0,
    where 8 far stereo pairs in place of a mission's last 8 goal pairs added 0.03-0.06
    coverage) raised coverage on 10 of 16 worlds (apartments 0-14, office 0; mean +0.012,
    worst -0.044), rooms visited 29 -> 32 of 41 and cut goals given up 112 -> 77; but the
    coverage median of the held-out apartments 10-14 fell 0.346 -> 0.316 and apartments
    0-9 and office 0 localised to a median of 5 cm or less fell 9 -> 7, which the landing
    rule fixed before the runs did not allow (2026-11-30). Why the gain is small: the far
    goals are not far. Candidates lie in the map's free space around the robot, and in a
    3-4 m room the longest run is 2-3.5 m (apartments 2 and 7: runs predicted to 0.1 m,
    true medians 1.9 and 2.3 m, none of 18 at 4 m), while the poses that see the upper
    surfaces look 3.6-5.6 m ahead, from one region into another."""
    sonar: SonarConfig = field(default_factory=SonarConfig)
    """The ultrasonic's geometry (the robot's sensor)."""
    sweep_frontiers: bool = False
    """At a frontier goal, turn a full circle reading the ultrasonic before the photos
    (`sweep_ultrasonic`; `explore --sweep-frontiers`). Off by default: the robot goes on
    into rooms it missed, but is lost more often there (`sweep_ultrasonic`)."""
    keep_off_surfaces: bool = False
    """Keep the robot off the surfaces the ultrasonic met on its way, not only at its goals:
    the grid's cells where it would touch one are dear (`_near_surfaces`), and a stereo pair's
    side step or a recovery's drive off the path goes to the side clear of them (`_flip_side`;
    `explore --keep-off-surfaces`). Off by default (stop of 2026-12-01, eighth): traced, the
    band alone took apartment 5's bumps from 85 to 25 and its goals given up from 7 to 2; but
    on the 15 worlds of a sweep (apartments 0-9, offices 0-4; one draw) the goals given up
    were 76 against main's 56 and 74 in two draws, more than both of main's on 5 worlds and
    fewer on 2, and the localisation median within 5 cm on 9 worlds against 12 and 12."""
    goal_separation_m: float = 0.8
    """Two goals of a round are at least this far apart, or differ by 60 degrees in heading (m)."""
    photos_per_goal: int = 2
    """Photos taken at a goal: the goal view, then side-stepped copies (stereo baselines)."""
    stereo_baseline_m: float = 0.6
    """Side step between the photos of a goal (m): 0.6 m is 5 degrees of parallax at 6.9 m."""
    min_gain_rad: float = 0.05
    """Stop when the best candidate's score (mean angle, rad) is below this."""
    max_rounds: int | None = None
    """Most rounds of goal selection and map rebuilding; None: no limit, the mission runs
    until it is complete, its photo budget is spent or no goal is reachable (each round
    either adds photos, bounded by the budget, or gives up goals that are never drawn
    again, bounded by the free space; the watchdog bounds each step)."""
    step_limit_s: float | None = 600.0
    """A step of a round (choosing goals, driving to one goal and photographing it,
    rebuilding the map) that takes longer than this (s) is an error (`robot.mission.watchdog`),
    never a silent stall. Generous: a step takes seconds to a minute on a busy 2-core machine."""
    switch_m: float = 0.3
    """Target-node switching: a path node within this distance counts as passed (m)."""
    reach_m: float = 0.15
    """The goal counts as reached within this distance (m)."""
    leg_m: float = 0.6
    """Longest straight drive on dead reckoning before re-aiming (m)."""
    max_obstacles: int = 5
    """Obstacles on the way to a goal after which it is given up (the paper's k = 5)."""
    robot_radius_m: float = 0.15
    """The robot's footprint radius (m, the robot's own size): a bump blocks the grid cells
    within this of the contact point (the robot's centre cannot go there)."""
    backoff_m: float = 0.2
    """How far to back up from an obstacle (m)."""
    off_path_m: float = 0.3
    """How far to drive off the path after an obstacle before re-planning (m)."""
    trail_drives: int = 10
    """Drives the robot remembers (`AdaptiveMission.trail`): where it has just driven stays
    passable to its planner. A count of the robot's own moves: a recovery from a bump is two
    drives, a stereo pair's side step one or two, so ten reach back over a few of them to
    where a plan had brought it."""
    max_legs_per_goal: int = 40
    """Legs after which a goal is given up (a planner or localisation fault never loops forever)."""
    max_path_cost: float = 0.35
    """Grid cells with a (normalised) KDE cost above this are blocked for A*."""
    grid_seen_margin_m: float = 0.15
    """A grid cell no photo saw through by this margin (m, `ViewQuality.seen_free`) is
    blocked: paths keep to the space the photos saw empty."""
    max_fix_jump_m: float = 0.15
    """A PnP fix farther than this (m) and than 3 of the filter's spreads from its estimate is
    rejected. The issue's 95th-percentile localisation error: a fix the filter cannot tell
    from its own estimate is never refused, one that jumps past both is not believed. At
    1.0 m, with the map grown after every goal, apartment 6 took fixes 0.5-1.1 m off where the
    filter was within 5-34 cm (their inliers on map points 0.2-0.3 m off the surfaces); the
    filter followed them, and their points drew the next fixes 1 m off for 150 photos (p95
    118 cm). A robot's accuracy, not a scene's."""
    max_fix_turn_deg: float = 8.0
    """A PnP fix whose heading differs from the filter's by more than this (degrees) is
    rejected (`AdaptiveMission.turn_gate`; without the compass, also by more than 3 of the
    filter's heading spreads). The compass holds the filter's heading
    (sigma 5 degrees per reading in the filter's model; traced against the truth on
    apartments 6 and 7, the estimate's heading was within 5.5 degrees at the 99th
    percentile), so a fix that turns the robot further is a wrong pose, whatever its
    position says: of the 514 fixes within 10 cm of the truth, 99 % differed from the
    estimate by at most 6 degrees and one by more than 8 (9.6); the wrong fixes that began
    apartment 6's drift (0.4-1.4 m off, 15-29 inliers, each inside the position gate) by
    14-21 degrees, and so did those that held it 1.2-1.7 m off afterwards (40-50 inliers).
    A compass's accuracy, not a scene's."""
    max_fix_height_err_m: float = 0.15
    """A PnP fix whose camera height is off by more than this is rejected (m)."""
    max_seed_m_per_px: float | None = None
    """A fix poses its photo, whose points then join the map, only when a pixel of error
    shared by its inliers moves it by at most this (m, `fix_precision.bias_sensitivity`);
    a weaker fix is still the filter's measurement. None (the default): every fix poses its
    photo. `explore --precise-seeds` sets `PRECISE_SEEDS_M_PER_PX`, off by default until the
    capture's coverage holds with it (module docstring of `fix_precision`)."""
    max_fix_tilt_px: float = 6.0
    """A PnP fix whose camera is tilted out of the map's level (`tilt_of_camera`: the robot
    stands level on a flat floor, and so did its map photos) by more than the angle that
    moves the image centre this many pixels, atan(px / focal length), is rejected. An
    image-space limit, 1.5 times the RANSAC inlier threshold: of apartment 1's 42 PnP poses,
    the 34 right to 5 cm tilted at most 1.0 degree (6 px at its focal length of 277 px is
    1.2 degrees), while the 8 off by 0.06-2.8 m, which passed the height and jump checks,
    tilted 1.5-3.9 degrees; held out, on apartment 7, 23 right fixes tilted at most 1.1
    degrees and 4 wrong ones (0.2-5.7 m off) 4.6-20 degrees."""
    grid: NavGridConfig = field(default_factory=lambda: NavGridConfig(z_floor_margin=0.08, z_max=1.2))
    """Navigation grid (KDE of above-ground points)."""
    view_quality: ViewQualityConfig = field(default_factory=ViewQualityConfig)
    """Rendering-quality heuristic."""
    localizer: FeatureLocalizerConfig = field(default_factory=lambda: FeatureLocalizerConfig(
        triangulation=TriangulationConfig(n_features=1500, neighbours=4, max_epipolar_px=3.0, max_reprojection_px=3.0,
                                          contrast_threshold=0.02),
        query_features=1500, min_inliers=12))
    """SIFT + RANSAC PnP localiser against the map (its map's features are cached per photo).
    Its SIFT keeps keypoints as faint as the SfM's: OpenCV's contrast threshold 0.02 is
    COLMAP's default peak threshold, 0.02 / 3 octave layers on both sides (OpenCV divides
    its threshold by the layers), a property of the detector, not of a scene. At OpenCV's
    default 0.04 an apartment photo at 320 x 240 held 78-109 keypoints at the median
    (132-205 at 0.02), PnP found no pose for 710 of apartment 2's 913 adaptive photos and
    886 of apartment 3's 1,186 (the sanity checks rejected 13 and 12), and the photos between
    fixes read the odometry's drift. At 0.02, held out: the fix rate rose on apartments
    10-14 and offices 5-9, the localisation error's median of medians 5.2 -> 2.7 cm
    (apartments) and 3.4 -> 2.3 cm (offices), the offices' median p95 17.7 -> 12.1 cm; where
    the map itself is displaced (apartment 3) more fixes follow it (p95 36 -> 60 cm)."""
    retry_tilts: tuple[float, ...] = ASIFT_TILTS
    """When plain SIFT finds no fix, the photo is described again at these horizontal tilts
    and pooled (`localization.feature_localizer.tilted_features`; () never, as with
    `explore --no-retry-tilts`). Why, and what it gives: `ASIFT_TILTS`."""
    map: MapConfig = field(default_factory=MapConfig)
    """Map building (SfM, triangulation, Poisson)."""
    extra_random_circles: int = 2
    """Circles of random photos added, one at a time, while SfM cannot map the random stage
    or the floor seen from two stops does not check its map's scale (too few pairs, or
    pairs that disagree: `mission._first_map`).
    Each circle is a new stop; two bound the cost at 72 photos of the paper's 261 with
    10 degree steps (apartment seed 5: the stage's three circles stood at two spots)."""
    filter: MissionFilterConfig = field(default_factory=MissionFilterConfig)
    """The particle filter of path following."""
    repose: ReposeConfig | None = field(default_factory=ReposeConfig)
    """Re-posing every photo by SfM when PnP keeps failing (`robot.mission.repose`), so the
    map follows the robot into rooms it has no points of; None: never."""
    bundle: BundleConfig | None = None
    """At each rebuild, bundle-adjust the photos posed since the first map with their tracks,
    the first map's photos held (`AdaptiveMission.adjust`, `robot.mission.bundle`; `explore
    --bundle-adjust`); None: never. Off by default (stop of 2026-12-01, sixth; 15 worlds,
    apartments 0-9 and offices 0-4, against main): the goal photos' position error fell at the
    median on 10 and at the p95 on 12 (office 0: 3.3 / 16.0 -> 1.2 / 4.6 cm), the localisation
    p95's median 16.0 -> 10.6 cm (worst 41.6 -> 39.5), lost photos 864 -> 599; but its rule
    also asked for a median <= 5 cm on 12 worlds (11), 27 rooms (25), 62 goals given up at
    most (67) and seconds up 20 % at most (median +47 %: the adjustment and the tracks made
    again at every rebuild, 10-30 s each on 300 photos, the solver most of it, at 100
    iterations; `BundleConfig.max_iterations` is 10 since, a fifth to a third of the solver's
    time for the same poses offline, not swept), so it stays off."""
    look: LookConfig | None = field(default_factory=LookConfig)
    """Before a localise photo, turn to the heading that sees the most map points SIFT can
    match (`robot.mission.look_heading`; `LookConfig.occlude`: not those its mesh hides, and
    the retry after a failed fix by the same count); None: photograph wherever the path left the robot."""


def _near_segment(xy: np.ndarray, a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
    """(N,) bool: the points xy (N, 2) within `radius` of the segment from a to b (2,)."""
    ab = b - a
    t = np.clip((xy - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    return np.linalg.norm(xy - (a + t[:, None] * ab), axis=1) < radius


def pick_goals(poses: np.ndarray, scores: np.ndarray, k: int, separation_m: float) -> np.ndarray:
    """Indices of up to `k` best-scoring poses (N, 3), each at least `separation_m` from, or
    60 degrees in heading away from, every better one picked."""
    chosen: list[int] = []
    for i in np.argsort(-scores):
        if len(chosen) == k:
            break
        if _apart(poses[i], poses[chosen], separation_m):
            chosen.append(int(i))
    return np.array(chosen, dtype=int)


def _apart(pose: np.ndarray, others: np.ndarray, separation_m: float) -> bool:
    """Whether the pose (3,) is at least `separation_m` from, or 60 degrees in heading away
    from, every pose of `others` (K, 3)."""
    return bool(np.all((np.hypot(*(others[:, :2] - pose[:2]).T) >= separation_m)
                       | (np.abs(wrap_angle(others[:, 2] - pose[2])) >= np.radians(60))))


class AdaptiveMission:
    """The adaptive stage's state: the robot and its dead reckoning (`body`), the photos, the
    map and the localiser. `run_mission` drives it; the methods are its steps."""

    def __init__(self, robot: Robot, body: Body, photos: list[MissionPhoto], robot_map: RobotMap,
                 config: AdaptiveConfig, rng: np.random.Generator, observer: MissionObserver,
                 unfixed: set[int] | None = None, reposed: set[int] | None = None, sfm_work: Path | None = None):
        self.robot, self.body, self.photos, self.map = robot, body, photos, robot_map
        self.config, self.rng, self.obs = config, rng, observer
        w, h = robot.image_size
        self.template = Camera(robot.intrinsics, w, h, np.eye(4))
        self.cam_height = float(np.linalg.inv(robot.cam_from_robot)[2, 3])
        self._features: dict[int, object] = {}
        self.fixes = self.failed = self.given_up = 0
        self.tilted_fixes = 0
        """Of `fixes`, those found only by the tilted retry (`AdaptiveConfig.retry_tilts`). Journalled."""
        self.weak_fixes = 0
        """Of `fixes`, those too weak to pose their photo (`_precise`). Journalled."""
        self.failure_reasons: dict[str, int] = dict.fromkeys(FIX_FAILURES, 0)
        """Why the failed fixes failed (`localise_photo`), a count per reason. Journalled."""
        self.failed_at_repose = 0
        """`failed` when the photos were last re-posed by SfM (`repose`)."""
        self._sfm_work: Path | None = None
        """`repose`'s SfM workspace, removed with the mission: `sfm_work` (the first map's,
        `mission._start_adaptive`, its features and matches reused) or, at the first
        re-posing, a new one."""
        if sfm_work is not None:
            self._keep_sfm_work(Path(sfm_work))
        self.reposed: set[int] = set(reposed or ())
        """Localise photos SfM posed (`repose`): not in the model, but in the map's tracks,
        where the robot was lost they are most of the photos of a room."""
        self.goals_reached: list[np.ndarray] = []
        self.given_up_goals: list[np.ndarray] = []
        """Goals given up: no candidate is drawn near them again."""
        self.bumps: list[np.ndarray] = []
        """Where the bumpers touched something (world xy, m, on the estimate): blocked while
        the robot tries the goal it bumped on the way to, dear in every later grid (`_with_bumps`)."""
        self.obstacles_met: dict[str, int] = dict.fromkeys(OBSTACLE_DRIVES, 0)
        """Drives a bumper or a stall stopped, by the drive (`OBSTACLE_DRIVES`). Journalled."""
        self.unfixed: set[int] = set(unfixed or ())
        """Goal photos PnP could not localise, or fixed only where the filter was lost
        (`take_photo`), posed at the filter's estimate: in the model
        (rendering, coverage) but not in the map's tracks, which PnP localises against (an
        estimate 0.2-0.5 m off would triangulate wrong points, and the next fixes would
        follow them)."""
        self._last_view: np.ndarray | None = None  # odometry when the last photo was taken
        self.trail: list[np.ndarray] = []
        """The estimate's xy (world, m) before and after each of the last `trail_drives`
        drives, (2, 2) each: the robot has just driven there (`_from_here`). Journalled."""
        self.swept: list[np.ndarray] = []
        """The estimate's xy (world, m) before and after each drive of the adaptive stage that
        no bumper stopped, made while the filter was localised at both ends, (2, 2) each:
        space the robot's own body drove through, passable in every later grid (`_swept_open`).
        Journalled."""
        self.stepped_from: np.ndarray | None = None
        """Where (world xy, m, on the estimate) the robot stood on its plan before the stereo
        pair's side step (`capture_at`); None once it follows a plan again (`_way_back`).
        Journalled: a round ends on a side step."""
        self._seen_free = None  # the last scorer's `ViewQuality.seen_free` (its sources' depth maps)
        self._sonar: SonarGrid | None = None  # the ultrasonic's grid of the last goal choice
        self.sonar_readings: list[np.ndarray] = []
        """The ultrasonic's readings taken without a photo (`sweep_ultrasonic`): (x, y, theta
        of the estimate then, range m) each. Journalled."""
        self.n_candidates = self.n_frontier_goals = 0  # of the last goal choice
        self.give_up_reason = ""
        self.matches = PairMatches(self._feats, config.localizer.triangulation.ratio)
        """The SIFT matches of every pair the tracks were made of (matched once: `adjust`
        triangulates them again on the adjusted poses)."""
        self.tracks = self._localiser_tracks()
        self._prior: dict[int, np.ndarray] = {}
        """Each tracked photo's camera centre when it joined the tracks (world, m): where
        `adjust` holds it (a resumed mission starts them at the journal's adjusted poses)."""
        self._adjusted: set[int] = set()  # the photos `adjust` last adjusted with
        self._tracked_to = len(photos)
        """Photos before this index are in the tracks if they ever will be (`grow_tracks`)."""
        self._mesh_tracks = Tracks.empty()
        """Tracks of the goal photos fixed since the last `rebuild`, which meshes them."""
        self._mesh_photos: set[int] = set()  # those photos
        self.fmap = self._feature_map()
        self._map_rays: tuple[object, Occluder] | None = None  # the map's mesh and its `hidden_by`

    # --- localisation -------------------------------------------------------------------
    def _feats(self, i: int):
        """SIFT features of photo i (computed once per mission)."""
        if i not in self._features:
            tri = self.config.localizer.triangulation
            self._features[i] = sift_features(self.photos[i].photo.image, tri.n_features, tri.contrast_threshold)
        return self._features[i]

    def _model_cameras(self) -> dict[int, Camera]:
        return {i: p.camera for i, p in enumerate(self.photos) if p.camera is not None and p.stage != "localise"}

    def _map_cameras(self) -> dict[int, Camera]:
        """The model's cameras posed by SfM or by a vision fix, and the localise photos SfM
        re-posed (what the map's points are made of)."""
        return {**{i: c for i, c in self._model_cameras().items() if i not in self.unfixed},
                **{i: self.photos[i].camera for i in sorted(self.reposed)}}

    def _track_cameras(self) -> dict[int, Camera]:
        """What the localiser's tracks are made of: the map's cameras and the localise photos
        a fix posed."""
        return {**self._map_cameras(),
                **{i: p.camera for i, p in enumerate(self.photos) if p.stage == "localise" and p.camera is not None}}

    def _localiser_tracks(self) -> Tracks:
        """The tracks of every photo posed so far: the map's cameras' stereo pairs, then those
        of the localise photos a fix posed (a resumed mission's, or after `adjust`)."""
        tri = self.config.localizer.triangulation
        mapped, tracked = self._map_cameras(), self._track_cameras()
        tracks = stereo_tracks(mapped, self._feats, tri, matches=self.matches)
        if looked := set(tracked) - set(mapped):
            tracks = tracks + stereo_tracks(tracked, self._feats, tri, only=looked, matches=self.matches)
        return tracks

    def _feature_map(self) -> FeatureMap:
        """SIFT + PnP map of the tracks so far (built once, then grown by `rebuild` and `repose`)."""
        return FeatureMap(self.tracks.points, self.tracks.descriptors, self.tracks.owner, self.config.localizer)

    def _world_from_robot(self, cam_from_world: np.ndarray) -> np.ndarray:
        """(4, 4) pose of the robot of a camera pose (the mount undone), world frame."""
        return np.linalg.inv(cam_from_world) @ self.robot.cam_from_robot

    def pose_of_camera(self, cam_from_world: np.ndarray) -> np.ndarray:
        """SE(2) robot pose of a camera pose (the mount undone)."""
        return robot_pose(np.linalg.inv(cam_from_world), self.robot.cam_from_robot)

    def tilt_of_camera(self, cam_from_world: np.ndarray) -> float:
        """Angle (rad) between the robot's up axis at a camera pose and the map's level: the
        median up axis of the map's photos, each taken standing level (a map whose floor
        fit leaves it tilted by a degree, as apartment 0's was by 1.3, tilts its right
        fixes alike). 0 for a camera where the robot stands level in the map."""
        ups = np.array([self._world_from_robot(c.cam_from_world)[:3, 2]
                        for c in self._map_cameras().values()]).reshape(-1, 3)
        level = np.median(ups, axis=0) if len(ups) else np.array([0.0, 0.0, 1.0])
        level /= np.linalg.norm(level)
        return float(np.arccos(np.clip(self._world_from_robot(cam_from_world)[:3, 2] @ level, -1.0, 1.0)))

    def localise_photo(self, photo: Photo):
        """PnP result (`PnPResult`) of a photo against the map if it passes the sanity
        checks (`_fix_rejected`), else None, and the reason counted in `failure_reasons`
        (`FIX_FAILURES`). Plain SIFT first; when it finds no pose that passes, the photo
        again described at `retry_tilts` (`tilted_features`)."""
        c = self.config
        reason = "no pose"
        if len(self.fmap) >= c.localizer.min_inliers:
            for tilts in ((1.0,), c.retry_tilts) if c.retry_tilts else ((1.0,),):
                res = self.fmap.localize(photo.image, self.template, tilts=tilts)
                reason = self._fix_rejected(res)
                if reason is None:
                    self.fixes += 1
                    self.tilted_fixes += tilts != (1.0,)
                    return res
        self.failed += 1
        self.failure_reasons[reason] += 1
        return None

    def _fix_rejected(self, res) -> str | None:
        """Why a PnP result (`PnPResult` or None) is no fix (`FIX_FAILURES`), or None when it
        passes the sanity checks: camera height; within `max_fix_jump_m` of the estimate, or
        3 spreads; turned from it by at most `turn_gate`; level, `max_fix_tilt_px` (checked
        last: it reads every map photo)."""
        c = self.config
        if res is None:
            return "no pose"
        centre = np.linalg.inv(res.cam_from_world)[:3, 3]
        pose = self.pose_of_camera(res.cam_from_world)
        if abs(centre[2] - self.cam_height) >= c.max_fix_height_err_m:
            return "height"
        if np.hypot(*(pose[:2] - self.body.est.pose[:2])) >= max(c.max_fix_jump_m, 3 * self.spread()):
            return "jump"
        if abs(wrap_angle(pose[2] - self.body.est.pose[2])) >= self.turn_gate():
            return "heading"
        if self.tilt_of_camera(res.cam_from_world) > np.arctan(c.max_fix_tilt_px / self.template.K[0, 0]):
            return "tilt"
        return None

    def localise_here(self) -> None:
        """A photo taken only to localise, unless the robot has not moved or turned since
        its last photo (by odometry: 1 cm, 0.5 degrees, its own motion's resolution, not a
        scene's): the same view gives the same PnP answer, or the same failure (at a path's
        last node or after a failed fix, the office's mission photographed one spot up to 4 times)."""
        if self._last_view is not None:
            d = self.robot.odometry() - self._last_view
            if np.hypot(d[0], d[1]) < 0.01 and abs(wrap_angle(d[2])) < np.radians(0.5):
                return
        failed = self.failed
        self._face_the_map()
        self.take_photo("localise")
        if self.failed > failed and isinstance(self.body, FilteredBody):
            heading = self._retry_heading()
            if heading is not None:
                self._face(heading)
                self.take_photo("localise")

    def _face_the_map(self) -> None:
        """Turn to the heading from which the estimate sees the most map points SIFT can
        match (`look_heading`; config `look`), when it sees clearly more than the current one."""
        if self.config.look is None or not isinstance(self.body, FilteredBody):
            return
        heading = self._heading_by(look_heading, self._hidden_by_map())
        if heading is not None:
            self._face(heading)

    def _heading_by(self, choose, hidden: Occluder | None) -> float | None:
        """`choose` (`look_heading` or `retry_heading`) at the estimate, over the localiser's
        tracks, with the robot's camera, PnP's minimum inliers and `hidden`."""
        return choose(self.body.est.pose, self.tracks.points, self.tracks.seen_from, self.robot.intrinsics,
                      self.robot.image_size, self.robot.cam_from_robot, self.config.localizer.min_inliers,
                      self.config.look, hidden)

    def _hidden_by_map(self) -> Occluder | None:
        """What hides map points from the camera for `look_heading`: the map's mesh, with
        `LookConfig.occlude` (its ray intersector built once per mesh); else None."""
        look = self.config.look
        if look is None or not look.occlude or len(self.map.mesh.faces) == 0:
            return None
        if self._map_rays is None or self._map_rays[0] is not self.map.mesh:
            self._map_rays = (self.map.mesh, hidden_by(RayMeshIntersector(self.map.mesh), look.occlusion_margin_m))
        return self._map_rays[1]

    def _retry_heading(self) -> float | None:
        """After a failed fix: with `LookConfig.occlude`, the heading more than half the field
        of view away that sees the most map points the map's mesh does not hide
        (`retry_heading`), else, or when none sees enough, `_mapped_view_heading`."""
        if (hidden := self._hidden_by_map()) is not None:
            heading = self._heading_by(retry_heading, hidden)
            if heading is not None:
                return heading
        return self._mapped_view_heading()

    def _mapped_view_heading(self) -> float | None:
        """After a failed fix: the heading (rad) of the nearest map photo (posed by SfM or a
        fix) that looked more than half the field of view away from the robot's heading,
        the way to look for features the map holds (a path's node often faces a bare wall
        close by: 44 % of the office's localisation photos found no pose). None: no such photo."""
        est = self.body.est.pose
        half = np.arctan2(self.template.width / 2, self.template.K[0, 0])
        best, best_d = None, np.inf
        for cam in self._map_cameras().values():
            f = cam.world_from_cam[:3, 2]
            yaw = float(np.arctan2(f[1], f[0]))
            d = float(np.hypot(*(cam.center[:2] - est[:2])))
            if abs(wrap_angle(yaw - est[2])) > half and d < best_d:
                best, best_d = yaw, d
        return best

    def spread(self) -> float:
        """The filter's position spread (m; 0 without a filter, `MissionLocalizer.spread_m`)."""
        return self.body.est.spread_m if isinstance(self.body, FilteredBody) else 0.0

    def heading_spread(self) -> float:
        """The filter's heading spread (rad, the standard deviation of its particles' wrapped
        headings; 0 without a filter)."""
        return float(np.sqrt(max(self.body.est.cov[2, 2], 0.0))) if isinstance(self.body, FilteredBody) else 0.0

    def turn_gate(self) -> float:
        """The largest turn (rad) a fix may make from the estimate's heading: `max_fix_turn_deg`
        while the filter reads the compass, which holds its heading whatever its particles'
        spread says (a turn in place draws their headings from the compass's model, sigma 5
        degrees: 3 spreads, about 15 degrees, let through 6 of apartment 6's wrong fixes, turned
        9-14 degrees, 0.4-0.6 m off); without the compass, also 3 of the filter's heading
        spreads, as odometry alone lets the heading drift (no spread without a filter)."""
        turn = np.radians(self.config.max_fix_turn_deg)
        return turn if self.config.filter.compass_sigma_rad > 0 else max(turn, 3 * self.heading_spread())

    def lost(self) -> bool:
        """The filter's spread is above `MissionFilterConfig.relocalise_std_m` (never without a filter)."""
        return self.spread() > self.config.filter.relocalise_std_m

    def take_photo(self, stage: str) -> MissionPhoto:
        """Capture, localise by vision: a good fix is the particle filter's measurement (a
        plain `Body` takes it as its estimate). A photo is posed by its fix, and joins the
        localiser's tracks (`grow_tracks`), only when the filter was localised before it
        (spread within `relocalise_std_m`): a fix that relocalises a lost filter is believed
        but seeds no map point, since a wrong one would draw the next fixes to its points (the
        next fix, checked against the filter it moved, seeds them). With `max_seed_m_per_px`,
        nor does a fix its map points could have moved far (`_precise`). A goal photo without
        such a fix is posed at the filter's estimate (`unfixed`)."""
        photo = self.robot.capture()
        self._last_view = self.robot.odometry().copy()
        localised = not self.lost()
        res = self.localise_photo(photo)
        fixed = res is not None
        precise = fixed and self._precise(res)
        cam = res.camera if precise and localised else None
        if fixed and isinstance(self.body, FilteredBody):
            self.body.est.update_pnp(self.pose_of_camera(res.cam_from_world), res.n_inliers)
        elif fixed:
            self.body.est.pose = self.pose_of_camera(res.cam_from_world)
        if cam is None and stage == "goal":
            cam = robot_camera(self.body.est.pose, self.robot.intrinsics, self.robot.image_size,
                               self.robot.cam_from_robot)
            self.unfixed.add(len(self.photos))
        if cam is not None:
            cam = cam.with_pose(cam.cam_from_world, name=f"photo_{len(self.photos):05d}")
        dr = self.body.est.dead_reckoning.pose.copy() if isinstance(self.body, FilteredBody) else None
        mp = MissionPhoto(photo, self.body.est.pose.copy(), stage, cam, dr, fixed)
        self.photos.append(mp)
        self.obs.photo(mp)
        self.obs.estimate(self.body.est.pose, "pnp" if fixed else "odometry")
        self.log_particles()
        return mp

    def _precise(self, res) -> bool:
        """Whether the fix `res` (`PnPResult`) may pose its photo: a shared pixel of error of
        its inliers moves it by at most `max_seed_m_per_px` (`bias_sensitivity`); counted in
        `weak_fixes` when not."""
        if self.config.max_seed_m_per_px is None:
            return True
        moved = bias_sensitivity(res.camera, res.inlier_xyz, self.robot.cam_from_robot)
        if moved <= self.config.max_seed_m_per_px:
            return True
        self.weak_fixes += 1
        return False

    def log_particles(self) -> None:
        if isinstance(self.body, FilteredBody):
            self.obs.particles(self.body.est.pf.particles, self.body.est.pf.weights)

    # --- goals ----------------------------------------------------------------------------
    def choose_goals(self) -> tuple[np.ndarray, float, object]:
        """(goals (G, 3), best score, navigation grid) of this round: the view-quality goals
        (best first), then the frontier goals (`frontier_goals`). Candidates are drawn in the
        free space of the mesh slice (`explore.candidates`) and kept only where (a) some
        photo saw through them (`ViewQuality.seen_free`: not behind a wall of the map nor
        inside furniture, and the ultrasonic met no surface on the way, `_sonar_blocked`),
        (b) the robot can drive to on this round's grid (the component of
        its cell that A* can search, `explore.nav_grid.reachable_mask`; on the strict grid,
        else the relaxed one, `nav_grid`), and (c) not near a goal given up before
        (`given_up_goals`). When the best candidate gains less than `min_gain_rad`, only the
        frontier goals are returned. `n_candidates` and `n_frontier_goals` say how many
        there were (no goal and no candidate: "no reachable goal"; no goal but candidates
        that gain too little: "complete")."""
        c = self.config
        cams = [p.camera for p in self.photos if p.camera is not None and p.stage != "localise"]
        xy = np.array([cam.center[:2] for cam in cams])
        free = free_space_from_mesh(self.map.mesh, self.cam_height, xy)
        self._sonar = self.sonar()
        vq = ViewQuality(self.map.mesh, cams, config=c.view_quality)
        try:
            self._seen_free = partial(vq.seen_free, blocked=self._sonar_blocked)  # numpy only: usable after release()
            for strict in (True, False):
                grid = self.nav_grid(free, strict)
                cand = self._candidates(free, grid)
                if len(cand) == 0:
                    continue
                clip, eyes = vq.pose_views(cand, self.template, self.robot.cam_from_robot)
                seen = self._seen_free(eyes, c.clearance_m)  # not behind the map's walls, nor in furniture
                log.debug(f"goal choice ({'strict' if strict else 'relaxed'} grid): {len(cand)} reachable "
                          f"candidates, {int(seen.sum())} where a photo saw free space")
                cand = cand[seen]
                if len(cand):
                    break
            scores = vq.score_views(clip[seen], eyes[seen]) if len(cand) else np.zeros(0)
        finally:
            vq.release()
        best = float(scores.max(initial=0.0))
        far = np.zeros((0, 3))
        pick = []
        if best >= c.min_gain_rad:
            pick = pick_goals(cand, scores, c.goals_per_round - c.far_goals_per_round, c.goal_separation_m)
            far = self.far_goals(cand, free, cand[pick].reshape(-1, 3))
        front = self.frontier_goals(grid)
        self.n_candidates, self.n_frontier_goals = len(cand), len(front)
        goals = np.r_[cand[pick].reshape(-1, 3), far, front]
        self.obs.map(self.map, free)
        self.obs.sonar(self._sonar)
        self.obs.candidates(cand, scores, goals)
        return goals, best, grid

    def far_goals(self, cand: np.ndarray, free, taken: np.ndarray) -> np.ndarray:
        """(F, 3) of the candidates `cand` (N, 3), at most `far_goals_per_round`: those that
        look the farthest across open space (`explore.view_run.view_runs`: along the heading,
        to the edge of the map's free space `free` or a surface the ultrasonic met), none
        within `goal_separation_m` and 60 degrees of heading of a goal in `taken` (G, 3), of
        another far goal or of a goal reached (`_visited`: it took that view already). Their
        stereo pair (`capture_at`) sees the upper walls and ceiling across the room."""
        c = self.config
        if c.far_goals_per_round <= 0 or len(cand) == 0:
            return np.zeros((0, 3))
        sonar = self._sonar
        blocked = None if sonar is None else (lambda xy: sonar.surface_distance(xy) < sonar.cell_m / 2)
        runs = view_runs(cand, free, c.robot_radius_m / 4, blocked)  # every half of the ultrasonic's cell
        out: list[np.ndarray] = []
        for i in np.argsort(-runs, kind="stable"):
            others = np.r_[taken, np.reshape(out, (-1, 3))]
            if self._visited(cand[i]) or not _apart(cand[i], others, c.goal_separation_m):
                continue
            out.append(cand[i])
            if len(out) == c.far_goals_per_round:
                break
        return np.array(out).reshape(-1, 3)

    def sonar(self) -> SonarGrid:
        """The ultrasonic's occupancy grid (`explore.frontier.sonar_grid`) of every photo's
        range reading, at the photo's robot pose in the map (its camera's when it has one,
        else the filter's estimate when it was taken), and of the readings taken without a
        photo (`sonar_readings`), on cells half the robot's radius."""
        poses = [self.pose_of_camera(p.camera.cam_from_world) if p.camera is not None else p.estimate
                 for p in self.photos]
        ranges = [p.photo.range_m for p in self.photos]
        readings = np.reshape(self.sonar_readings, (-1, 4))
        return sonar_grid(np.r_[np.reshape(poses, (-1, 3)), readings[:, :3]], np.r_[ranges, readings[:, 3]],
                          self.config.robot_radius_m / 2, self.config.sonar)

    def frontier_goals(self, grid) -> np.ndarray:
        """(F, 3) goals at the largest frontiers of the ultrasonic's grid (`explore.frontier`;
        narrower than the robot: none), at most `frontier_goals_per_round`: per frontier,
        its cell nearest its middle that the robot can reach on `grid`, that lies farther
        than `goal_separation_m` from every goal given up and where the robot touches no
        surface the ultrasonic met (`clear_of_surfaces`; apartments 0-2: frontier goals
        0.16 m beyond a wall and 0.11-0.17 m from one), facing the unknown space within
        half the ultrasonic's range (`explore.frontier.toward_unknown`). None within
        `goal_separation_m` of a goal reached facing within 60 degrees of the same way (it
        looked there already). A goal given up rules out its own cells, not the frontier:
        on apartment 7 the kitchen door and the corridor's unexplored north end were one
        frontier, its middle cell was at the door, the goal there was given up, and the
        corridor was never tried (the bedroom beyond it never visited).

        None at all while the filter's spread is above `MissionFilterConfig.relocalise_std_m`:
        the robot explores the unknown only while it knows where it is. A frontier leads
        into a room the map has no points of, where PnP finds no fix; sent there unlocalised,
        the robot got lost for good (apartments 0-9: localisation median 0.19 -> 0.47 m,
        worst seed 1.5 -> 4.3 m, goals given up 30 -> 55 %; with this rule 0.23 m, 1.8 m,
        31 %, and the coverage gain kept in part: median 0.18 -> 0.22, not 0.29)."""
        c = self.config
        if c.frontier_goals_per_round <= 0 or self._sonar is None or self.lost():
            return np.zeros((0, 3))
        mask = reachable_mask(self._from_here(grid), self.body.est.pose[:2], c.max_path_cost)
        out: list[np.ndarray] = []
        for cells in frontiers(self._sonar, 2 * c.robot_radius_m):
            ok = reachable_at(grid, mask, cells) & ~self.near_given_up(cells) & self.clear_of_surfaces(cells)
            if not ok.any():
                continue
            xy = cells[ok][np.argmin(np.linalg.norm(cells[ok] - cells.mean(0), axis=1))]
            heading = toward_unknown(self._sonar, xy, c.sonar.max_range_m / 2)
            goal = np.r_[xy, heading if heading is not None else self.body.est.pose[2]]
            if not self._visited(goal):
                out.append(goal)
            if len(out) == c.frontier_goals_per_round:
                break
        return np.array(out).reshape(-1, 3)

    def sweep_ultrasonic(self) -> int:
        """At a frontier goal reached: turn a full circle in steps of the ultrasonic's cone
        (`SonarConfig.half_cone_rad` twice, so the readings tile the circle) reading it at
        each, with no photo; the readings join the grid (`sonar_readings`). Returns how many
        of the grid's unknown cells they made free (`explore.frontier.revealed`, each
        reading against the grid before the sweep, so a cell two readings reached counts
        twice); 0 with `sweep_frontiers` off.

        Why: the ultrasonic reads the nearest surface in its 20-degree cone, and a frontier
        goal's heading (`toward_unknown`) points at the mean of the unknown cells near it,
        which takes in the unknown behind walls no reading crosses. At the 144 frontier
        goals of main's missions on apartments 2, 4 and 7, the true reading at that heading
        made 36.7 unknown cells free on the mean (38 % of them under 5), the best of 36
        headings 113.2 (2 % under 5). On apartment 7 the corridor's frontier, looked at
        facing 100 degrees from 0.37 m off its west wall, read that wall at 0.88 m; the
        frontier stayed where it was, its goal counted as looked at (`_visited`), and the
        robot never left the first room.

        What it gives (stop of 2026-12-01, fourth; missions against main, 261 photos): on
        apartments 0-5, 7 and 8 a room more on apartments 2 and 4 (coverage -0.002 on the
        mean), but the p95 rose on 7 of the 8 (median 19.8 -> 33.1 cm), the photos taken more
        than 15 cm off 600 -> 884, goals given up 34 -> 50; apartment 7's robot went up its
        corridor at last, was lost there (spread 0.5-0.8 m) and entered no other room:
        the frontier goals now lead on into regions the map lacks, where PnP finds no fix,
        and the robot spends more of the budget there lost. So it is off by default. The
        photos face the goal's heading; facing them the way the best reading went (photos
        of the unknown) raised coverage on 4 of apartments 0-4 (+0.05 on the mean) but
        doubled the photos taken lost (435 -> 907)."""
        c = self.config
        if not c.sweep_frontiers:
            return 0
        grid = self.sonar()
        step = 2 * c.sonar.half_cone_rad
        taught = 0
        for k in range(int(np.ceil(2 * np.pi / step))):
            if k:
                self.body.move(turn=float(step))
            pose = self.body.est.pose.copy()
            r = float(self.robot.ultrasonic())
            self.sonar_readings.append(np.r_[pose, r])
            taught += revealed(grid, pose, r, c.sonar)
        self.log_particles()
        log.debug(f"frontier sweep at ({pose[0]:.2f}, {pose[1]:.2f}): {taught} unknown cells read")
        return taught

    def _visited(self, goal: np.ndarray) -> bool:
        """Whether `goal` (3,) lies within `goal_separation_m` of a goal given up, or of one
        reached with a heading within 60 degrees of its own."""
        return bool(self.near_given_up(goal[None, :2])[0]
                    or not _apart(goal, np.reshape(self.goals_reached, (-1, 3)), self.config.goal_separation_m))

    def _candidates(self, free, grid) -> np.ndarray:
        """(N, 3) candidate poses in `free` (eroded by `clearance_m`) that the robot can reach
        on `grid`, that are not within `goal_separation_m` of a given-up goal, and where it
        would touch no surface the ultrasonic met (`clear_of_surfaces`: the mesh's free
        space lacks what SfM found no points on)."""
        c = self.config
        try:
            cand = sample_candidates(free, c.n_candidates, self.rng, c.clearance_m)
        except InputError:  # the free space has no room left after the clearance
            log.debug("goal choice: the free space has no room left after the clearance")
            return np.zeros((0, 3))
        mask = reachable_mask(self._from_here(grid), self.body.est.pose[:2], c.max_path_cost)
        keep = reachable_at(grid, mask, cand[:, :2])
        log.debug(f"goal choice: {len(cand)} candidates in the free space ({free.area:.1f} m2), "
                  f"{int(keep.sum())} reachable ({int(mask.sum())} grid cells)")
        return cand[keep & ~self.near_given_up(cand[:, :2]) & self.clear_of_surfaces(cand[:, :2])]

    def clear_of_surfaces(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: the robot could stand at the points xy (N, 2) without touching a surface
        the ultrasonic met: its centre lies farther than `robot_radius_m` from every surface,
        plus half the diagonal of the ultrasonic's cell (`sonar`: a surface lies somewhere
        in its occupied cell, not at the centre the distance is taken to). All True before
        the first reading. Both are the robot's own sizes, not a scene's. Of apartments
        0-2's 20 goals given up, 12 lay within 0.15 m of a true surface or beyond one,
        where no robot centre fits (given up after five bumps); the ultrasonic's surfaces
        were 0.11-0.18 m from apartment 2's three such goals."""
        if self._sonar is None:
            return np.ones(len(xy), bool)
        c = self.config.robot_radius_m
        return self._sonar.surface_distance(xy) > c + np.sqrt(2) / 2 * self._sonar.cell_m

    def _sonar_blocked(self, centres: np.ndarray, points: np.ndarray) -> np.ndarray:
        """(K,) bool: the ultrasonic met a surface between each camera centre (K, 3) and
        world point (K, 3) (`SonarGrid.blocks`): the camera's ray there crossed a surface the
        map's mesh lacks (apartment 3: the plain side of a bed 0.2 m from the photo, no SfM
        point on it; 5 of the 14 goals of rounds 1-2 were drawn inside the bed and given up)."""
        if self._sonar is None:
            return np.zeros(len(points), bool)
        return self._sonar.blocks(centres[:, :2], points[:, :2])

    def near_given_up(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: the points xy (N, 2) lie within `goal_separation_m` of a goal given up."""
        if not self.given_up_goals:
            return np.zeros(len(xy), bool)
        bad = np.array(self.given_up_goals)[:, :2]
        return np.linalg.norm(xy[:, None] - bad[None], axis=2).min(axis=1) < self.config.goal_separation_m

    def nav_grid(self, free, strict: bool = True):
        """The KDE grid over the photos' positions, the free space and the ultrasonic's free
        cells; cells no photo saw through (a table with few points, space behind a wall or a
        plain wall SfM found no point on) and the ultrasonic did not find free are blocked
        when `strict` (the robot drives only where its sensors saw empty space, and where it
        stands, `_from_here`), else they cost `max_path_cost`: passable but dear
        (`choose_goals` relaxes to this when the strict grid reaches no candidate, e.g.
        where the proxy has holes). A cell the ultrasonic found free costs at most
        `max_path_cost`: the readings outrank stray map points (apartment 5: SfM points of a
        map 10 % off in scale hung in the air around the robot, and every path was blocked
        from where it stood). The filter's box prior is grown to cover it."""
        cams = np.array([p.estimate[:2] for p in self.photos])
        lo = np.minimum(cams.min(0), np.asarray(free.bounds[:2])) - 0.5
        hi = np.maximum(cams.max(0), np.asarray(free.bounds[2:])) + 0.5
        heard = self._sonar.free_bounds() if self._sonar is not None else None
        if heard is not None:  # the ultrasonic's free space, beyond the map's
            lo, hi = np.minimum(lo, heard[0] - 0.5), np.maximum(hi, heard[1] + 0.5)
        grid = nav_grid_from_points(self.map.points, (*lo, *hi), self.config.grid)
        if isinstance(self.body, FilteredBody):
            self.body.est.grow_prior(np.array([lo, hi]))
        seen = self._seen_free
        if seen is not None:
            H, W = grid.shape
            xy = grid.centres()
            free_cells = seen(np.c_[xy, np.full(len(xy), self.cam_height)], self.config.grid_seen_margin_m)
            heard = (self._sonar.is_free(xy) if self._sonar is not None else np.zeros(len(xy), bool)).reshape(H, W)
            unseen = np.inf if strict else np.maximum(grid.cost, self.config.max_path_cost)
            cost = np.where(free_cells.reshape(H, W) | heard, grid.cost, unseen)
            # the ultrasonic found it empty: passable, if dear where the map's points say otherwise
            grid = replace(grid, cost=np.where(heard, np.minimum(cost, self.config.max_path_cost), cost))
        grid = self._with_bumps(self._swept_open(grid), self.bumps, dear=True)
        if self.config.keep_off_surfaces:
            grid = self._near_surfaces(grid)
        self.obs.grid(grid)
        return grid

    def _near_surfaces(self, grid):
        """`grid` with the cells where the robot would touch a surface the ultrasonic met
        (`clear_of_surfaces`) made to cost at least `max_path_cost`: dear, so A* keeps the
        robot's disc off the surfaces SfM found no point on (a bed's plain side, a plain wall)
        where another way is, and passable, since the surfaces stand where the estimate was
        and the sensor's arc marks more than it hit (a doorway read at a slant). Why: on
        apartment 5's mission (traced against the truth), 45 of the 50 bumps on a planned
        drive came from plans that drove into a surface (0.33 m deep at the median: the
        bed's plain side, the kitchen's wall), 41 of them with no map point within 0.15 m of
        the contact; the candidates kept off such surfaces, the paths to them did not. With
        this band alone: 11 such bumps of 25 in all, goals given up 7 -> 2 (one run each)."""
        if self._sonar is None:
            return grid
        H, W = grid.shape
        xy = grid.centres()
        near = ~self.clear_of_surfaces(xy).reshape(H, W)
        return replace(grid, cost=np.where(near, np.maximum(grid.cost, self.config.max_path_cost), grid.cost))

    def _swept_open(self, grid):
        """`grid` with the cells within half the robot's radius of the drives it made while
        localised (`swept`) passable (cost at most `max_path_cost`): its own body drove
        through them, the surest free space it has, whatever the map's points or the photos'
        views say. Half the radius (the robot's size, not a scene's), and at least one cell:
        a band a cell or two wide along its centre's path, not the cells beside a door's jambs,
        and 4-connected on any grid (the crossed cells of a diagonal drive touch only at their
        corners, which A* does not cut; the grid's cells grow with the explored area, 0.06-0.08
        m in an apartment's first rounds, past half the radius beyond 7.5 m explored).
        Why: a rebuilt grid can close a doorway or a corridor the robot has driven through
        (apartment 2, traced: a new round's grid split the corridor into three parts at the
        bedroom's door; the round's frontier goals, reachable from where the robot stood at
        the round's start, were given up for "no path" once it had driven back to the
        kitchen, and the bedroom and the corridor past its door were never entered; with this,
        it entered both, and was lost in the bedroom, which the map never reached)."""
        if not self.swept:
            return grid
        near = near_segments(grid, np.array(self.swept), max(self.config.robot_radius_m / 2, grid.cell_m))
        return replace(grid, cost=np.where(near, np.minimum(grid.cost, self.config.max_path_cost), grid.cost))

    def _with_bumps(self, grid, contacts: list[np.ndarray], dear: bool = False):
        """`grid` with the cells within `robot_radius_m` of each contact point (2,) blocked,
        or, when `dear`, made to cost at least `max_path_cost` (passable where no other way
        is). A contact is marked where the estimate was, as uncertain as it: blocked for
        ever, wrong marks sealed doorways and corridors (apartment 0: 145 bumps in one
        mission; 14 of its 23 goals given up for "no path" had one on the final map without
        them), so only the goal being tried treats its own bumps as walls."""
        if not contacts:
            return grid
        H, W = grid.shape
        xy = grid.centres()
        d = np.linalg.norm(xy[:, None] - np.asarray(contacts)[None], axis=2).min(axis=1)
        near = d.reshape(H, W) < self.config.robot_radius_m
        cost = np.maximum(grid.cost, self.config.max_path_cost) if dear else np.inf
        return replace(grid, cost=np.where(near, cost, grid.cost))

    def _from_here(self, grid):
        """`grid` with the cells within `robot_radius_m` plus twice the filter's spread of
        the estimate that bumps or unseen space blocked (inf) made passable (at
        `max_path_cost`): the robot stands somewhere there, so A* and the reachable set
        start from the same free cells even when the estimate is a little off. Cells the
        map's points make dear stay as they are (a wall near the robot is not opened).
        After a stereo pair's side step, the robot's way back to where its plan brought it
        is passable too (`_way_back`), and so are its last drives (`_on_trail`)."""
        H, W = grid.shape
        xy = grid.centres()
        r = self.config.robot_radius_m + 2 * self.spread()
        here = (np.linalg.norm(xy - self.body.est.pose[:2], axis=1) < r).reshape(H, W)
        cost = np.where(here & np.isinf(grid.cost), self.config.max_path_cost, grid.cost)
        back = (self._way_back(xy) | self._on_trail(xy)).reshape(H, W)
        return replace(grid, cost=np.where(back, np.minimum(cost, self.config.max_path_cost), cost))

    def _on_trail(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: the points xy (N, 2) within `robot_radius_m` of one of the robot's last
        drives (`trail`, on the estimate): it has just driven there, whatever a grid rebuilt
        since says. Office 1, round 2: after two recoveries from bumps the robot stood in a
        pocket of 20 cells the new round's grid walled in with blocked cells, one or two cells
        wide, between it and the free space it had come from; the round's next five goals
        were given up for "no path" where it stood."""
        near = np.zeros(len(xy), bool)
        for a, b in self.trail:
            near |= _near_segment(xy, a, b, self.config.robot_radius_m)
        return near

    def _way_back(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: the points xy (N, 2) within `robot_radius_m` of the straight drive from
        where the robot stood on its plan to the estimate (the stereo pair's side step of
        `stereo_baseline_m`, `capture_at`): the robot has just driven there, whatever the
        map's points say. Without it, a side step that ended by a wall or furniture left the
        robot in cells the grid blocks or prices above `max_path_cost`, and every later goal
        of the round was given up for "no path" on the spot (office 1: 4 of its 10 goals given
        up for "no path" at one stop, apartment 7: 5 of 9; with the cells within 0.3-0.5 m of
        the robot opened, A* found each of them a path). All False when the robot follows a
        plan."""
        if self.stepped_from is None:
            return np.zeros(len(xy), bool)
        return _near_segment(xy, self.stepped_from, self.body.est.pose[:2], self.config.robot_radius_m)

    def _bumped(self, motion, grid):
        """Remember where the bumper touched (the robot's edge ahead of, or behind, the
        estimate) and return the grid with it blocked, so the re-plan goes around it."""
        est = self.body.est.pose
        ahead = -1.0 if motion.bumper_rear else 1.0
        contact = est[:2] + ahead * self.config.robot_radius_m * np.array([np.cos(est[2]), np.sin(est[2])])
        self.bumps.append(contact)
        return self._with_bumps(grid, [contact])

    # --- path following -----------------------------------------------------------------------
    def _aim_and_drive(self, target: np.ndarray):
        est = self.body.est.pose
        d = target - est[:2]
        turn = wrap_angle(np.arctan2(d[1], d[0]) - est[2])
        if abs(turn) > 1e-3:
            self.body.move(turn=float(turn))
        return self._drive(float(min(self.config.leg_m, np.hypot(*d))))

    def _drive(self, distance_m: float):
        """Drive `distance_m` (m; negative: backwards), remembering the drive in `trail` and,
        when no bumper stopped it and the filter was localised before and after, in `swept`."""
        before, localised = self.body.est.pose[:2].copy(), not self.lost()
        motion = self.body.move(drive=distance_m)
        drive = np.array([before, self.body.est.pose[:2]])
        self.trail = [*self.trail, drive][-self.config.trail_drives:]
        if localised and not motion.blocked and not self.lost():
            self.swept.append(drive)
        return motion

    def _recover(self, motion) -> None:
        """Back off an obstacle, turn away and drive a little off the path, to a random side
        (with `keep_off_surfaces`, the other one when only that drive keeps clear of the
        ultrasonic's surfaces, `_flip_side`)."""
        c = self.config
        back = self._drive(c.backoff_m if motion.bumper_rear else -c.backoff_m)
        turn = self.rng.uniform(np.pi / 4, np.pi / 2) * self.rng.choice([-1.0, 1.0])
        est = self.body.est.pose[2]
        if self._flip_side(est + turn, est - turn, c.off_path_m):
            turn = -turn
        self.body.move(turn=float(turn))
        off = self._drive(c.off_path_m)
        self.obstacles_met["recovery"] += back.blocked + off.blocked

    def _flip_side(self, heading: float, mirror: float, distance_m: float) -> bool:
        """With `keep_off_surfaces`: a sideways drive of `distance_m` (m) from the estimate
        should take `mirror` (rad, world), the other side, instead of `heading`, because only
        that drive keeps the robot off every surface the ultrasonic met (`_drive_clear`). On
        office 0's mission (traced against the truth), 12 of the 15 bumps of a stereo pair's
        side step, and 3 of 3 of a recovery's drive off the path, went toward a surface the
        ultrasonic had met within 0.25 m of the true contact."""
        if not self.config.keep_off_surfaces or self._sonar is None:
            return False
        return not self._drive_clear(heading, distance_m) and self._drive_clear(mirror, distance_m)

    def _drive_clear(self, heading: float, distance_m: float) -> bool:
        """A straight drive of `distance_m` (m) from the estimate along `heading` (rad, world)
        keeps the robot's disc off the ultrasonic's surfaces (`clear_of_surfaces`, sampled
        every half of its cell; the first half cell left out: the robot stands there)."""
        step = self._sonar.cell_m / 2
        n = max(1, int(np.ceil(abs(distance_m) / step)))
        s = distance_m * np.arange(1, n + 1) / n
        xy = self.body.est.pose[:2] + np.outer(s, [np.cos(heading), np.sin(heading)])
        return bool(self.clear_of_surfaces(xy[np.abs(s) >= step]).all())

    def go_to(self, goal: np.ndarray, grid) -> bool:
        """Drive to goal (3,) on the plan; True when reached. Why a goal was given up is
        left in `self.give_up_reason` ("no path"; "no path past its bumps", when the bumps met
        on the way to it cut every path, the goal's own cells often among them; "obstacles";
        "legs")."""
        c = self.config
        obstacles, legs = 0, 0
        self.give_up_reason = ""
        # the space driven through and the obstacles found since the grid was built
        grid = self._with_bumps(self._swept_open(grid), self.bumps, dear=True)
        while obstacles <= c.max_obstacles and legs < c.max_legs_per_goal:
            path = plan_path(self._from_here(grid), self.body.est.pose[:2], goal[:2], max_cost=c.max_path_cost)
            if path is None:
                self.give_up_reason = "no path past its bumps" if obstacles else "no path"
                return False
            self.obs.path(path)
            t, blocked = 1, False
            while t < len(path) and legs < c.max_legs_per_goal:
                last = t == len(path) - 1
                if np.hypot(*(path[t] - self.body.est.pose[:2])) < (c.reach_m if last else c.switch_m):
                    self.stepped_from = None  # back on a plan
                    if last:
                        self.localise_here()  # check the arrival by vision
                        if np.hypot(*(path[t] - self.body.est.pose[:2])) < c.reach_m + 0.05:
                            return True
                        legs += 1
                        continue
                    t += 1
                    self.localise_here()  # vision fix at every path node
                    continue
                motion = self._aim_and_drive(path[t])
                legs += 1
                if motion.blocked:
                    obstacles += 1
                    self.obstacles_met["path"] += 1
                    grid = self._bumped(motion, grid)
                    self._recover(motion)
                    blocked = True
                    break
                self.log_particles()
                if isinstance(self.body, FilteredBody) and self.body.est.needs_fix():
                    self.localise_here()  # the filter's spread grew: look before going on
            if not blocked:
                self.give_up_reason = "" if legs < c.max_legs_per_goal else "legs"
                return legs < c.max_legs_per_goal
            self.localise_here()
        self.give_up_reason = "obstacles" if obstacles > c.max_obstacles else "legs"
        return False

    def _face(self, heading: float) -> None:
        turn = wrap_angle(heading - self.body.est.pose[2])
        if abs(turn) > 1e-3:
            self.body.move(turn=float(turn))

    def capture_at(self, goal: np.ndarray, budget: int) -> list[MissionPhoto]:
        """A stereo pair at the goal (at most `budget` photos): one photo facing the goal
        heading, then one after a side step of `stereo_baseline_m` to its left (with
        `keep_off_surfaces`, to its right when only that keeps clear of the ultrasonic's
        surfaces, `_flip_side`; backing off when it bumps) and a look to localise
        (`localise_here`), so what the goal sees is seen from two directions."""
        c = self.config
        self._face(goal[2])
        out = [self.take_photo("goal")]
        self.stepped_from = self.body.est.pose[:2].copy()
        for k in range(1, min(c.photos_per_goal, budget)):
            side = goal[2] + (np.pi / 2 if k % 2 else -np.pi / 2)
            if self._flip_side(side, 2 * goal[2] - side, c.stereo_baseline_m * k):
                side = 2 * goal[2] - side
            self._face(side)
            motion = self._drive(c.stereo_baseline_m * k)
            if motion.blocked:
                self.obstacles_met["side step"] += 1
                self._drive(-c.backoff_m)
            self.localise_here()  # a side step on odometry alone is 8 cm off (14 % per drive)
            self._face(goal[2])
            out.append(self.take_photo("goal"))
        return out

    def grow_tracks(self) -> None:
        """Add to the localiser's tracks the photos a fix posed since the last call: the goal
        photos (their tracks kept for the model's mesh, `rebuild`) and the localise photos.
        Called after every goal, so PnP's map follows the robot through a round into a room
        the map lacked, instead of waiting for the round's end (six goals later). On 16 worlds,
        with the filter's vouching (`take_photo`) and the tilted retry, the p95 in regions
        first entered after the random stage fell on 11 of 15 (median 31.8 -> 22.1 cm)."""
        cfg = self.config.localizer.triangulation
        since = range(self._tracked_to, len(self.photos))
        self._tracked_to = len(self.photos)
        fixed = {i for i in since if self.photos[i].stage != "localise" and self.photos[i].camera is not None
                 and i not in self.unfixed}
        looked = {i for i in since if self.photos[i].stage == "localise" and self.photos[i].camera is not None}
        if fixed:
            tracks = stereo_tracks(self._map_cameras(), self._feats, cfg, only=fixed, matches=self.matches)
            self._mesh_tracks = self._mesh_tracks + tracks
            self._mesh_photos |= fixed
            self.tracks = self.tracks + tracks
        if looked:
            self.tracks = self.tracks + stereo_tracks(self._track_cameras(), self._feats, cfg, only=looked,
                                                      matches=self.matches)
        for i in fixed | looked:
            self._prior.setdefault(i, self.photos[i].camera.center)
        if fixed or looked:
            self.fmap = self._feature_map()

    def rebuild(self, new: list[MissionPhoto]) -> None:
        """Add the new model photos `new` to the map (the mesh rebuilt with the tracks of
        those a fix posed), after `grow_tracks` has added the photos fixed since its last call
        to the localiser's tracks: PnP's map grows wherever the robot looked and knew where it
        was, not only at its goals (apartment 7's first-round map, grown so, gave 8 level
        fixes in the next round's 96 photos instead of 2). With `bundle`, the photos are
        adjusted first (`adjust`) and the new photos' tracks meshed on the adjusted poses.
        Then re-pose by SfM when PnP keeps failing, even in a round that reached no goal (the
        robot is most lost there)."""
        started = time.perf_counter()
        self.grow_tracks()
        if self.adjust():
            self._mesh_tracks = stereo_tracks(self._map_cameras(), self._feats, self.config.localizer.triangulation,
                                              only=self._mesh_photos, matches=self.matches)
        cams = self._model_cameras()
        new_ids = {i for i in cams if any(self.photos[i] is q for q in new)}
        if new_ids:
            self.map = extend_map(self.map, {i: cams[i] for i in new_ids}, self._mesh_tracks, self.config.map)
        self._mesh_tracks, self._mesh_photos = Tracks.empty(), set()
        r = self.config.repose
        if r is not None and self.failed - self.failed_at_repose >= r.after_failures and self.lost():
            self.repose(started)

    def adjust(self) -> bool:
        """Bundle-adjust the photos posed since the first map with their tracks, the first
        map's (random-stage) photos held (`robot.mission.bundle.adjust_grown`, config
        `bundle`), when photos joined the tracks since the last adjustment; the adjusted
        cameras replace the photos' (and the map's: the journal keeps them), and the
        localiser's tracks are triangulated again on them. Returns whether any photo moved."""
        cams = self._track_cameras()
        if self.config.bundle is None or set(cams) == self._adjusted:
            return False
        self._adjusted = set(cams)
        held = {i for i in cams if self.photos[i].stage == "random"}
        prior = {i: self._prior.get(i, cam.center) for i, cam in cams.items()}
        res = adjust_grown(cams, held, prior, self._feats, self.matches, self.config.localizer.triangulation,
                           self.config.bundle)
        if isinstance(res, str):
            log.info(f"bundle adjustment: the poses are unchanged: {res}")
            return False
        for i, cam in res.cameras.items():
            self.photos[i].camera = cam
        self.map = replace(self.map, cameras={i: res.cameras.get(i, c) for i, c in self.map.cameras.items()})
        self.tracks = self._localiser_tracks()
        self.fmap = self._feature_map()
        moved = np.array(list(res.moved_m.values()))
        log.info(f"bundle adjustment: {len(res.cameras)} photos adjusted ({res.held} held) with {res.points} points, "
                 f"reprojection {res.error_px[0]:.2f} -> {res.error_px[1]:.2f} px, centres moved "
                 f"{100 * np.median(moved):.1f} cm at the median, {100 * moved.max():.1f} cm at most")
        return True

    def _odometry_held(self, cams: dict[int, Camera], known: dict[int, Camera]) -> set[int]:
        """The photos of the re-posed `cams` {photo: Camera, map frame} that the odometry ties
        to map photos (`known`) SfM re-posed where the map has them (`repose.odometry_held`)."""
        tol = self.config.repose.max_anchor_error_m
        agree = {i: bool(np.linalg.norm(cam.center - known[i].center) <= tol) for i, cam in cams.items() if i in known}
        poses = {i: self.pose_of_camera(cam.cam_from_world) for i, cam in cams.items()}
        odometry = np.array([p.photo.odometry for p in self.photos])
        dead_reckoning = np.array([np.full(3, np.nan) if p.dead_reckoning is None else p.dead_reckoning
                                   for p in self.photos])  # the adaptive stage's; none before a resume
        return odometry_held(poses, odometry, agree, self.config.repose, dead_reckoning)

    def repose(self, started: float | None = None) -> int:
        """Re-pose every photo by SfM, placed on the map's own photos (`robot.mission.repose`).
        Photos the map lacks join it at their SfM pose: model photos unposed or posed only at
        the filter's estimate, and localise photos no fix posed (tracks only, `reposed`),
        each only where the odometry ties it to map photos SfM agrees with (`_odometry_held`).
        Their tracks extend the map, so PnP works there from now on, unless more than
        `ReposeConfig.max_seen_through` of those tracks lie where the map's photos saw empty
        space (`seen_through`): then none joins. When the robot's last photo, taken where it
        still stands, is one of them, its pose is the filter's measurement, as a fix would
        be. SfM runs in a child process stopped when the step, begun at `started`
        (`time.perf_counter()`; None: now), has run `ReposeConfig.time_share` of
        `step_limit_s`; the map is then unchanged. Returns how many photos joined the map."""
        c = self.config
        self.failed_at_repose = self.failed
        if self._sfm_work is None:  # features and matches kept between calls
            self._keep_sfm_work(Path(tempfile.mkdtemp(prefix="ibrnav_repose_")))
        known = self._map_cameras()  # the anchors; nothing changes them until the photos join
        max_s = limit = None
        if c.step_limit_s:
            max_s = c.repose.mapping_share * c.step_limit_s
            limit = c.repose.time_share * c.step_limit_s - (0.0 if started is None else time.perf_counter() - started)
            if limit <= 0:
                log.info("re-posing by SfM: skipped, the step has used its share of the time limit")
                return 0
        found = repose_photos([p.photo.image for p in self.photos], self.robot.intrinsics,
                              np.array([p.photo.compass_rad for p in self.photos]),
                              np.array([p.stage != "localise" for p in self.photos]), known, c.map,
                              self._sfm_work, c.repose, max_s, limit, self.robot.cam_from_robot)
        if isinstance(found, str):
            log.info(f"re-posing by SfM: the map is unchanged: {found}")
            return 0
        cams, support, err = found
        upright = at_mount_height(cams, self.cam_height, c.max_fix_height_err_m)
        held = self._odometry_held(upright, known)
        loose = [i for i in upright if i not in held and i not in known]
        if loose:
            log.info(f"re-posing by SfM: {len(loose)} of the {sum(i not in known for i in upright)} photos new to the "
                     f"map left out (the odometry ties them to no map photo that agrees)")
        upright = {i: cam for i, cam in upright.items() if i in held}
        joined = {i: cam.with_pose(cam.cam_from_world, name=f"photo_{i:05d}") for i, cam in upright.items()
                  if i not in known and (self.photos[i].stage != "localise" or self.photos[i].camera is None)}
        tracks = (stereo_tracks({**self._map_cameras(), **joined}, self._feats, c.localizer.triangulation,
                                only=set(joined), matches=self.matches) if joined else Tracks.empty())
        if (through := self.seen_through(tracks.points)) > c.repose.max_seen_through:
            log.info(f"re-posing by SfM: the map is unchanged: {100 * through:.0f} % of the {len(tracks.points)} points "
                     f"the {len(joined)} photos new to it would add lie where its photos saw empty space")
            return 0
        for i, cam in joined.items():
            self.photos[i].camera = cam
            self._prior[i] = cam.center
        self.unfixed -= set(joined)
        self.reposed |= {i for i in joined if self.photos[i].stage == "localise"}
        new = {i: cam for i, cam in joined.items() if self.photos[i].stage != "localise"}
        if joined:
            self.map = extend_map(self.map, new, tracks, c.map)
            self.tracks = self.tracks + tracks
            self.fmap = self._feature_map()
        last = len(self.photos) - 1
        still = self._last_view is not None and np.allclose(self.robot.odometry(), self._last_view)
        if last in joined and still and isinstance(self.body, FilteredBody):
            self.body.est.update_pnp(self.pose_of_camera(joined[last].cam_from_world), support[last])
            log.info("re-posing by SfM: the robot's last photo posed, the filter's measurement")
        log.info(f"re-posing by SfM: {len(cams)} of {len(self.photos)} photos posed (anchors agree to "
                 f"{100 * err:.1f} cm), {len(joined)} joined the map ({len(new)} of the model; "
                 f"{100 * through:.0f} % of their points where its photos saw empty space)")
        return len(joined)

    def _keep_sfm_work(self, work: Path) -> None:
        """`work` becomes `repose`'s SfM workspace, removed with the mission."""
        self._sfm_work = work
        weakref.finalize(self, shutil.rmtree, work, True)

    def seen_through(self, points: np.ndarray) -> float:
        """The share of world `points` (N, 3) (m) lying where the map's photos saw empty space
        (`ViewQuality.seen_free` of the last goal choice, by `grid_seen_margin_m`); 0 with no
        point or before the first goal choice."""
        if self._seen_free is None or len(points) == 0:
            return 0.0
        return float(self._seen_free(points, self.config.grid_seen_margin_m).mean())


def start_filter(robot: Robot, body: Body, photos: list[MissionPhoto], rmap: RobotMap,
                 config: AdaptiveConfig, rng: np.random.Generator) -> FilteredBody:
    """The adaptive stage's body: the particle filter starts at the last random photo's SfM
    pose when SfM posed it (the robot has not moved since), else at the dead reckoning."""
    last = len(photos) - 1
    start, std = body.est.pose, None
    if last in rmap.cameras:
        start = robot_pose(rmap.cameras[last].world_from_cam, robot.cam_from_robot)
        std = np.array([0.1, 0.1, np.radians(3.0)])
    xy = np.array([c.center[:2] for c in rmap.cameras.values()] or [start[:2]])
    loc = MissionLocalizer(start, np.r_[xy, start[None, :2]], config.filter, rng, std)
    return FilteredBody(robot, loc, body.path_m)
