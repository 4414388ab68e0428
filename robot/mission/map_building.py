"""The robot's map from its photos: SfM, alignment to the floor frame, points, normals and a
Poisson mesh (Foster, Wang & Grupen, sections IV-A end, IV-B "Choosing a goal", IV-C).

`initial_map` poses the random-exploration photos with pycolmap's incremental SfM (the role
Bundler plays in the paper), made fast for a robot: one shared, known pinhole camera (not
refined), few SIFT features per small image, exhaustive matching of the (~100) photos.
COLMAP's frame is arbitrary, so each model is levelled (`levelled_model`: the cameras' known
up, from their SfM rotations and the mount, becomes +z) and given its metric scale by the
floor, the bottom of its points that two circles saw (`points_across_circles`), which lies
the camera's (known) height below the cameras,
and by the ultrasonic's ranges to the points each photo saw straight ahead (`sonar_scale`;
the floor of a plain floor holds too few points, and was 0.2-36 % off where the ultrasonic
was within 0.1-1.6 %).
SfM of a random stage breaks into several models (one per sector of headings: a circle of
photos is a pure rotation, and where a circle faces a bare wall nothing is triangulated);
`map_from_models` places them together in the floor frame by the robot's circles (the
floors, the compass and the dead reckoning from the known start; `robot.mission.circles`),
adjusts their photos and points on the robot's rig (each circle turned in place about one
axle, `robot.mission.rig_adjustment`: SfM takes part of the mount's swing for turn) and
poses the circles' remaining photos. Without any floor the odometry gives the scale
(the simulated odometry is 14 % off per drive, so that map is 10-17 % off).
The placed map's scale is then corrected by the floor seen in pairs of photos of different
stops (`robot.mission.floor_scale`: the floor plane's homography, with the cameras at their
known height, fixes the baselines' length): the placement's scale was -1.9 to +1.1 % off on
apartments 0-9 (first maps); the floor's first maps of apartments 0-9 and offices 0-4 are
0.00-0.62 % off (median 0.11 %), but for apartment 2 (1.07 %, where the pairs' median is
within 0.25 % of their baselines' true ratio: the error is the layout's, over photos
spanning 1.2 m) and apartment 5 (1.74 %). A map of one stop has no baseline, and one whose
floor is hidden (apartment 5 starts beside a bed: every floor pixel of its pairs is the
bed's top) has pairs that disagree; both keep the placement's scale.
With `MapConfig.floor_spans` the floor measures each distance between two stops instead
(`floor_scale.stop_spans`), and the map is placed and adjusted again with those spans, its
stops free on the rig. One factor fixes the one span most pairs saw and nothing else:
apartment 14's 65 pairs all came from its first two stops (0.6 m), while SfM's model of all
three had its third stop 8 cm short, so the factor took the map from 2.9 % to 4.5 % off;
with the spans it is 0.02 % off, apartment 2's 1.07 % is 0.24 % (first maps of 108 photos,
apartments 0-14 and office 0: within 1 % on 14 of 16 against 12). Off by default: the
missions it changes did not pass their rule (`explore --floor-spans`).

`extend_map` adds photos whose poses were localised (PnP) later: their SIFT features are
matched with their stereo partners (`stereo_tracks`) and triangulated with the poses *fixed*
(`ibr.proxy.triangulation`, no bundle adjustment), and the mesh is rebuilt. Frames: world metres, z up, floor z = 0;
SE(2) robot poses (x, y, theta).
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import logging

import cv2
import numpy as np
import trimesh

from explore.frontier import SonarConfig
from ibr.camera import Camera, rigid
from ibr.colmap import colmap_errors_only, import_in_name_order
from ibr.errors import InputError
from ibr.proxy.normals import estimate_normals, merge_repeats, remove_outliers
from ibr.proxy.poisson import MeshingError, PoissonConfig, poisson_mesh
from ibr.proxy.triangulation import TriangulationConfig, pair_tracks
from robot.mission.circles import (CircleConfig, LevelledModel, Placement, circle_ids, complete_circles, place_models,
                                   rot2d)
from robot.mission.floor_scale import FloorScaleConfig, floor_scale, rescaled, stop_spans
from robot.mission.rig_adjustment import RigAdjustmentConfig, RigObservations, adjust_on_rig, turned


log = logging.getLogger(__name__)


class MapError(InputError):
    """The photos could not be turned into a map (too few registered, no points)."""


@dataclass(frozen=True)
class MapConfig:
    """Settings of `initial_map` and `extend_map`."""

    max_features: int = 1500
    """SIFT features per photo for SfM."""
    sift_first_octave: int = -1
    """COLMAP's SIFT first octave: -1 doubles the image first (4x the work, but at 0 a 320x240
    photo keeps ~170 features and SfM registered 12 of 100 photos instead of 94)."""
    match_heading_rad: float = np.radians(75.0)
    """Photos are matched only with those whose compass headings differ less than this (rad)."""
    seed: int = 0
    """COLMAP's random seed, of its mapping and of each photo pair's verification (reproducible maps)."""
    min_registered: int = 10
    """Fewest photos SfM must register."""
    threads: int = 1
    """Worker threads of COLMAP's SIFT extraction. One, so that a mission repeats: on two, a
    photo's keypoints now and then came out otherwise (apartment 13's 108 first-map photos
    extracted 6 times: 2 runs differed from the first, in 1-2 photos; 0 of 8 on one thread),
    a pair at the edge of `min_num_inliers` was then verified or not, the first map placed
    18 or 19 photos in their circles and the whole mission went another way. One thread
    costs 6.2 s instead of 4.7 s for 108 photos (re-posings extract only the new ones)."""
    mapping_threads: int = 1
    """Threads of COLMAP's matching, mapping and bundle adjustment. One, so that a mission
    repeats. On two, the CPU matcher now and then matched a pair otherwise (2 of 9 runs of
    the same 108 photos: one pair 57 matches or none; 0 of 16 on one thread), and Ceres
    threads every adjustment of over 50,000 residuals, whose sums then come in another
    order (a 438-photo re-posing mapped twice: 5,465 or 5,450 points; identical on one).
    A mission amplifies either into another mission. Matching 25,177 pairs took 11.7 s on
    one thread, 10.2 s on two (brute force, also repeatable: 38.7 s)."""
    poisson: PoissonConfig = field(default_factory=lambda: PoissonConfig(depth=7, max_gap_spacing=4.0, threads=1))
    """Poisson meshing of the oriented points (coarse: the heuristic needs a rough proxy; one
    thread: its OpenMP threads spin and crawl, 10x, on a busy 2-core machine)."""
    model_poisson: PoissonConfig = field(
        default_factory=lambda: PoissonConfig(depth=8, max_gap_spacing=PoissonConfig.max_gap_spacing, threads=1))
    """Poisson meshing of the capture's model, what new views are rendered from (`capture_model`):
    one octree level finer than `poisson` (cells 1/256 of the map's extent), and gaps cut as for
    any photo proxy (`PoissonConfig.max_gap_spacing`), not at `poisson`'s 4. The map's points
    are pair tracks, each feature triangulated from several pairs a millimetre or two apart
    (median nearest neighbour 1.2-1.4 mm on two finished apartment missions, 42-51 % of the
    points repeats), so the spacing the cut is measured in was small and 4 of it cut away
    the walls the map saw only sparsely. On those two missions (seeds 0 and 1), ULR at 50
    random free-space poses covered 0.42 and 0.47 of the views (repeats merged, this
    meshing) instead of 0.17 and 0.13 (the map's proxy). Over the pixels both meshes cover,
    the mean PSNR moved +0.3 and 0.0 dB with the finer meshing, then +0.4 and -0.2 dB with
    the repeats merged."""
    max_point_range_m: float = 12.0
    """Points farther than this from every camera are dropped (badly triangulated)."""
    max_camera_height_err_m: float = 0.15
    """A photo SfM posed more than this above or below the camera's height on the mount is a
    wrong registration (the robot stands on a flat floor) and stays out of the map, with
    the points only it saw (apartment 3: seven photos of one circle posed 0.5 m low, tilted
    4 degrees; PnP against their points gave fixes as wrong). The mission's bound on a PnP
    fix's height (`AdaptiveConfig.max_fix_height_err_m`) is the same."""
    circles: CircleConfig = field(default_factory=CircleConfig)
    """How SfM's models are placed together and the circles completed (`robot.mission.circles`)."""
    rig: RigAdjustmentConfig | None = field(default_factory=RigAdjustmentConfig)
    """The placed photos and points adjusted on the robot's rig (`robot.mission.rig_adjustment`;
    None: SfM's poses as placed)."""
    sonar: SonarConfig = field(default_factory=SonarConfig)
    """The ultrasonic's geometry (`sonar_scale`)."""
    floor_scale: FloorScaleConfig | None = field(default_factory=FloorScaleConfig)
    """The placed map's scale corrected by the floor's homographies between its photos
    (`robot.mission.floor_scale`; None: the placement's scale kept)."""
    floor_spans: bool = False
    """The floor measures the distance between each two stops (`floor_scale.stop_spans`),
    and the map is placed and adjusted on the rig again with them, its stops free, instead
    of one factor for the whole map (module docstring: first maps within 1 % of scale on 14
    of 16 worlds against 12). Off by default: swept over 16 worlds, the missions' p95 fell on
    11 but rose by 4.4 cm on the mean (apartment 6: 17 -> 150 cm, a lost run after a
    re-posing), rooms visited 31 -> 29; on 6 more worlds rooms 13 -> 11."""


@dataclass
class RobotMap:
    """The map: `cameras` {photo index: Camera in the floor frame}; `points` (N, 3) metres,
    `colors` (N, 3) uint8, `normals` (N, 3) unit; `mesh` the Poisson proxy; `registered`
    how many photos SfM posed."""

    cameras: dict[int, Camera]
    points: np.ndarray
    colors: np.ndarray
    normals: np.ndarray
    mesh: trimesh.Trimesh
    registered: int = 0
    floor_scaled: bool | None = None
    """The first map's: True when the floor seen from two stops fixed its scale
    (`floor_scale`, or a distance between them, `floor_scale.stop_spans`, that placed it);
    False when too few pairs of photos saw it (a map of one stop has no baseline) or they
    disagree, so its scale is the placement's, unchecked; None: not tried."""

    def poses(self, cam_from_robot: np.ndarray) -> dict[int, np.ndarray]:
        """SE(2) robot pose (x, y, theta) of each mapped photo (the mount undone)."""
        return {i: robot_pose(cam.world_from_cam, cam_from_robot) for i, cam in self.cameras.items()}


def stereo_pairs(cameras: list[Camera], k: int, min_baseline_m: float = 0.25,
                 max_axis_angle_rad: float = np.radians(40.0)) -> np.ndarray:
    """(P, 2) index pairs i < j: each camera with its k nearest others among those at least
    `min_baseline_m` away whose optical axes differ less than `max_axis_angle_rad`. A robot's
    circles of photos share a centre up to the mount offset, so the plain nearest views
    (`ibr.proxy.triangulation.neighbour_pairs`) would be stereo pairs with no baseline."""
    C = np.array([c.center for c in cameras]).reshape(-1, 3)
    F = np.array([c.forward for c in cameras]).reshape(-1, 3)
    dist = np.linalg.norm(C[:, None] - C[None], axis=2)
    ang = np.arccos(np.clip(F @ F.T, -1.0, 1.0))
    score = dist * (1.0 + 2.0 * ang)
    score[(dist < min_baseline_m) | (ang > max_axis_angle_rad)] = np.inf
    pairs = {(min(i, j), max(i, j)) for i in range(len(cameras))
             for j in np.argsort(score[i])[:k] if np.isfinite(score[i, j])}
    return np.array(sorted(pairs), dtype=int).reshape(-1, 2)


# --- SfM -------------------------------------------------------------------------------
def heading_pairs(headings: np.ndarray, max_diff_rad: float) -> np.ndarray:
    """(P, 2) index pairs i < j of photos whose compass headings (rad) differ by less than
    `max_diff_rad`: only they can share SIFT features (opposite views never do)."""
    d = np.abs(np.angle(np.exp(1j * (headings[:, None] - headings[None]))))
    i, j = np.nonzero(np.triu(d < max_diff_rad, 1))
    return np.c_[i, j]


def run_sfm(images: list[np.ndarray], K: np.ndarray, headings: np.ndarray, config: MapConfig, work: Path,
            pairs: np.ndarray | None = None, grow_only: bool = False, max_seconds: float | None = None):
    """pycolmap incremental SfM of `images` (H, W, 3) uint8 with the known shared `K`, matching
    only the photos whose compass `headings` (rad) are within `config.match_heading_rad`
    (`heading_pairs`; or the index `pairs` (P, 2) given).
    `work` may hold an earlier run's database (a growing photo set mapped again,
    `robot.mission.repose`): photos already there keep their features, pairs already
    matched are not matched again, and the last run's largest model is continued (COLMAP
    registers the new photos into it), so each run extracts, matches and maps only what is
    new. `grow_only`: when there is such a model, grow it and start no other (COLMAP's
    `multiple_models` off, for a caller that uses the largest model alone,
    `robot.mission.repose`): the photos that do not join it are not tried again as the
    seeds of new models, nor, relaxed, as those of more. `max_seconds`: COLMAP's mapping
    stops after this long and keeps the model it has (None: no limit).
    Returns every reconstruction, largest first (the circles' sectors of headings, or
    photos that share no features, make separate models; `map_from_models` places them)."""
    names = save_images(images, work)
    return sfm_in_workspace(names, K, headings, config, work, pairs, grow_only, max_seconds)


def save_images(images: list[np.ndarray], work: Path) -> list[str]:
    """The photos' file names in `work`/images (00000.png, ...), the files written for those
    not there yet (RGB (H, W, 3) uint8 in, PNG out)."""
    img_dir = work / "images"
    img_dir.mkdir(parents=True, exist_ok=True)
    names = [f"{i:05d}.png" for i in range(len(images))]
    for i, n in enumerate(names):
        if not (img_dir / n).exists():
            cv2.imwrite(str(img_dir / n), images[i][..., ::-1])
    return names


def _in_database(db: Path, names: list[str]) -> tuple[list[str], list[str], int | None]:
    """(the `names` whose features the database `db` does not hold yet, the `names` it holds
    no image of, the id of the camera it holds or None): all names, all names and None
    without a database. Read from the database, not from which files exist, so a run stopped
    between saving the photos and extracting their features extracts them next time. Every
    photo is the robot's one camera: a later extraction reuses that camera
    (`extract_features` with `CameraMode.SINGLE` adds a camera and rig per call, one per
    re-posing of a mission)."""
    import pycolmap

    if not db.exists():
        return list(names), list(names), None
    database = pycolmap.Database.open(db)
    try:
        images = {im.name: im.image_id for im in database.read_all_images()}
        done = {n for n, i in images.items() if database.exists_keypoints(i)}
        cameras = [c.camera_id for c in database.read_all_cameras()]
    finally:
        database.close()
    return [n for n in names if n not in done], [n for n in names if n not in images], min(cameras, default=None)


def sfm_in_workspace(names: list[str], K: np.ndarray, headings: np.ndarray, config: MapConfig, work: Path,
                     pairs: np.ndarray | None = None, grow_only: bool = False, max_seconds: float | None = None):
    """`run_sfm` of the photos `names` already saved in `work`/images (`save_images`)."""
    import pycolmap

    img_dir = work / "images"
    db = work / "database.db"
    new, absent, camera = _in_database(db, names)
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = "PINHOLE"
    reader.camera_params = ",".join(str(v) for v in (K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5))
    if camera is not None:
        reader.existing_camera_id = camera
    extract = pycolmap.FeatureExtractionOptions()
    extract.num_threads, extract.sift.max_num_features = config.threads, config.max_features
    extract.sift.first_octave = config.sift_first_octave
    if new:
        with colmap_errors_only():
            if absent:
                import_in_name_order(db, img_dir, pycolmap.CameraMode.SINGLE, absent, reader)
            pycolmap.extract_features(db, img_dir, new, camera_mode=pycolmap.CameraMode.SINGLE,
                                      reader_options=reader, extraction_options=extract,
                                      device=pycolmap.Device.cpu)
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = config.mapping_threads
    # seeded: unseeded, a pair's RANSAC judged it calibrated or planar by chance (72 of 1333
    # pairs between two runs), and the same photos gave a model of 37 or 44
    verify = pycolmap.TwoViewGeometryOptions()
    verify.ransac.random_seed = config.seed
    matched = work / "matched.txt"
    done = set(matched.read_text().splitlines()) if matched.exists() else set()
    if pairs is None:
        pairs = heading_pairs(np.asarray(headings), config.match_heading_rad)
    todo = [f"{names[i]} {names[j]}" for i, j in pairs]
    todo = [p for p in todo if p not in done]
    if todo:
        (work / "pairs.txt").write_text("".join(f"{p}\n" for p in todo))
        with colmap_errors_only():
            pairing = pycolmap.ImportedPairingOptions(match_list_path=work / "pairs.txt")
            pycolmap.match_image_pairs(db, matching_options=matching, device=pycolmap.Device.cpu,
                                       pairing_options=pairing, verification_options=verify)
        with matched.open("a") as f:
            f.write("".join(f"{p}\n" for p in todo))
    shutil.rmtree(work / "sparse", ignore_errors=True)
    opts = pycolmap.IncrementalPipelineOptions()
    opts.num_threads, opts.random_seed = config.mapping_threads, config.seed
    opts.mapper.num_threads, opts.mapper.random_seed = config.mapping_threads, config.seed
    opts.ba_refine_focal_length = opts.ba_refine_principal_point = opts.ba_refine_extra_params = False
    model = work / "model"  # the largest model of the last run, continued rather than rebuilt
    opts.multiple_models = not (grow_only and model.is_dir())  # photos in different rooms often form separate models
    opts.max_runtime_seconds = -1 if max_seconds is None else max(1, int(max_seconds))
    opts.ba_global_frames_ratio = opts.ba_global_points_ratio = 1.4  # fewer global BAs: ~100 photos
    opts.ba_global_max_num_iterations, opts.ba_local_max_num_iterations = 30, 15
    with colmap_errors_only():
        maps = pycolmap.incremental_mapping(db, img_dir, work / "sparse", opts,
                                            input_path=model if model.is_dir() else "")
    if not maps:
        raise MapError(f"SfM registered none of the {len(names)} photos (too little texture or overlap?)")
    recs = sorted(maps.values(), key=lambda r: -r.num_reg_images())
    written = work / "model.new"  # replaced whole: a run stopped while writing leaves the last model, or none
    shutil.rmtree(written, ignore_errors=True)
    written.mkdir()
    recs[0].write(written)
    shutil.rmtree(model, ignore_errors=True)
    written.rename(model)
    if recs[0].num_reg_images() < config.min_registered:
        raise MapError(f"SfM registered only {recs[0].num_reg_images()} of {len(names)} photos; "
                       f"need {config.min_registered}")
    return recs


def forget_model(work: Path) -> None:
    """The next `run_sfm` in the workspace `work` maps afresh instead of continuing its last
    model (the photos' features and matches are kept)."""
    shutil.rmtree(work / "model", ignore_errors=True)


def umeyama(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Similarity (s, R (d, d), t (d,)) minimising |dst - (s R src + t)|^2 for (N, d) point
    sets (Umeyama 1991)."""
    ms, md = src.mean(0), dst.mean(0)
    a, b = src - ms, dst - md
    U, S, Vt = np.linalg.svd(b.T @ a / len(src))
    D = np.diag([1.0] * (src.shape[1] - 1) + [np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / max((a ** 2).sum() / len(src), 1e-12))
    return s, R, md - s * R @ ms


def _level(centres: np.ndarray, ups: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(c0, level): a point at the camera centres' median height (their mean, moved along the
    up to the median height) and the rotation (rows: new axes) that puts the mean of the
    cameras' `ups` (N, 3) (each camera's known world up, in the SfM frame) on +z. The
    median height, not the mean: the cameras' height is the floor's reference (`floor_depth`)
    and the placed model's (`world_from_levelled`), and a photo SfM registered far off moves
    a mean (apartment 6: one first map had a whole model 12.3 m above the floor, its x, y right).
    The cameras' rotations fix the floor's normal to a tenth of a degree; the best-fit plane of
    their centres does not: a robot's circles of photos are only the mount offset (5 cm) wide,
    and 1 cm of SfM noise tilted that plane by 2 degrees (office, 48 photos), which smeared
    the floor's points over 10 cm of depth 3 m away."""
    n = np.asarray(ups, float).mean(0)
    n /= np.linalg.norm(n)
    c0 = centres.mean(0)
    c0 = c0 + np.median((centres - c0) @ n) * n
    x = np.cross([0, 1.0, 0], n) if abs(n[1]) < 0.9 else np.cross([1.0, 0, 0], n)
    x /= np.linalg.norm(x)
    return c0, np.stack([x, np.cross(n, x), n])


def floor_depth(heights: np.ndarray, bin_share: float = 0.025, min_points: int = 12,
                contrast: float = 2.0) -> tuple[float, int] | None:
    """(depth, support): how far below the cameras the floor lies, in the map's units, and
    how many points support it, from the heights (N,) of the map's points above the cameras'
    plane (negative below). The floor is the *bottom* of the map: the floor's own points and
    the feet of the walls and furniture end there, and below it lie only badly triangulated
    points (1 % of an office map's lay 0.75 m deep, twice the floor's depth, so no
    percentile marks the bottom; and an SfM floor can hold as few points per cm of depth as
    the walls, 2x not 3x, so it is not the "densest layer" either). Depths are binned in
    `bin_share` of their 90th percentile (a share: no unit; an SfM floor is a layer +-2 to
    5 % of its depth thick); a layer is 3 bins. The floor is the deepest layer that holds
    `min_points` points, at least the median layer (not a sparse tail), and `contrast`
    times the layer 3 bins deeper (the drop below the floor), moved to the fullest layer
    within 3 bins, then refined to the median depth of the points within 1.5 bins of it.
    None (no floor found) when no layer qualifies."""
    depth = -np.asarray(heights, float)
    depth = depth[np.isfinite(depth) & (depth > 0)]
    if len(depth) < min_points:
        return None
    width = bin_share * float(np.percentile(depth, 90))
    n_bins = int(np.ceil(2.0 / bin_share))
    counts, edges = np.histogram(depth, bins=n_bins, range=(0.0, n_bins * width))
    layer = np.convolve(counts, np.ones(3, int), mode="same")  # points within 1.5 bins of each bin's centre
    below = np.r_[layer[3:], np.zeros(3, int)]
    edge = (layer >= min_points) & (layer >= np.median(layer[layer > 0])) & (layer >= contrast * below)
    if not edge.any():
        return None
    i = np.flatnonzero(edge)[-1]
    lo, hi = max(i - 3, 0), i + 4
    peak = 0.5 * (edges[lo:hi] + edges[lo + 1:hi + 1])[np.argmax(layer[lo:hi])]
    background = np.median(layer[layer > 0]) / (3 * width)  # the walls' points per unit depth
    for _ in range(10):  # the layer's median with the walls' even share taken out, re-centred
        near = np.abs(depth - peak) <= 1.5 * width
        peak = _median_over_background(np.sort(depth[near]), peak - 1.5 * width, peak + 1.5 * width, background)
    return peak, int(near.sum())


def _median_over_background(d: np.ndarray, a: float, b: float, density: float) -> float:
    """The depth m in [a, b] that splits the sorted depths `d` in the window in two equal
    counts once an even background of `density` points per unit depth is taken out of
    each side (the walls' points reach down to the floor, so they would pull a plain
    median of the floor's layer upwards)."""
    m = np.linspace(a, b, 201)
    left = np.searchsorted(d, m) - density * (m - a)
    right = (len(d) - np.searchsorted(d, m)) - density * (b - m)
    return float(m[np.argmin(np.abs(left - right))])


def transform_camera(cam: Camera, world_from_sfm: np.ndarray) -> Camera:
    """The camera re-expressed in the floor frame (a similarity: the scale goes into t)."""
    s = np.cbrt(np.linalg.det(world_from_sfm[:3, :3]))
    R = world_from_sfm[:3, :3] / s
    centre = world_from_sfm[:3, :3] @ cam.center + world_from_sfm[:3, 3]
    world_from_cam = rigid(R @ cam.world_from_cam[:3, :3], centre)
    return cam.with_pose(np.linalg.inv(world_from_cam))


def initial_map(images: list[np.ndarray], K: np.ndarray, estimates: np.ndarray, compass_rad: np.ndarray,
                cam_from_robot: np.ndarray, config: MapConfig = MapConfig(),
                ranges_m: np.ndarray | None = None, work: Path | None = None) -> RobotMap:
    """The map of the random-exploration photos `images` with shared intrinsics `K`;
    `estimates` (N, 3) their dead-reckoning SE(2) poses (scale and heading of the frame),
    `compass_rad` (N,) their compass readings (which photos to match), `ranges_m` (N,) their
    ultrasonic readings (a scale, `sonar_scale`; None: not used). SfM's models (one per
    sector of headings, `robot.mission.circles`) are placed in metres together by the
    robot's circles of photos (`place_models`), then the photos of those circles that no
    model posed are turned into place from a posed neighbour (`complete_circles`).
    `work`: an SfM workspace the caller keeps (`run_sfm`), mapped afresh (`forget_model`)
    but with the features and matches of the photos an earlier call there had (the same
    photos at the same indices: a photo is known by its index's file name): the mission
    builds its first map again, one circle of photos more each time, while the floor cannot
    check its scale (`mission._first_map`), and the same photos give the same map (test).
    None: a temporary one."""
    if len(images) < config.min_registered:
        raise MapError(f"{len(images)} photos: SfM needs at least {config.min_registered}")
    kept = work is not None
    work = Path(work) if kept else Path(tempfile.mkdtemp(prefix="ibrnav_sfm_"))
    try:
        forget_model(work)
        recs = run_sfm(images, K, compass_rad, config, work)
        return map_from_models(recs, work / "database.db", K, images[0].shape[:2], estimates, compass_rad,
                               cam_from_robot, config, ranges_m, images)
    finally:
        if not kept:
            shutil.rmtree(work, ignore_errors=True)


def map_from_models(recs: list, database: Path, K: np.ndarray, size_hw: tuple[int, int], estimates: np.ndarray,
                    compass_rad: np.ndarray, cam_from_robot: np.ndarray, config: MapConfig = MapConfig(),
                    ranges_m: np.ndarray | None = None, images: list[np.ndarray] | None = None) -> RobotMap:
    """`initial_map` from SfM's models `recs` (pycolmap reconstructions, largest first) and
    its `database` (the matches): placed together in metres (`_placed`); then its scale
    corrected by the floor seen in the `images` (None: not; `_floor_scaled`), or with
    `config.floor_spans` the distances between its stops measured (`_floor_spans`) and the
    map placed again with them; meshed. `size_hw` (height, width) of the photos (px)."""
    rig = _Rig(np.asarray(estimates, float), np.asarray(compass_rad, float), cam_from_robot, config, ranges_m)
    models = [m for m in (_levelled(rec, rig) for rec in recs) if m is not None]
    if not models:
        raise MapError(f"no SfM model holds 3 photos or more ({[r.num_reg_images() for r in recs]})")
    matches = _Matches(database)
    placed = _placed(models, rig, K, size_hw, matches, config)
    floor = config.floor_scale if images is not None else None
    scaled = None
    if floor is not None and config.floor_spans:
        spans = _floor_spans(images, placed.cameras, rig, floor)
        scaled = bool(spans)
        if spans:
            placed = _placed(models, rig, K, size_hw, matches, config, spans)
    cameras = placed.cameras
    pts, cols, seen_from = (np.vstack([q[j] for q in placed.parts]) for j in range(3))
    if floor is not None and not config.floor_spans:
        cameras, pts, seen_from, scaled = _floor_scaled(images, cameras, pts, seen_from, rig, floor)
    log.info(f"initial map: {len(placed.placement.models)} of {len(recs)} SfM models placed in metres "
             f"({[r.num_reg_images() for r in recs]} photos each; {placed.sfm_posed} photos), "
             f"{placed.added} more photos turned into place in their circles")
    rmap = _mesh_map(cameras, pts, cols, seen_from, config, registered=len(cameras))
    rmap.floor_scaled = scaled
    return rmap


@dataclass
class _Placed:
    """`_placed`'s map: the `placement` of SfM's models, the photos' `cameras`
    {photo: Camera}, the map's `parts` [(points, colours, seen_from)], how many photos the
    models posed (`sfm_posed`) and how many `complete_circles` `added`."""

    placement: Placement
    cameras: dict[int, Camera]
    parts: list
    sfm_posed: int
    added: int


def _placed(models: list, rig: "_Rig", K: np.ndarray, size_hw: tuple[int, int], matches: "_Matches",
            config: MapConfig, spans: dict | None = None) -> _Placed:
    """SfM's `models` (`_levelled`) placed together in metres by the robot's circles
    (`place_models`, with the floor's `spans` between stops when given), adjusted on the
    rig (`_on_rig`; not when `config.rig` is None) and the circles completed
    (`complete_circles`)."""
    h, w = size_hw
    placement = place_models([m[0] for m in models], rig.circle, rig.heading, rig.estimates[:, :2],
                             rig.cam_xy, rig.driven_m, rig.mount_xy, rig.mount_yaw, config.circles, spans)
    cameras, placed = {}, []
    for k, (s, a, t) in placement.models.items():
        rec, world_from_sfm = models[k][1], world_from_levelled(models[k][2], s, a, t, rig.height)
        cams = {int(i): Camera(K, w, h, transform_camera(models[k][3][int(i)], world_from_sfm).cam_from_world,
                               f"photo_{int(i):05d}") for i in placement.photos[k]}
        cams = at_mount_height(cams, rig.height, config.max_camera_height_err_m)
        placed.append((rec, world_from_sfm, cams))
        for i, c in cams.items():
            cameras.setdefault(i, c)
    centres = placement.centres
    if config.rig is not None:
        cameras, centres, parts = _on_rig(placed, cameras, centres, rig, matches, K, (w, h), config.rig, spans)
    else:
        parts = [_sfm_points(rec, world_from_sfm, cams) for rec, world_from_sfm, cams in placed]
    sfm_posed = len(cameras)
    added = complete_circles({i: c.world_from_cam for i, c in cameras.items()}, rig.circle, centres,
                             rig.heading, matches, K, rig.mount_xy, rig.mount_yaw, rig.height,
                             config.circles)
    cameras.update({i: Camera(K, w, h, np.linalg.inv(T), f"photo_{i:05d}") for i, T in added.items()})
    return _Placed(placement, cameras, parts, sfm_posed, len(added))


def _floor_spans(images: list[np.ndarray], cameras: dict[int, Camera], rig: "_Rig",
                 config: FloorScaleConfig) -> dict[tuple[int, int], tuple[float, float]]:
    """The floor's measures of the distances between the robot's stops in the map of
    `cameras` (`stop_spans` of the pairs `floor_scale` fits): {(a, b): (m, relative
    sigma)}; empty when no two stops saw a common floor or their pairs disagree."""
    _, fits = floor_scale({i: images[i] for i in cameras}, cameras, config)
    robot_xy = {i: robot_pose(c.world_from_cam, rig.cam_from_robot)[:2] for i, c in cameras.items()}
    spans = stop_spans(fits, cameras, {i: int(rig.circle[i]) for i in cameras}, robot_xy, config)
    said = ", ".join(f"{a}-{b}: {length:.3f} m, {_stop_distance(a, b, robot_xy, rig.circle):.3f} in the map"
                     for (a, b), (length, _) in sorted(spans.items()))
    log.info(f"initial map: the floor measured {len(spans)} spans between stops from {len(fits)} pairs of "
             f"photos{' (' + said + ')' if spans else ''}")
    return spans


def _floor_scaled(images: list[np.ndarray], cameras: dict[int, Camera], pts: np.ndarray, seen_from: np.ndarray,
                  rig: "_Rig", config: FloorScaleConfig) -> tuple[dict[int, Camera], np.ndarray, np.ndarray, bool]:
    """The map (cameras, points, the centres that saw them) scaled about the known start (at
    the camera's height) by the floor's factor (`floor_scale`), and True; as it was without
    one, and False."""
    k, fits = floor_scale({i: images[i] for i in cameras}, cameras, config)
    q = np.exp(np.percentile([f.log_k for f in fits], [25, 75])) if fits else np.ones(2)
    quartiles = f"quartiles {q[0]:.4f}-{q[1]:.4f}"
    if not np.isfinite(k):
        why = (f"only {len(fits)} pairs of photos count" if len(fits) < config.min_pairs else
               f"its {len(fits)} pairs of photos disagree, {quartiles}")
        log.info(f"initial map: no floor scale ({why})")
        return cameras, pts, seen_from, False
    log.info(f"initial map: the floor scales it by {k:.4f} ({len(fits)} pairs of photos, {quartiles})")
    origin = np.r_[rig.estimates[0, :2], rig.height]
    cams, P = rescaled(cameras, np.vstack([pts, seen_from]), k, origin)
    return cams, P[:len(pts)], P[len(pts):], True


def _stop_distance(a: int, b: int, robot_xy: dict[int, np.ndarray], circle: np.ndarray) -> float:
    """The distance (m) between the mean robot positions of the photos of stops a and b."""
    mean = [np.mean([p for i, p in robot_xy.items() if circle[i] == k], axis=0) for k in (a, b)]
    return float(np.linalg.norm(mean[1] - mean[0]))


def _on_rig(placed: list, cameras: dict[int, Camera], centres: dict[int, np.ndarray], rig: "_Rig",
            matches: "_Matches", K: np.ndarray, size_wh: tuple[int, int], config: RigAdjustmentConfig,
            spans: dict | None = None):
    """The placed models' photos, points and stops adjusted on the rig (`adjust_on_rig`),
    with the photos of their circles that no model posed joining by their `matches`:
    `placed` [(rec, world_from_sfm, {photo: Camera})], `cameras` {photo: Camera} (first
    model's pose of each photo), `centres` {circle: robot position}, `spans` the floor's
    distances between them (`stop_spans`). Returns the cameras (those of circles without a
    centre as they were), the centres (adjusted; those of circles without photos in the
    adjustment turned with the placement onto the compass) and the map's [(points,
    colours, seen_from)]."""
    obs = rig_observations(placed, cameras, centres, rig, matches)
    if spans:  # the stops move only where the floor holds the lengths between them
        obs = replace(obs, stop=rig.circle[obs.photos], spans=spans)
    if len(obs.photo) == 0:
        return cameras, centres, [_sfm_points(rec, T, cams) for rec, T, cams in placed]
    fit = adjust_on_rig(obs, K, rig.cam_from_robot, config)
    from robot.protocol import se2_matrix

    xy = fit.xy
    out = dict(cameras)
    for n in np.flatnonzero(fit.posed):
        i = int(obs.photos[n])
        robot_from_world = np.linalg.inv(se2_matrix(np.r_[xy[n], fit.theta[n]]))
        out[i] = Camera(K, *size_wh, rig.cam_from_robot @ robot_from_world, f"photo_{i:05d}")
    first = np.full(len(fit.points), -1)
    first[obs.point[::-1]] = obs.photo[::-1]  # the first photo that saw each point (an SfM-posed one)
    seen = np.array([out[int(obs.photos[f])].center for f in first[fit.kept]]).reshape(-1, 3)
    log.info(f"initial map adjusted on the robot's rig: {int((~obs.joining).sum())} photos, "
             f"{int(fit.posed[obs.joining].sum())} of {int(obs.joining.sum())} more joined by their matches, "
             f"{int(fit.kept.sum())} of {len(fit.points)} points kept, median reprojection {fit.before_px:.2f} -> "
             f"{fit.after_px:.2f} px, turned {np.degrees(fit.alpha):+.2f} deg onto the compass")
    moved = {int(rig.circle[i]): p for i, p in zip(obs.photos, xy)}
    return out, {c: moved.get(c, turned(p[None], fit.alpha, obs.pivot)[0]) for c, p in centres.items()}, [
        (fit.points[fit.kept], obs.colors[fit.kept], seen)]


def rig_observations(placed: list, cameras: dict[int, Camera], centres: dict[int, np.ndarray],
                     rig: "_Rig", matches: "_Matches") -> RigObservations:
    """The observations of the placed models' points (world metres) in the `cameras` of the
    photos of circles with a centre (`_on_rig`; a point seen by fewer than two of them is
    left out), and in the other photos of those circles, through their `matches` with the
    posed photos' observations (at most one per point and photo). A circle none of whose
    photos a model posed is left out: its centre is the dead reckoning's alone."""
    held = {int(rig.circle[i]) for i in cameras} & set(centres)  # a circle no model holds: dead reckoning only
    circled = [i for i in range(len(rig.circle)) if int(rig.circle[i]) in held]
    posed = [i for i in circled if i in cameras]
    photos = np.array(posed + [i for i in circled if i not in cameras], int)
    slot = {int(i): n for n, i in enumerate(photos)}
    obs, keypoint_point, pts, cols = _model_observations(placed, slot)
    joining = photos[len(posed):]
    _joining_observations(obs, joining, posed, slot, keypoint_point, matches)
    ph, pt = np.array(list(obs), int).reshape(-1, 2).T
    uv = np.array(list(obs.values()), float).reshape(-1, 2)
    heading = np.r_[[robot_pose(cameras[i].world_from_cam, rig.cam_from_robot)[2] for i in posed],
                    rig.compass[joining]]
    xy = np.array([centres[int(rig.circle[i])] for i in photos]).reshape(-1, 2)
    return RigObservations(ph, pt, uv, photos, xy, heading, rig.compass[photos], np.array(pts).reshape(-1, 3),
                           np.array(cols, np.uint8).reshape(-1, 3), np.asarray(centres[min(centres)], float),
                           np.isin(photos, joining))


def _model_observations(placed: list, slot: dict[int, int]):
    """The placed models' points seen by two photos of `slot` {photo: slot} or more: their
    observations {(photo slot, point): pixel}, {(photo, keypoint index): point}, the points
    (world metres) and their colours."""
    obs: dict[tuple[int, int], np.ndarray] = {}
    keypoint_point: dict[tuple[int, int], int] = {}
    pts, cols = [], []
    for rec, world_from_sfm, cams in placed:
        names = {iid: int(Path(im.name).stem) for iid, im in rec.images.items()}
        for p in rec.points3D.values():
            els = [(names[e.image_id], e.image_id, e.point2D_idx) for e in p.track.elements
                   if names[e.image_id] in cams and names[e.image_id] in slot]
            if len({i for i, _, _ in els}) < 2:
                continue
            for i, image_id, k in els:
                xy = rec.images[image_id].points2D[k].xy
                obs.setdefault((slot[i], len(pts)), xy - 0.5)  # COLMAP's pixel origin is a corner
                keypoint_point.setdefault((i, k), len(pts))
            pts.append(world_from_sfm[:3, :3] @ p.xyz + world_from_sfm[:3, 3])
            cols.append(p.color)
    return obs, keypoint_point, pts, cols


def _joining_observations(obs: dict, joining: np.ndarray, posed: list[int], slot: dict[int, int],
                          keypoint_point: dict[tuple[int, int], int], matches: "_Matches") -> None:
    """Add to `obs` {(photo slot, point): pixel} the observations of each `joining` photo: its
    keypoints that geometric verification matched with a `posed` photo's keypoint of a point
    (`keypoint_point` {(posed photo, keypoint index): point})."""
    for i in joining:
        for j in posed:
            for a, b in matches.inliers(int(i), j):
                if (j, b) in keypoint_point:
                    obs.setdefault((slot[int(i)], keypoint_point[(j, b)]), matches.keypoints(int(i))[a])


def robot_pose(world_from_cam: np.ndarray, cam_from_robot: np.ndarray) -> np.ndarray:
    """SE(2) pose (x, y, theta) of the robot whose camera stands at `world_from_cam` (4, 4)
    (the mount `cam_from_robot` undone)."""
    world_from_robot = world_from_cam @ cam_from_robot
    return np.array([world_from_robot[0, 3], world_from_robot[1, 3],
                     np.arctan2(world_from_robot[1, 0], world_from_robot[0, 0])])


def at_mount_height(cameras: dict[int, Camera], height_m: float, tol_m: float) -> dict[int, Camera]:
    """The cameras {photo: Camera, floor frame} whose centres lie within `tol_m` of the
    mount's `height_m` above the floor (m): where a robot on a flat floor can have taken them."""
    return {i: c for i, c in cameras.items() if abs(c.center[2] - height_m) < tol_m}


class _Rig:
    """What the robot knows of each photo of the random stage: its `circle`, the compass
    reading `compass` (the robot's heading, rad) and the camera's heading by it, `heading`;
    the dead-reckoning `estimates` and camera position `cam_xy`, `driven_m` before it, the
    ultrasonic's `ranges_m` (None: not read); the camera's mount (`mount_xy` m, `mount_yaw`
    rad) and `height` (m)."""

    def __init__(self, estimates: np.ndarray, compass_rad: np.ndarray, cam_from_robot: np.ndarray,
                 config: MapConfig, ranges_m: np.ndarray | None = None):
        robot_from_cam = np.linalg.inv(cam_from_robot)
        self.estimates, self.cam_from_robot, self.config = estimates, cam_from_robot, config
        self.ranges_m = None if ranges_m is None else np.asarray(ranges_m, float)
        self.circle = circle_ids(estimates, config.circles)
        self.mount_xy = robot_from_cam[:2, 3]
        self.mount_yaw = float(np.arctan2(robot_from_cam[1, 2], robot_from_cam[0, 2]))
        self.height = float(robot_from_cam[2, 3])
        self.compass = np.asarray(compass_rad, float)
        self.heading = np.array([_camera_yaw(np.r_[e[:2], c], cam_from_robot) for e, c in zip(estimates, compass_rad)])
        self.cam_xy = np.array([_camera_xy(e, cam_from_robot) for e in estimates]).reshape(-1, 2)
        self.driven_m = np.r_[0.0, np.cumsum(np.hypot(*np.diff(estimates[:, :2], axis=0).T))]


def posed_images(rec) -> dict:
    """{photo index: pycolmap Image} of the photos an SfM model `rec` posed (`run_sfm` names
    each photo by its index)."""
    return {int(Path(im.name).stem): im for im in rec.images.values() if im.has_pose}


def _levelled(rec, rig: _Rig):
    """(LevelledModel, rec, (c0, level), {index: Camera in the SfM frame}) of one SfM model
    (`levelled_model`); None with fewer than 3 photos. Its floor and its ultrasonic scale
    come from the points photos of two circles saw (`points_across_circles`): a point one
    circle alone saw rests on the mount's few centimetres of baseline, and far wall points
    whose depth that overestimates sink below the floor. On apartment 5 (the start room's
    walls a repeated polka-dot wallpaper) one SfM run of its first 108 photos had 179 such
    points 0.2-0.8 m under a floor of 78. Five SfM runs of those photos, the model's floor
    scale from all points against from those two circles saw (the placed map's scale error):
    -22 against -2 % (30 %; the other map not measured), -12 against +3 % (7.0 against
    0.4 %), -63 against +1 % (9.7 against 3.7 %), +1.5 against +2.4 % (0.2 against 1.0 %),
    and a wrong model either way, left out by the placement (0.2 % both). On the first maps of
    apartments 0-4 and 6-19 and offices 0-4, one SfM run each, no map's scale moved by more
    than 0.1 % (apartment 2's posed 86 photos instead of 97)."""
    posed = posed_images(rec)
    cams = {i: Camera.from_pycolmap(im, rec.cameras[im.camera_id]) for i, im in posed.items()}
    idx = np.array(sorted(cams), int)
    if len(idx) < 3:
        return None
    up_in_cam = rig.cam_from_robot[:3, :3] @ np.array([0.0, 0.0, 1.0])  # the floor's normal, seen by the camera
    across = points_across_circles(rec, rig.circle)  # depth from the drives, not the mount's few cm
    points = np.array([q.xyz for pid, q in rec.points3D.items() if pid in across]).reshape(-1, 3)
    model, frame = levelled_model(idx, np.array([cams[i].center for i in idx]),
                                  np.array([cams[i].world_from_cam[:3, :3] @ up_in_cam for i in idx]),
                                  np.array([cams[i].world_from_cam[:3, 2] for i in idx]), points, rig.height)
    found = _model_sonar_scale(rec, posed, rig, cams, frame, across) if rig.ranges_m is not None else None
    if found is not None:
        model = replace(model, sonar_scale=found[0], sonar_sigma=found[1])
    return model, rec, frame, cams


def _model_sonar_scale(rec, posed: dict, rig: _Rig, cams: dict[int, Camera], frame,
                       across: set[int]) -> tuple[float, float] | None:
    """`sonar_scale` of one SfM model `rec` (its `posed_images` and their `cams` in the SfM
    frame, levelled by `frame` = (c0, level)): each photo's centre, axis and the points it
    observed of `across`, those photos of another circle observed too (`points_across_circles`)."""
    c0, level = frame
    seen = {i: np.array([rec.points3D[p.point3D_id].xyz for p in im.points2D
                         if p.has_point3D() and p.point3D_id in across]).reshape(-1, 3) for i, im in posed.items()}
    mount_forward_m = float(rig.mount_xy @ [np.cos(rig.mount_yaw), np.sin(rig.mount_yaw)])
    return sonar_scale({i: (c.center - c0) @ level.T for i, c in cams.items()},
                       {i: c.world_from_cam[:3, 2] @ level.T for i, c in cams.items()},
                       {i: (seen[i] - c0) @ level.T for i in cams}, rig.ranges_m, mount_forward_m, rig.config.sonar,
                       {i: int(rig.circle[i]) for i in cams})


def points_across_circles(rec, circle: np.ndarray) -> set[int]:
    """The point ids of SfM model `rec` observed from two circles or more (`circle` (N,) of
    each photo). A point seen from one circle only is triangulated over the camera mount's
    few centimetres of baseline, and its depth rests on SfM's estimate of that baseline: in
    the apartments the faces of furniture nearest the robot lay 10-15 % too far (apartment 8:
    a face at 0.97 m, its points at 1.11 m), while points seen from two circles rest on the
    drives' metres."""
    circle_of = {im_id: int(circle[int(Path(im.name).stem)]) for im_id, im in rec.images.items()}
    return {pid for pid, p in rec.points3D.items() if len({circle_of[e.image_id] for e in p.track.elements}) >= 2}


def sonar_scale(centres: dict[int, np.ndarray], forwards: dict[int, np.ndarray], seen: dict[int, np.ndarray],
                ranges_m: np.ndarray, mount_forward_m: float, sonar: SonarConfig, circles: dict[int, int] | None = None,
                nearest_share: float = 0.1, agree: float = 0.05) -> tuple[float, float] | None:
    """(metres per model unit, its relative standard error) of a levelled model from the
    robot's ultrasonic: a reading r < `sonar.max_range_m` - `max_tol_m` is the nearest
    surface within `sonar.half_cone_rad` of the robot's heading, from the robot's centre,
    `mount_forward_m` behind the camera. Per photo i, the points it saw (`seen[i]` (M, 3)),
    ahead of its camera (`centres[i]` (3,), optical axis `forwards[i]` (3,)) within the cone
    (horizontal angle), give the nearest surface in model units as the `nearest_share`
    quantile of their forward distances (a few badly triangulated points nearer than the
    surface do not make it); its metres over that are the photo's scale. Tuned on offices
    0-4 (the 10 % quantile: 5 % read 0.3-1.8 % high, 25 % 4-5 % low).
    A photo whose nearest surface holds no points (a plain face of furniture) reads the
    surface behind it: too low a scale, and such photos are many in a furnished room. So the
    model's scale is the largest group of photo scales that agree (`_agreeing`), not their
    median; `circles` {photo: its circle} (None: each photo its own) tells how independent
    the group is. Against the truth over the models of every saved SfM run (fit within 5 cm):
    offices 0-4 and the demo 0.8 % off at the median, 2.9 % at worst, errors within 1.8
    sigmas; apartments 0-9 1.1 % at the median, 8.7 % at the 90th percentile (the photos'
    median was 3.3 % and 47 %). None with fewer than 5 photos in range or fewer than 3 that
    agree."""
    scales, circle = [], []
    for i, c in centres.items():
        r = ranges_m[i]
        if not r < sonar.max_range_m - sonar.max_tol_m or len(seen[i]) == 0:
            continue
        f = np.asarray(forwards[i], float)[:2]
        f /= np.linalg.norm(f)
        v = seen[i][:, :2] - c[:2]
        ahead, side = v @ f, v @ [-f[1], f[0]]
        cone = (ahead > 0) & (np.abs(np.arctan2(side, ahead)) < sonar.half_cone_rad)
        if cone.sum() >= 3 and r > mount_forward_m:
            scales.append((r - mount_forward_m) / np.quantile(ahead[cone], nearest_share))
            circle.append(i if circles is None else circles[i])
    if len(scales) < 5:
        return None
    return _agreeing(np.log(scales), np.array(circle), agree)


def _agreeing(log_scales: np.ndarray, circle: np.ndarray, agree: float,
              min_photos: int = 3) -> tuple[float, float] | None:
    """(scale, relative standard error) of the largest group of photos whose `log_scales`
    (n,) lie within `agree` of its median: the group's median, and its spread (at least
    agree / 2) over the square root of the circles (`circle` (n,)) it spans: the photos of
    one circle see the same walls, so their errors are not independent. `agree` is a share
    (no unit): the ultrasonic's 1 cm over its 0.3-2.5 m and the nearest points' depth noise
    spread the photos of one surface by 2 % (the groups' median spread, offices and
    apartments alike). None with fewer than `min_photos` in the group."""
    counts = [(np.abs(log_scales - x) <= agree).sum() for x in log_scales]
    centre = np.median(log_scales[np.abs(log_scales - log_scales[int(np.argmax(counts))]) <= agree])
    group = np.abs(log_scales - centre) <= agree
    if group.sum() < min_photos:
        return None
    spread = max(float(np.std(log_scales[group])), agree / 2)
    return float(np.exp(np.median(log_scales[group]))), float(spread / np.sqrt(len(np.unique(circle[group]))))


def levelled_model(idx: np.ndarray, centres: np.ndarray, ups: np.ndarray, forwards: np.ndarray,
                   points: np.ndarray, camera_height_m: float) -> tuple[LevelledModel, tuple[np.ndarray, np.ndarray]]:
    """One SfM model levelled (`_level`: the mean of the cameras' `ups` (N, 3), each camera's
    known world up in the SfM frame, becomes +z) with its metric scale from the floor: the
    floor plane in the model's `points` (M, 3) (`floor_depth`) lies the camera's known
    height `camera_height_m` below the cameras, so metres per model unit =
    camera_height_m / depth (None where no floor is found). `idx` (N,) the photos, `centres`
    (N, 3) and `forwards` (N, 3) their camera centres and optical axes in the SfM frame.
    Returns the model and its frame (c0, level) for `world_from_levelled`."""
    c0, level = _level(centres, ups)
    p = (centres - c0) @ level.T
    f = np.asarray(forwards, float) @ level.T
    floor = floor_depth(((np.asarray(points, float) - c0) @ level.T)[:, 2]) if len(points) else None
    model = LevelledModel(np.asarray(idx), p[:, :2], np.arctan2(f[:, 1], f[:, 0]),
                          None if floor is None else camera_height_m / floor[0], 0 if floor is None else floor[1])
    return model, (c0, level)


def world_from_levelled(frame: tuple[np.ndarray, np.ndarray], s: float, a: float, t: np.ndarray,
                    height: float) -> np.ndarray:
    """The 4x4 similarity of a levelled model (`frame` = (c0, level)) placed with scale `s`,
    heading `a` (rad) and shift `t` (2,) m, its cameras' median at the camera `height`."""
    c0, level = frame
    S = np.eye(4)
    S[:2, :2] = s * rot2d(a)
    S[:2, 3], S[2, 2], S[2, 3] = t, s, height
    return S @ rigid(level, -level @ c0)


class _Matches:
    """`matches(i, j)`: the (M, 2) pixel pairs (ibrnav's pixel centres) of photos i and j that
    COLMAP's geometric verification kept, from its database (empty when never matched)."""

    def __init__(self, db_path: Path):
        import pycolmap

        self.db = pycolmap.Database.open(db_path)
        self.ids = {int(Path(im.name).stem): im.image_id for im in self.db.read_all_images()}
        self.kp: dict[int, np.ndarray] = {}

    def keypoints(self, i: int) -> np.ndarray:
        if i not in self.kp:
            self.kp[i] = self.db.read_keypoints(self.ids[i])[:, :2] - 0.5
        return self.kp[i]

    def inliers(self, i: int, j: int) -> np.ndarray:
        """(M, 2) keypoint indices of photos i and j that geometric verification kept."""
        a, b = self.ids[i], self.ids[j]
        if not self.db.exists_two_view_geometry(a, b):
            return np.zeros((0, 2), int)
        return np.asarray(self.db.read_two_view_geometry(a, b).inlier_matches, int).reshape(-1, 2)

    def __call__(self, i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
        m = self.inliers(i, j)
        return self.keypoints(i)[m[:, 0]], self.keypoints(j)[m[:, 1]]


def _camera_yaw(pose: np.ndarray, cam_from_robot: np.ndarray) -> float:
    """World yaw (rad) of the optical axis of the camera on a robot at SE(2) `pose`."""
    from robot.protocol import se2_matrix

    f = (se2_matrix(pose) @ np.linalg.inv(cam_from_robot))[:3, 2]
    return float(np.arctan2(f[1], f[0]))


def _camera_xy(pose: np.ndarray, cam_from_robot: np.ndarray) -> np.ndarray:
    from robot.protocol import se2_matrix

    return (se2_matrix(pose) @ np.linalg.inv(cam_from_robot))[:2, 3]


def _sfm_points(rec, world_from_sfm: np.ndarray, cameras: dict[int, Camera]):
    """Floor-frame points, colours and the centre of a camera that saw each; only the points
    that one of `cameras` saw (a photo left out of the map leaves its own points out)."""
    pts, cols, seen = [], [], []
    for p in rec.points3D.values():
        saw = (int(Path(rec.images[e.image_id].name).stem) for e in p.track.elements)
        first = next((i for i in saw if i in cameras), None)
        if first is None:
            continue
        pts.append(p.xyz)
        cols.append(p.color)
        seen.append(cameras[first].center)
    P = np.asarray(pts).reshape(-1, 3) @ world_from_sfm[:3, :3].T + world_from_sfm[:3, 3]
    return P, np.asarray(cols, np.uint8).reshape(-1, 3), np.asarray(seen).reshape(-1, 3)


def _mesh_map(cameras: dict[int, Camera], pts: np.ndarray, cols: np.ndarray, seen_from: np.ndarray,
              config: MapConfig, registered: int) -> RobotMap:
    """Filter the points, estimate normals towards their cameras, Poisson-mesh them."""
    near = np.linalg.norm(pts - seen_from, axis=1) < config.max_point_range_m
    pts, cols, seen_from = pts[near], cols[near], seen_from[near]
    keep = remove_outliers(pts)
    pts, cols, seen_from = pts[keep], cols[keep], seen_from[keep]
    if len(pts) < 50:
        raise MapError(f"the photos gave only {len(pts)} map points; need at least 50")
    normals = estimate_normals(pts, seen_from)
    mesh = poisson_mesh(pts, normals, cols, config.poisson)
    return RobotMap(cameras, pts, cols, normals, mesh, registered)


def capture_model(rmap: RobotMap, config: MapConfig = MapConfig()) -> RobotMap:
    """The capture's model for new views: `rmap` with its points meshed at
    `config.model_poisson`, their repeats merged first (`merge_repeats`, one point per
    quarter of the octree's finest cell, a length of the map's own extent). The map's own
    mesh is the coarse proxy the next-best-view heuristic needs (`MapConfig.poisson`);
    rendered, it left most of a new view empty. The map as it is when the finer mesh fails
    (a warning)."""
    cfg = config.model_poisson
    extent = float(np.ptp(rmap.points, axis=0).max()) if len(rmap.points) else 0.0
    points = (rmap.points, rmap.normals, rmap.colors) if extent == 0.0 else \
        merge_repeats(rmap.points, rmap.normals, rmap.colors, extent / 2 ** (cfg.depth + 2))
    try:
        mesh = poisson_mesh(*points, cfg)
    except MeshingError as e:
        log.warning(f"the capture's model keeps the map's coarse mesh: {e}")
        return rmap
    return replace(rmap, mesh=mesh)


@dataclass
class Tracks:
    """Triangulated SIFT tracks: points (N, 3) metres, colors (N, 3) uint8, seen_from (N, 3)
    the centre of a camera that saw each point, descriptors (2N, 128) float32 of both features
    of each point with owner (2N,) the point index (what `FeatureMap` localises against)."""

    points: np.ndarray
    colors: np.ndarray
    seen_from: np.ndarray
    descriptors: np.ndarray
    owner: np.ndarray

    @classmethod
    def empty(cls) -> "Tracks":
        return cls(np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros((0, 3)), np.zeros((0, 128), np.float32),
                   np.zeros(0, int))

    def __add__(self, other: "Tracks") -> "Tracks":
        return Tracks(np.vstack([self.points, other.points]), np.vstack([self.colors, other.colors]),
                      np.vstack([self.seen_from, other.seen_from]),
                      np.vstack([self.descriptors, other.descriptors]),
                      np.r_[self.owner, other.owner + len(self.points)])


def stereo_tracks(cameras: dict[int, Camera], features, cfg: TriangulationConfig,
                  only: set[int] | None = None, matches=None) -> Tracks:
    """Tracks of the `stereo_pairs` of `cameras` {index: Camera} (only the pairs with a photo
    in `only`, when given), the poses fixed; `features(index)` gives a photo's features,
    `matches(a, b)` (optional, `robot.mission.bundle.PairMatches`) two photos' matches."""
    order = np.array(sorted(cameras))
    pairs = stereo_pairs([cameras[i] for i in order], cfg.neighbours)
    ids = order[pairs] if len(pairs) else np.zeros((0, 2), int)
    if only is not None:
        ids = ids[np.isin(ids, list(only)).any(axis=1)]
    used = sorted(set(ids.ravel().tolist()))
    if not used:
        return Tracks.empty()
    local = {i: k for k, i in enumerate(used)}
    cams = [cameras[i] for i in used]
    P, C, D, O, first = pair_tracks(cams, [features(i) for i in used],
                                    np.array([[local[a], local[b]] for a, b in ids]), cfg,
                                    None if matches is None else (lambda a, b: matches(used[a], used[b])))
    return Tracks(P, C, np.array([cams[f].center for f in first]).reshape(-1, 3), D, O)


def extend_map(old: RobotMap, new_cameras: dict[int, Camera], tracks: Tracks,
               config: MapConfig = MapConfig()) -> RobotMap:
    """`old` with the photos at their localised `new_cameras` {index: Camera} and the points
    of their `tracks` (`stereo_tracks` with the poses fixed) added; the mesh is rebuilt."""
    cameras = {**old.cameras, **new_cameras}
    if len(tracks.points) == 0:
        return RobotMap(cameras, old.points, old.colors, old.normals, old.mesh, old.registered)
    return _mesh_map(cameras, np.vstack([old.points, tracks.points]),
                     np.vstack([old.colors, tracks.colors]).astype(np.uint8),
                     np.vstack([old.points + old.normals, tracks.seen_from]), config, old.registered)
