"""How well a simulated capture mission did, against the simulator's truth (which the mission
itself never reads): the localisation error of the adaptive stage's photos, the map's scale
error, the rooms the robot photographed, and the new views its model renders
(`eval_capture`). Used by `ibrnav explore --json` and `ibrnav eval-capture`.
Frames: world SE(2) poses (x, y, theta), metres, radians.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from localization.motion_models import wrap_angle
from robot.mission.map_building import RobotMap, umeyama
from robot.mission.observer import MissionPhoto
from robot.protocol import se2_matrix

log = logging.getLogger(__name__)

PSNR_CEILING_DB = float(10 * np.log10(255.0 ** 2 * 12))
"""The PSNR of a view rendered exactly (zero error) counts as this (58.9 dB): the PSNR of
an error as small as 8-bit rounding itself (variance 1/12 grey level squared), so a perfect
view is the best score rather than an infinity the summaries would have to drop. A property
of 8-bit images, not of any scene."""


def true_poses(truth: list[dict]) -> dict[int, np.ndarray]:
    """{photo index: true SE(2) pose} from a `SimRobot.truth` list."""
    return {int(t["index"]): np.asarray(t["pose"], float) for t in truth}


def localisation_errors(photos: list[MissionPhoto], truth: dict[int, np.ndarray]) -> dict | None:
    """Position error (m: median, p95, max) and heading error (deg: median, p95) of the
    robot's estimate at each photo of the adaptive stage (goal and localisation photos:
    the filter's estimate right after the photo's vision fix), against the truth; under
    "model", the same over the adaptive stage's model photos alone (its goal photos, the
    paper's 153 adaptive photos; None without one). The localisation photos are most of
    the stage's photos (841 of 994 on apartment 1) and a failed one reads the odometry's
    drift since the last fix, so the two figures differ. None when the mission has no
    adaptive photo."""
    adaptive = _adaptive_photos(photos, truth)
    if not adaptive:
        return None
    out = _pose_errors(adaptive, truth)
    model = [p for p in adaptive if p.stage == "goal"]
    out["model"] = _pose_errors(model, truth) if model else None
    return out


def localisation_errors_by_region(world, photos: list[MissionPhoto], truth: dict[int, np.ndarray]) -> dict | None:
    """`localisation_errors` (without "model") of the adaptive stage's photos split by where
    each was truly taken: "random_stage_regions", in a room or corridor where the random stage
    took a photo (what the first map holds), and "later_regions", anywhere else (regions the
    robot first entered in the adaptive stage, and doorway thresholds); None for a part
    without photos. The split shows where the map runs out: on 11 apartments (seeds 0-5, 7,
    8, 11-13, the ultrasonic read along every path) the later regions' photos were localised
    to a pooled median of 9.7 cm (5.5 cm on seeds 11-13) against 2.4 cm (0.9 cm) in the first
    map's. None when the mission has no adaptive photo."""
    adaptive = _adaptive_photos(photos, truth)
    if not adaptive:
        return None
    region = lambda p: world.room_at(truth[p.photo.index][:2])  # noqa: E731
    first = {region(p) for p in photos if p.stage == "random" and p.photo.index in truth} - {None}
    in_first = [region(p) in first for p in adaptive]
    parts = {"random_stage_regions": [p for p, k in zip(adaptive, in_first) if k],
             "later_regions": [p for p, k in zip(adaptive, in_first) if not k]}
    return {k: _pose_errors(v, truth) if v else None for k, v in parts.items()}


LOST_M = 0.15
"""A photo whose estimate is farther than this (m) from the truth counts as taken lost: the
issue's bar for the 95th percentile of the localisation error, not a property of a scene."""


