"""Re-posing the mission's photos by SfM over all of them, so the map follows the robot into
rooms it could not localise in.

The adaptive stage grows its map only from photos a PnP fix posed: a photo of a room the
map has no points of finds no fix, stays out of the map, and the next photo there fails the
same way while the filter drifts on odometry (14 % per drive). Yet the photos themselves
overlap: incremental SfM (COLMAP, Schoenberger & Frahm 2016) over every photo taken so far,
the localise photos included, chains them through the doorway. On two finished apartment
missions it posed 65 of 94 and 144 of 234 photos of rooms the mission never localised in,
within 3-4 cm of the truth after one similarity, where the filter had been 0.4-3.8 m off.

The SfM model is put into the map's frame by the similarity between its cameras and
the map's *anchors*, the photos SfM or a PnP fix posed before (not the goal photos posed
at the filter's estimate): the rotation from their orientations, the scale and shift from
their centres (`oriented_similarity`), then the scale from the floor (`floor_placed`: the
anchors span a few stops at first, and a scale set over 1-2 m is a few per cent off over
a whole apartment). The map keeps its place: SfM only adds what the map lacked. A model
whose anchors do not agree with it is not used (a wrong model, or one that merged two
rooms by a repeated texture). The anchors check a model only where it meets the map:
within a model that passes, a photo joins only where the robot's own odometry (its
compass-aided dead reckoning where it has one) ties it, photo by photo, to map photos that
agree (`odometry_held`); on two apartment missions (seeds 3 and 5) it let in 27 and 42
photos 0.15-4 m off, the map grew from them and the filter followed their wrong points.
The workspace keeps every photo's features, every pair's matches and the last model
between calls, so a call extracts, matches and registers only the photos taken since the
last (SfM of 533 photos from scratch: about 60 s of matching and 34 s of mapping on 2 cores).

Frames: world metres (the map's floor frame); cameras as `ibr.camera.Camera`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ibr.camera import Camera
from localization.motion_models import wrap_angle
from localization.pose_views import robot_camera
from robot.mission.circles import rot2d
from robot.mission.floor_scale import FloorScaleConfig, floor_scale
from robot.mission.map_building import (MapConfig, MapError, forget_model, heading_pairs, posed_images, robot_pose,
                                         run_sfm, transform_camera)
from robot.mission.sfm_process import run_sfm_within

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ReposeConfig:
    """Settings of `repose_photos` and of when the mission calls it."""

    min_anchors: int = 8
    """Fewest map photos the SfM model must share with the map to be placed by them."""
    max_anchor_error_m: float = 0.1
    """Largest median distance (m) between the anchors' map centres and the placed SfM
    centres. The anchors are SfM or PnP poses, 2-4 cm off; twice the issue's 5 cm
    localisation goal tells a consistent model from one bent or merged by a repeated texture.
    A robot-sized tolerance, not a scene's."""
    after_failures: int = 20
    """Re-pose when this many photos failed their PnP fix since the last re-posing and the
    filter's spread is above `MissionFilterConfig.relocalise_std_m` (a robot that keeps
    localising against its map, or knows where it is, does not need SfM)."""
    mapping_share: float = 0.5
    """COLMAP's mapping stops after this share of the watchdog's step limit
    (`AdaptiveConfig.step_limit_s`) and keeps the model it has, which the next call grows:
    the rest of the step (extraction, matching, the map's rebuild) fits in the other half,
    and a slow re-posing costs this call some photos instead of the mission (on apartment
    9, two missions sharing the 2 cores, a re-posing's mapping ran past the 600 s limit
    and the mission stopped with the watchdog's error). A share of the limit, not a time
    of any scene's."""
    time_share: float = 0.8
    """The whole SfM call (features, matching, mapping) runs in a child process, killed when
    the step has run this share of its limit (`sfm_process`): COLMAP checks its own stop
    only between registrations, and apartment 2's re-posing (920 photos, three missions on
    the 2 cores) was still in its mapping when the 600 s limit ended the mission. Killed,
    the re-posing leaves the map as it was; the rest of the step (the map's rebuild with
    the photos that joined) fits in the other fifth. A share of the limit, not a time of
    any scene's."""
    link_tol_m: float = 0.15
    """Two photos taken one after the other are linked when the SfM step between their robot
    poses is the robot's own measure of it (`robot_steps`) within this (m) ..."""
    link_drift: float = 0.15
    """... plus this share of the distance the odometry drove between them ..."""
    link_max_m: float = 5.0
    """... and it drove at most this (m). The robot's dead reckoning, not the scene's. Chosen
    on two re-posings run again offline (apartments 5 and 0, first re-posing of each),
    checked on a third (apartment 1): with 0.3 and 1.5 m, and the odometry's steps, they
    kept 8 of 58, 10 of 108 and 0 of 87 photos SfM posed right (within 15 cm), because a
    gap of photos SfM left unposed (1.8-2.2 m driven) cut each run from the map's photos;
    now 20, 108 and 87, and none of the 7 posed wrong (0.2-1.2 m off). Wrong runs met
    before sat 0.4-4 m off, right steps missed by 0.25 m over 1.8 m."""
    link_photos: int = 3
    """A photo is linked to any of this many photos SfM posed before it, not only the last:
    one photo SfM got wrong does not cut a run of right ones in two (on that mission the
    right photos kept rose from 97 to 101 of 118, and from 187 to 226 of 248 on another,
    seed 3 again, round 10; none wrong kept with 1, 2, 3 or 5)."""
    floor_photos: int = 150
    """The placed model's scale is checked on the floor (`floor_placed`) over at most this
    many of its photos, spread evenly over the order they were taken in (a few per stop):
    `floor_scale` compares every two of them, and its median needs tens of pairs, not
    thousands. A count of photos, not a length of any scene."""
    window: int = 3
    """A photo taken only to localise is matched with the model's photos facing its way and
    with the next `window` photos the robot took (consecutive photos overlap), not with
    every other localise photo: a lost robot takes three of them per model photo, and
    matching all pairs grows as N^2 (a mission's 800 photos: 130,000 pairs)."""
    max_seen_through: float = 0.4
    """Largest share of the points the joining photos' tracks would add that may lie where the
    map's own photos saw empty space (`AdaptiveMission.seen_through`); above it the re-posing
    joins nothing. The anchors check a model only where it meets the map, and the odometry
    ties photo to photo within 0.15 m plus 15 %: on apartment 2 a chain of 30 photos joined
    0.30 m off at the median (the floor gave no scale), their 940 points lay 0.2 m from any
    surface at the median, filled the kitchen the robot stood in, and no goal was reachable
    from there (the mission stopped at 140 photos). That re-posing's share was 0.55. Over
    every other re-posing of a 15-world sweep (apartments 0-9, offices 0-4; photos 1-8 cm
    off at the median) it was 0.00-0.30: the proxy lags where new photos look, and true
    points in front of it count. A share of points between the two, no length of a scene."""