def lost_episodes(photos: list[MissionPhoto], truth: dict[int, np.ndarray], lost_m: float = LOST_M) -> dict | None:
    """How the adaptive stage's photos (goal and localisation) that were taken lost (estimate
    more than `lost_m` off the truth, m) came: {"photos", "lost", "episodes": runs of them in a
    row, "longest": the longest run (photos)}. The 95th percentile of the error is made of
    such runs, not of scattered misses: on apartments 0 and 2 (main 3ccf719) 12 and 15 runs,
    the longest 25 and 153 photos, where every PnP fix failed and the estimate rode the
    odometry; 74 of apartment 0's 75 lost photos were in the room the random stage never
    saw. None without adaptive photos."""
    adaptive = _adaptive_photos(photos, truth)
    if not adaptive:
        return None
    lost = _position_errors(adaptive, truth) > lost_m
    edges = np.diff(np.r_[0, lost.astype(int), 0])
    runs = np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)
    return {"photos": len(lost), "lost": int(lost.sum()), "episodes": len(runs), "longest": int(runs.max(initial=0))}


def localisation_errors_by_fix(photos: list[MissionPhoto], truth: dict[int, np.ndarray],
                               lost_m: float = LOST_M) -> dict | None:
    """`localisation_errors` (without "model") of the adaptive stage's photos split by whether
    a PnP fix of the photo was the filter's measurement (`MissionPhoto.fixed`): "fixed", and
    "unfixed" (no pose, or a pose the checks rejected: the estimate rode the odometry since
    the last fix); None for a part without photos. "lost_unfixed": the share of the photos
    taken lost (more than `lost_m` off, m) that had no fix. The split says which way the
    95th percentile goes: apartment 6 (main a2834fe) had fixed photos at a median of 5.2 cm
    and p95 14.7 cm, unfixed ones at 9.8 and 32.4 cm, and 110 of its 147 lost photos unfixed.
    Photos whose `fixed` is not known (a session resumed from before it was recorded) are in
    neither part. None when the mission has no adaptive photo."""
    adaptive = _adaptive_photos(photos, truth)
    if not adaptive:
        return None
    parts = {"fixed": [p for p in adaptive if p.fixed is True], "unfixed": [p for p in adaptive if p.fixed is False]}
    out = {k: _pose_errors(v, truth) if v else None for k, v in parts.items()}
    lost = {k: int((_position_errors(v, truth) > lost_m).sum()) for k, v in parts.items()}
    n_lost = lost["fixed"] + lost["unfixed"]
    out["lost_unfixed"] = lost["unfixed"] / n_lost if n_lost else None
    return out


def _adaptive_photos(photos: list[MissionPhoto], truth: dict[int, np.ndarray]) -> list[MissionPhoto]:
    """The adaptive stage's photos (goal and localisation) that have a true pose."""
    return [p for p in photos if p.stage != "random" and p.photo.index in truth]


def _position_errors(photos: list[MissionPhoto], truth: dict[int, np.ndarray]) -> np.ndarray:
    """(N,) distance (m) from each photo's estimate to its true position."""
    est = np.array([p.estimate for p in photos]).reshape(-1, 3)
    true = np.array([truth[p.photo.index] for p in photos]).reshape(-1, 3)
    return np.hypot(*(est[:, :2] - true[:, :2]).T)


def _pose_errors(photos: list[MissionPhoto], truth: dict[int, np.ndarray]) -> dict:
    est = np.array([p.estimate for p in photos])
    true = np.array([truth[p.photo.index] for p in photos])
    d = _position_errors(photos, truth)
    h = np.degrees(np.abs(wrap_angle(est[:, 2] - true[:, 2])))
    return {"photos": len(d), "median": float(np.median(d)), "p95": float(np.percentile(d, 95)),
            "max": float(d.max()), "heading_median_deg": float(np.median(h)),
            "heading_p95_deg": float(np.percentile(h, 95))}