def rotation_mean(rotations: np.ndarray) -> np.ndarray:
    """(3, 3) chordal L2 mean of rotations (N, 3, 3): the rotation nearest their sum
    (Hartley, Trumpf, Dai & Li, "Rotation averaging", IJCV 2013, section 5.3)."""
    U, _, Vt = np.linalg.svd(rotations.sum(axis=0))
    return U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt


def oriented_similarity(sfm: list[Camera], anchors: list[Camera], scale: float | None = None) -> np.ndarray:
    """(4, 4) similarity map_from_sfm from cameras seen in both frames: the rotation from
    their orientations (`rotation_mean` of R_map R_sfm^T), then the scale and shift that
    fit their centres with it (least squares; the shift alone with a known `scale`, map
    metres per SfM unit). A ground robot's camera centres all lie at its camera's height:
    fitted to the centres alone (Umeyama 1991), the tilt of the placed model rests on
    their centimetres of height noise over a few metres. On
    apartment 7 (main, traced) the PnP fixes right to 10 cm stood ~3.5 degrees out of the
    map's level for the 300 photos after two re-posings (0.2-0.6 before), so the level check
    (`AdaptiveConfig.max_fix_tilt_px`) threw away 191 right fixes; it let 240 pass. Each camera's
    orientation gives the tilt on its own, to a fraction of a degree: on apartment 9 a
    placement tilted 0.64 degrees by the centres was level to 0.04, and 62 % of the PnP
    attempts passed instead of 47 %."""
    R = rotation_mean(np.array([a.world_from_cam[:3, :3] @ c.world_from_cam[:3, :3].T for c, a in zip(sfm, anchors)]))
    src = np.array([c.center for c in sfm]) @ R.T
    dst = np.array([a.center for a in anchors])
    ds, dd = src - src.mean(0), dst - dst.mean(0)
    s = float(np.sum(ds * dd) / np.sum(ds * ds)) if scale is None else float(scale)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = s * R, dst.mean(0) - s * src.mean(0)
    return T


def anchored(sfm: dict[int, Camera], anchors: dict[int, Camera],
             config: ReposeConfig = ReposeConfig(), scale: float | None = None) -> tuple[np.ndarray, float] | None:
    """(map_from_sfm (4, 4), median anchor error m) placing the SfM cameras {photo: Camera}
    onto the map's `anchors` by their shared photos (`oriented_similarity`, at a known
    `scale` when given): fitted on all, refitted on the half whose centres agree best (a
    few anchors posed wrong by a bad fix do not bend it). None with too few shared photos
    or a median error above `max_anchor_error_m`."""
    shared = sorted(set(sfm) & set(anchors))
    if len(shared) < config.min_anchors:
        return None
    src = np.array([sfm[i].center for i in shared])
    dst = np.array([anchors[i].center for i in shared])
    T = oriented_similarity([sfm[i] for i in shared], [anchors[i] for i in shared], scale)
    err = np.linalg.norm(dst - (src @ T[:3, :3].T + T[:3, 3]), axis=1)
    best = np.argsort(err)[: max(config.min_anchors, len(shared) // 2)]
    T = oriented_similarity([sfm[shared[k]] for k in best], [anchors[shared[k]] for k in best], scale)
    err = np.linalg.norm(dst - (src @ T[:3, :3].T + T[:3, 3]), axis=1)
    median = float(np.median(err))
    return (T, median) if median <= config.max_anchor_error_m else None


def floor_placed(sfm: dict[int, Camera], images: list[np.ndarray], anchors: dict[int, Camera],
                 placed: tuple[np.ndarray, float], floor: FloorScaleConfig, cam_from_robot: np.ndarray,
                 config: ReposeConfig = ReposeConfig()) -> tuple[np.ndarray, float, float]:
    """(map_from_sfm (4, 4), median anchor error m, the floor's factor k; NaN: none) of
    the SfM cameras `sfm` placed by the anchors (`placed`, from `anchored`), at the scale
    the floor gives them: the model placed by `placed`, the floor's factor k (true / placed
    scale, `floor_scale`) over `floor_photos` of its photos, each on the robot's rig at its
    placed pose (`on_rig`), then the anchors fit again at the scale k times the
    placement's (the rotation from the orientations, the shift from the centres). The
    anchors set the scale only over their own span, which is short at first (the first
    map's few stops, 1-2 m): on apartment 9 the first re-posing's model, 3 cm from the
    truth after a similarity of its own, was placed 3.6 % small (the floor read 1.0379, the
    truth 1.0382), the photos it added to the map stood 10 cm off at the median, and the
    next re-posings took those as anchors: the map's photos drifted to 7 cm off, and the
    photos re-posings added over the mission to 8.0 cm (90th percentile 14 cm); with the
    floor's scale 1.5 cm (3.0), and the map's photos stayed at 0.5 cm.
    `placed` is kept when the floor gives no factor, or when the anchors do not fit at
    its scale (`anchored`)."""
    T, err = placed
    ids = sorted(sfm)
    pick = [ids[k] for k in np.unique(np.linspace(0, len(ids) - 1, config.floor_photos).round().astype(int))]
    rig = {i: on_rig(transform_camera(sfm[i], T), cam_from_robot) for i in pick}
    k, _ = floor_scale({i: images[i] for i in pick}, rig, floor)
    if not np.isfinite(k):
        return T, err, float("nan")
    again = anchored(sfm, anchors, config, scale=k * float(np.cbrt(np.linalg.det(T[:3, :3]))))
    return (*again, k) if again is not None else (T, err, float("nan"))


def on_rig(cam: Camera, cam_from_robot: np.ndarray) -> Camera:
    """The camera of the robot standing where `cam` (map frame) puts it (`robot_pose`): at
    the mount's height, pitch and roll, the heading and place of `cam`. The floor's
    homography reads a camera's height and tilt as scale; SfM's cameras carry centimetres
    and tenths of a degree of both, the rig none (the first map is measured after its rig
    adjustment for the same reason)."""
    return robot_camera(robot_pose(cam.world_from_cam, cam_from_robot), cam.K, (cam.width, cam.height),
                        cam_from_robot, name=cam.name)


def odometry_held(poses: dict[int, np.ndarray], odometry: np.ndarray, anchors_agree: dict[int, bool],
                  config: ReposeConfig = ReposeConfig(), dead_reckoning: np.ndarray | None = None) -> set[int]:
    """The photos of `poses` {photo: robot pose (x, y m, theta rad) in the map frame, from
    SfM} that the robot's own odometry ties to the map: each photo is linked to those of the
    `link_photos` posed before it (in the order taken; `odometry` (N, 3) of every photo, in
    the odometry frame) whose step to it agrees (`_step_agrees`, on `robot_steps`), and a
    run of linked photos is kept when most of its anchors agree with the map
    (`anchors_agree` {photo: its SfM pose within `max_anchor_error_m` of its map pose}). A
    run no anchor holds is left out: `anchored` checks the model only where it meets the
    map, and that re-posing of the apartment mission above had 19 new photos in runs
    0.15-4 m off (one room's repeated texture taken for another's) beside 118 right ones,
    with its anchors 1.9 cm off at the median; all 19 are left out here, and 101 of the 118
    kept. `dead_reckoning` (N, 3): each photo's compass-aided dead reckoning (world frame;
    NaN where unknown), the steps' better measure where two photos have it."""
    ids, odometry = sorted(poses), np.asarray(odometry, float)
    driven = np.r_[0.0, np.cumsum(np.hypot(*np.diff(odometry[:, :2], axis=0).T))]
    step = robot_steps(poses, odometry, dead_reckoning)
    links = [(a, b) for b in range(len(ids)) for a in range(max(0, b - config.link_photos), b)
             if _step_agrees(poses[ids[a]], poses[ids[b]], step(ids[a], ids[b]), driven[ids[b]] - driven[ids[a]],
                             config)]
    a, b = np.array(links, int).reshape(-1, 2).T
    _, run = connected_components(coo_matrix((np.ones(len(a)), (a, b)), shape=(len(ids), len(ids))), directed=False)
    kept = set()
    for r in np.unique(run):
        members = [ids[k] for k in np.flatnonzero(run == r)]
        votes = [anchors_agree[i] for i in members if i in anchors_agree]
        if 2 * sum(votes) > len(votes):
            kept.update(members)
    return kept


def robot_steps(poses: dict[int, np.ndarray], odometry: np.ndarray, dead_reckoning: np.ndarray | None):
    """step(i, j): the robot's own measure (2,) of its move from photo i to photo j, in the
    map frame (m). Where both photos have a compass-aided dead reckoning, its step, turned
    by the map's heading offset from the compass (the median over the posed photos): the
    compass bounds the heading error of every drive. Else the odometry's step turned by
    photo i's map heading: its heading drifts with every turn between the two photos (the
    simulated robot's: 0.14 x the turn), and on an apartment mission the compass's steps
    missed the truth by 0.15 m at the 90th percentile where the odometry's missed by 0.19
    (0.17 against 0.23 on another; at most 0.53 m against 1.37)."""
    dr = np.full((len(odometry), 3), np.nan) if dead_reckoning is None else np.asarray(dead_reckoning, float)
    known = [i for i in poses if np.isfinite(dr[i]).all()]
    offset = float(np.median([wrap_angle(poses[i][2] - dr[i][2]) for i in known])) if known else 0.0

    def step(i: int, j: int) -> np.ndarray:
        if np.isfinite(dr[[i, j]]).all():
            return rot2d(offset) @ (dr[j, :2] - dr[i, :2])
        return rot2d(poses[i][2] - odometry[i, 2]) @ (odometry[j, :2] - odometry[i, :2])
    return step


def _step_agrees(p0: np.ndarray, p1: np.ndarray, step: np.ndarray, driven_m: float, config: ReposeConfig) -> bool:
    """Whether the step between two robot poses `p0`, `p1` (3,) in the map frame is the
    robot's own measure of it, `step` (2,) (`robot_steps`), within `link_tol_m` +
    `link_drift` x `driven_m`, with at most `link_max_m` driven."""
    miss = float(np.hypot(*(p1[:2] - p0[:2] - step)))
    return driven_m <= config.link_max_m and miss <= config.link_tol_m + config.link_drift * driven_m


def repose_pairs(compass_rad: np.ndarray, in_model: np.ndarray, max_heading_rad: float, window: int) -> np.ndarray:
    """(P, 2) photo pairs i < j to match: photos facing within `max_heading_rad` of each
    other (`map_building.heading_pairs`) of which one is a model photo (`in_model` (N,)
    bool), and each photo with the next `window` photos taken."""
    facing = heading_pairs(np.asarray(compass_rad, float), max_heading_rad)
    facing = facing[in_model[facing].any(axis=1)]
    n = len(compass_rad)
    after = np.array([(i, j) for i in range(n) for j in range(i + 1, min(n, i + 1 + window))], int).reshape(-1, 2)
    return np.unique(np.vstack([facing, after]), axis=0)


def sfm_cameras(images: list[np.ndarray], K: np.ndarray, pairs: np.ndarray, config: MapConfig,
                work: Path, max_seconds: float | None = None, limit_s: float | None = None
                ) -> tuple[dict[int, Camera], dict[int, int]] | None:
    """Cameras {photo: Camera, SfM frame} of the largest SfM model of `images` (the photo
    `pairs` (P, 2) matched; `work` keeps the features, matches and model of earlier calls,
    `map_building.run_sfm`, which grows that model alone, its mapping stopped after
    `max_seconds`) and each posed photo's number of triangulated observations (its
    support). With `limit_s`, SfM runs in a child process killed after that many seconds
    (`sfm_process.run_sfm_within`); None: it was."""
    if limit_s is None:
        rec = run_sfm(images, K, np.zeros(len(images)), config, work, pairs, grow_only=True,
                      max_seconds=max_seconds)[0]
    else:
        rec = run_sfm_within(images, K, config, work, pairs, True, max_seconds, limit_s)
        if rec is None:
            return None
    posed = posed_images(rec)
    return ({i: Camera.from_pycolmap(im, rec.cameras[im.camera_id]) for i, im in posed.items()},
            {i: int(im.num_points3D) for i, im in posed.items()})


def repose_photos(images: list[np.ndarray], K: np.ndarray, compass_rad: np.ndarray, in_model: np.ndarray,
                  anchors: dict[int, Camera], map_config: MapConfig, work: Path,
                  config: ReposeConfig = ReposeConfig(), max_seconds: float | None = None,
                  limit_s: float | None = None, cam_from_robot: np.ndarray | None = None
                  ) -> tuple[dict[int, Camera], dict[int, int], float] | str:
    """SfM over every photo (`sfm_cameras` of the `repose_pairs` of their compass headings
    (N,) and whether each is a model photo (N,), in the workspace `work`), placed in the
    map's frame by its `anchors` (`anchored`), at the floor's scale where the robot's
    mount `cam_from_robot` is given and `map_config.floor_scale` is set (`floor_placed`):
    ({photo: Camera in the map frame} of every photo the largest model posed, their
    support, the median anchor error m), or why not (SfM failed, or its model does not
    agree with the anchors: then the next call maps afresh, `map_building.forget_model`),
    or because SfM ran past `limit_s` seconds (`sfm_cameras`; None: no limit).
    `max_seconds`: the longest COLMAP's mapping may run (None: no limit)."""
    pairs = repose_pairs(compass_rad, np.asarray(in_model, bool), map_config.match_heading_rad, config.window)
    try:
        found = sfm_cameras(images, K, pairs, map_config, work, max_seconds, limit_s)
    except MapError as e:
        return f"SfM failed ({e})"
    if found is None:
        return f"SfM stopped after {limit_s:.0f} s, its share of the step's time limit"
    cams, support = found
    placed = anchored(cams, anchors, config)
    if placed is None:
        shared = len(set(cams) & set(anchors))
        if shared < config.min_anchors:
            return f"its largest model shares {shared} photos with the map (needs {config.min_anchors})"
        forget_model(work)  # grown further, a bent or merged model stays so (apartment 2: 5 calls in a row)
        return (f"the map's photos do not fit its largest model ({shared} shared, median error above "
                f"{100 * config.max_anchor_error_m:.0f} cm; the next re-posing maps afresh)")
    if map_config.floor_scale is not None and cam_from_robot is not None:
        t0 = time.perf_counter()
        T, err, k = floor_placed(cams, images, anchors, placed, map_config.floor_scale, cam_from_robot, config)
        why = (f"the floor scales the placed model by {k:.4f}" if np.isfinite(k) else
               "the anchors' scale kept (no floor scale they fit)")
        log.info(f"re-posing by SfM: {why} ({time.perf_counter() - t0:.1f} s)")
    else:
        T, err = placed
    return {i: transform_camera(c, T) for i, c in cams.items()}, support, err