def facing_distances(mesh, photos: list[MissionPhoto], truth: dict[int, np.ndarray], camera_height_m: float) -> dict:
    """How far ahead the model photos looked: per stage ("random", "adaptive": its goal
    photos), {p25, median, p75 (m), photos, open} of the distance from each photo's true
    camera centre, level along its true heading, to the first surface of the true `mesh`
    (embree through trimesh); "open" counts the rays that met nothing (they are not in the
    quartiles); None for a stage without photos (or without one that met a surface). Why:
    a level camera sees a surface at height z only from (z - camera height) / tan(half its
    vertical field of view) away, so photos that all face a surface about 1 m ahead never
    see the upper walls and ceiling (missions of apartment 0 and office 0 at 261 photos, the
    ultrasonic read along every path: the adaptive photos' median 1.1 and 1.0 m; the tenth
    of a dense set's 2,000 poses that saw the most of the upper surfaces those missions
    missed, 3.8 and 4.6 m)."""
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    rays = RayMeshIntersector(mesh)
    out: dict = {}
    for stage, name in (("random", "random"), ("goal", "adaptive")):
        poses = np.array([truth[p.photo.index] for p in photos if p.stage == stage and p.photo.index in truth])
        out[name] = _facing(rays, poses.reshape(-1, 3), camera_height_m)
    return out


def _facing(rays, poses: np.ndarray, camera_height_m: float) -> dict | None:
    """`facing_distances`' figure of SE(2) poses (N, 3)."""
    origins = np.c_[poses[:, :2], np.full(len(poses), camera_height_m)]
    dirs = np.c_[np.cos(poses[:, 2]), np.sin(poses[:, 2]), np.zeros(len(poses))]
    hits, ray, _ = rays.intersects_location(origins, dirs, multiple_hits=False) if len(poses) else ([], [], [])
    d = np.linalg.norm(np.asarray(hits).reshape(-1, 3) - origins[ray], axis=1)
    if len(d) == 0:
        return None
    p25, median, p75 = np.percentile(d, [25, 50, 75])
    return {"p25": float(p25), "median": float(median), "p75": float(p75), "photos": len(poses),
            "open": len(poses) - len(d)}


def map_scale_error(robot_map: RobotMap | None, truth: dict[int, np.ndarray], cam_from_robot: np.ndarray,
                    photos: list[MissionPhoto], only: frozenset[int] | None = None) -> float | None:
    """|s - 1| of the 2-D similarity (Umeyama) from the map's camera centres of the random
    stage's photos (posed by SfM; of those in `only` alone, when given) onto their true
    centres: 0 for a map in metres. None without at least 3 such photos."""
    if robot_map is None:
        return None
    idx = [i for i in robot_map.cameras if i < len(photos) and photos[i].stage == "random"
           and photos[i].photo.index in truth and (only is None or i in only)]
    if len(idx) < 3:
        return None
    mapped = np.array([robot_map.cameras[i].center[:2] for i in idx])
    true = np.array([(se2_matrix(truth[photos[i].photo.index]) @ np.linalg.inv(cam_from_robot))[:2, 3]
                     for i in idx])
    s, _, _ = umeyama(mapped, true)
    return float(abs(s - 1.0))


def rooms_visited(world, photos: list[MissionPhoto], truth: dict[int, np.ndarray]) -> tuple[list[str], list[str]]:
    """(rooms where a model photo was taken, every room of the world; corridors excluded)."""
    rooms = [r.name for r in world.rooms if r.kind == "room"]
    seen = {world.room_at(truth[p.photo.index][:2]) for p in photos
            if p.stage != "localise" and p.photo.index in truth}
    return [r for r in rooms if r in seen], rooms


def model_of_photos(photos: list[MissionPhoto], robot, config) -> RobotMap | None:
    """The map the mission's first stage would build of `photos` (`map_building.initial_map`:
    SfM, placed in metres by dead reckoning and the compass; `config` a `MapConfig`), the
    photos it posed given their cameras, meshed as the mission's final model
    (`map_building.capture_model`); None when SfM poses too few of them. For a capture with
    no map of its own (random exploration alone), so that its new views are judged
    (`eval_capture`) like the mission's."""
    from robot.mission.map_building import MapError, capture_model, initial_map

    try:
        rmap = initial_map([p.photo.image for p in photos], robot.intrinsics,
                           np.array([p.estimate for p in photos]), np.array([p.photo.compass_rad for p in photos]),
                           robot.cam_from_robot, config, np.array([p.photo.range_m for p in photos]))
    except MapError as e:
        log.info(f"no map of the {len(photos)} photos: {e}")
        return None
    for i, cam in rmap.cameras.items():
        photos[i].camera = cam
    return capture_model(rmap, config)


def evaluation_poses(world, n_poses: int, rng: np.random.Generator, clearance_m: float = 0.15) -> np.ndarray:
    """(n_poses, 3) random robot poses (x, y, theta) in the world's free space eroded by
    `clearance_m` (the robot's radius, m), random headings: where `eval_capture` looks."""
    from explore.candidates import sample_candidates

    return sample_candidates(world.free_space, n_poses, rng, clearance_m)


def eval_capture(world, cameras: list, images: list[np.ndarray], mesh, n_poses: int, rng: np.random.Generator,
                 intrinsics: np.ndarray, size: tuple[int, int], cam_from_robot: np.ndarray,
                 clearance_m: float = 0.15, ctx=None, on_view: Callable | None = None,
                 ulr_config=None) -> dict:
    """What the capture is for: new views. ULR renders (`ibr.render.ulr`) of the captured
    model (posed `cameras`, their `images`, the proxy `mesh`) at `n_poses` random robot
    poses in the world's free space (`evaluation_poses`; the robot's camera height and
    intrinsics at `size` (w, h)) against the world's true renders: PSNR (dB) and SSIM over
    the covered pixels (at most `PSNR_CEILING_DB`), and the covered fraction; mean and worst
    decile (the mean of the worst 10 %) of each. Views ULR covers nowhere count with a
    covered fraction of 0 and no PSNR/SSIM. `on_view(k, pose (3,), camera, rendered, truth,
    metrics)` is called after each view (`metrics`: {"psnr_db", "ssim", "covered"}, None
    where nothing is covered): for progress, logging and per-view reports. `ulr_config`
    (`ibr.render.ulr.UlrConfig`): the renderer's settings (default: the sparse blending
    field; blending="pixel" is the quality reference)."""
    from ibr.render.eval import psnr, ssim
    from ibr.render.ulr import UlrRenderer
    from ibr.scene import Scene, View
    from robot.protocol import robot_camera

    poses = evaluation_poses(world, n_poses, rng, clearance_m)
    ulr = UlrRenderer(Scene("capture", [View(c, im) for c, im in zip(cameras, images)]), mesh, ctx,
                      config=ulr_config)
    p, s, cov = [], [], []
    try:
        for k, pose in enumerate(poses):
            cam = robot_camera(pose, intrinsics, size, cam_from_robot, name=f"eval_{k:03d}")
            truth = world.photograph(cam, ctx)
            image, covered = ulr.render(cam)
            m = {"psnr_db": None, "ssim": None, "covered": float(covered.mean())}
            if covered.any():
                m["psnr_db"] = min(float(psnr(image, truth, covered)), PSNR_CEILING_DB)
                m["ssim"] = float(ssim(image, truth, covered))
                p.append(m["psnr_db"])
                s.append(m["ssim"])
            cov.append(m["covered"])
            if on_view is not None:
                on_view(k, pose, cam, image, truth, m)
    finally:
        ulr.release()
    return {"poses": len(poses), "psnr_db": _mean_and_worst_decile(p), "ssim": _mean_and_worst_decile(s),
            "covered": _mean_and_worst_decile(cov)}


def _mean_and_worst_decile(values: list[float]) -> dict:
    """{"mean", "worst_decile"} of the finite values (higher is better: the worst decile is
    the mean of the lowest 10 %, at least one value); None for both when there is none."""
    v = np.sort(np.asarray([x for x in values if np.isfinite(x)], float))
    if len(v) == 0:
        return {"mean": None, "worst_decile": None}
    return {"mean": float(v.mean()), "worst_decile": float(v[:max(1, len(v) // 10)].mean())}
