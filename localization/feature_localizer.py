"""Feature-based camera localisation: SIFT matched to a map of 3-D points, RANSAC PnP.

Foster, Wang & Grupen (section IV-B, path following): SIFT features of the robot's image are
matched against the SfM points' descriptors through a precomputed KD-tree, the camera is
found by RANSAC (DLT) and then refined (f, R, T), about 2 in / 1 degree accurate.

Here the map comes from posed photos (`ibr.scene.Scene`): SIFT per image, matched between
neighbouring views, kept when consistent with the epipolar geometry of the *known* poses and
triangulated (`ibr.proxy.triangulation`). Every triangulated point keeps the descriptors of both
features it came from, and all descriptors go into one FLANN KD-tree index built once (in a
background thread, `FeatureMap`).
A query's descriptors are matched with a ratio test whose second neighbour must belong to a
*different* 3-D point (more than `FeatureLocalizerConfig.same_point_m` away), then pycolmap's
`estimate_and_refine_absolute_pose` (LO-RANSAC P3P + non-linear refinement) gives the pose.

SIFT is invariant to scale and rotation, not to the affine squash of a surface seen obliquely:
its matches thin out beyond about 40 degrees of viewpoint change. A query can therefore be
described at several simulated *tilts* (`tilted_features`, `FeatureLocalizerConfig.query_tilts`):
ASIFT's idea (Morel & Yu, "ASIFT: a new framework for fully affine invariant image comparison",
SIAM J. Imaging Sciences 2009) kept to horizontal tilts, the only ones a level camera turning
about the vertical axis produces on walls and furniture sides.

Frames: world points in metres; pixels (u, v) with centres at integer coordinates, as
`ibr.camera.Camera` (COLMAP's half-pixel offset cancels: the principal point and the
keypoints are given to pycolmap in the same convention).
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field

import cv2
import numpy as np
import pycolmap
from scipy.spatial.transform import Rotation

from ibr.camera import Camera, rigid
from ibr.scene import Scene
from ibr.proxy.triangulation import (Features, TriangulationConfig, neighbour_pairs, pair_tracks,
                                     sift_features)


@dataclass(frozen=True)
class FeatureLocalizerConfig:
    """Settings of `FeatureMap` (map building and `localize`)."""

    triangulation: TriangulationConfig = field(default_factory=TriangulationConfig)
    """SIFT count, matching and triangulation checks used to build the map (known poses)."""
    query_features: int = 8000
    """SIFT keypoints extracted from a query image."""
    ratio: float = 0.8
    """Lowe's ratio between the nearest and the nearest *other-point* descriptor distance."""
    same_point_m: float = 0.02
    """Neighbours whose 3-D points lie closer than this (metres) count as the same point in
    the ratio test (the map holds each point's descriptors from two or more views)."""
    kdtree_trees: int = 4
    """Randomised KD-trees in the FLANN index."""
    kdtree_checks: int = 64
    """Leaves FLANN visits per query descriptor (more: slower, closer to exact)."""
    kdtree_seed: int = 0
    """Seed of the randomised KD-trees. FLANN draws their split dimensions from OpenCV's
    process-wide RNG (`cv::theRNG`), so unseeded the same map matched differently after other
    maps had been built in the process (a mission's PnP fixes changed with what ran before)."""
    ransac_max_error_px: float = 4.0
    """RANSAC inlier threshold on the reprojection error (pixels of the query image)."""
    min_inliers: int = 15
    """Fewer RANSAC inliers than this: no pose (`localize` returns None)."""
    query_tilts: tuple[float, ...] = (1.0,)
    """Horizontal stretch factors the query is described at (`tilted_features`); (1.0,):
    plain SIFT. A factor t undoes the squash of a surface turned by arccos(1/t) more (t > 1)
    or less (t < 1) towards the query than towards the map's photos."""


@dataclass
class PnPResult:
    """A localised query. cam_from_world (4, 4) rigid, world metres -> camera axes;
    n_matches: descriptor matches given to RANSAC; n_inliers: RANSAC inliers; camera: the
    query's `Camera` at that pose (with the refined focal length if it was refined);
    inlier_uv (n_inliers, 2) pixels and inlier_xyz (n_inliers, 3) world metres: the inlier
    correspondences."""

    cam_from_world: np.ndarray
    n_matches: int
    n_inliers: int
    camera: Camera
    inlier_uv: np.ndarray | None = None
    inlier_xyz: np.ndarray | None = None


def pycolmap_camera(camera: Camera) -> pycolmap.Camera:
    """The pinhole intrinsics of `camera` as a pycolmap PINHOLE camera (skew dropped)."""
    K = camera.K
    return pycolmap.Camera(model="PINHOLE", width=camera.width, height=camera.height,
                           params=[K[0, 0], K[1, 1], K[0, 2], K[1, 2]])


def ransac_pnp(uv: np.ndarray, xyz: np.ndarray, camera: pycolmap.Camera, max_error_px: float,
               refine_focal: bool = False) -> tuple[np.ndarray, dict] | None:
    """pycolmap's LO-RANSAC P3P + non-linear refinement of pixels (M, 2) onto world points
    (M, 3) (seeded, so repeatable): (cam_from_world (4, 4), pycolmap's result with
    num_inliers and inlier_mask), or None when it finds no pose. With refine_focal the
    refined focal length is written into `camera`'s params."""
    est = pycolmap.AbsolutePoseEstimationOptions()
    est.ransac.max_error = max_error_px
    est.ransac.random_seed = 0
    ref = pycolmap.AbsolutePoseRefinementOptions()
    ref.refine_focal_length = refine_focal
    res = pycolmap.estimate_and_refine_absolute_pose(uv.astype(np.float64), xyz.astype(np.float64), camera, est, ref)
    if res is None:
        return None
    T = rigid(np.eye(3), np.zeros(3))
    T[:3, :] = res["cam_from_world"].matrix()
    return T, res


def tilted_features(image: np.ndarray, n_features: int, contrast_threshold: float,
                    tilts: tuple[float, ...]) -> Features:
    """SIFT features of `image` ((H, W, 3) uint8 RGB) described at each horizontal tilt of
    `tilts`: the image resized to round(W t) x H, SIFT there (at most `n_features` each), and
    the keypoints' u divided by t back to `image`'s pixels; all tilts' features pooled.
    Morel & Yu's ASIFT simulates tilts t = 1, sqrt 2, 2, ... in all directions on both images;
    here the direction is horizontal only (a level robot camera turns about the vertical) and
    t < 1 stands for the map photo's tilt, so only the query is resampled."""
    feats = []
    for t in tilts:
        w = max(1, int(round(image.shape[1] * t)))
        im = image if w == image.shape[1] else cv2.resize(
            image, (w, image.shape[0]), interpolation=cv2.INTER_AREA if t < 1 else cv2.INTER_LINEAR)
        f = sift_features(im, n_features, contrast_threshold)
        feats.append(Features(f.uv * [image.shape[1] / w, 1.0], f.descriptors, f.colors))
    return Features(np.vstack([f.uv for f in feats]), np.vstack([f.descriptors for f in feats]),
                    np.vstack([f.colors for f in feats]))


def unique_matches(m: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """The matches (M, 2) (query feature, map point) keeping the first of those sharing a map
    point, then the first of those whose query keypoints `uv` (Q, 2) round to one pixel: a
    keypoint described at several tilts, or at two orientations, is one observation, and
    counted twice it would inflate RANSAC's inliers."""
    if len(m) == 0:
        return m
    m = m[np.sort(np.unique(m[:, 1], return_index=True)[1])]
    return m[np.sort(np.unique(np.round(uv[m[:, 0]]).astype(int), axis=0, return_index=True)[1])]


def triangulated_tracks(cameras: list[Camera], feats: list[Features], cfg: TriangulationConfig
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Triangulate epipolar-consistent matches of neighbouring views (known poses).

    Returns points (P, 3) world metres, descriptors (2P, 128) float32 and owner (2P,) the
    point index of each descriptor (both features of every match are kept)."""
    points, _, descriptors, owner, _ = pair_tracks(cameras, feats, neighbour_pairs(cameras, cfg.neighbours), cfg)
    return points, descriptors, owner


def trained_matcher(descriptors: np.ndarray, config: FeatureLocalizerConfig) -> cv2.FlannBasedMatcher:
    """A FLANN matcher over `descriptors` (D, 128) float32, its randomised KD-trees built
    (`kdtree_trees`, `kdtree_checks`) with OpenCV's RNG seeded (`kdtree_seed`): FLANN splits its
    trees with the RNG of the thread that builds them, so the same descriptors give the same
    trees, and the same neighbours, in whichever thread and after whatever ran before."""
    matcher = cv2.FlannBasedMatcher(dict(algorithm=1, trees=config.kdtree_trees),  # FLANN_INDEX_KDTREE
                                    dict(checks=config.kdtree_checks))
    if len(descriptors):
        matcher.add([np.ascontiguousarray(descriptors, np.float32)])
        cv2.setRNGSeed(config.kdtree_seed)
        matcher.train()
    return matcher


_INDEX_BUILDER = ThreadPoolExecutor(max_workers=1, thread_name_prefix="feature-map-index")
"""One thread that builds `FeatureMap` indices in the background, one after another in the
order they were asked for (OpenCV releases the GIL while it trains)."""


class FeatureMap:
    """3-D points with SIFT descriptors and a KD-tree index over the descriptors.

    points: (P, 3) world metres; descriptors: (D, 128) float32; owner: (D,) point of each
    descriptor. Build with `from_scene`; query with `localize`. The index is built in a
    background thread (`trained_matcher`) and waited for at the first match: a mission grows
    its map after every goal, and a 0.6 s build (apartment 3's 78 builds: 45 s of its 316)
    overlaps the drive and the photo that come before the next query (apartment 3's mission
    alone on 2 cores: 266 s instead of 281 s, the same photos and poses). The neighbours are
    the same as a build in the caller's thread would give."""

    def __init__(self, points: np.ndarray, descriptors: np.ndarray, owner: np.ndarray,
                 config: FeatureLocalizerConfig = FeatureLocalizerConfig()):
        self.points, self.descriptors, self.owner, self.config = points, descriptors, owner, config
        self._index = self._start_index()

    def _start_index(self) -> Future:
        """The matcher's build (`trained_matcher`), submitted to the background thread."""
        return _INDEX_BUILDER.submit(trained_matcher, self.descriptors, self.config)

    @property
    def matcher(self) -> cv2.DescriptorMatcher:
        """The trained matcher, once its background build has finished (its error, if it failed)."""
        return self._index.result()

    @classmethod
    def from_scene(cls, scene: Scene, config: FeatureLocalizerConfig = FeatureLocalizerConfig(),
                   exclude: tuple[str, ...] | list[str] = ()) -> "FeatureMap":
        """Map of `scene`'s posed photos, leaving out the views named in `exclude`."""
        views = [v for v in scene.views if v.name not in set(exclude)]
        feats = [sift_features(v.image, config.triangulation.n_features, config.triangulation.contrast_threshold)
                 for v in views]
        return cls.from_features([v.camera for v in views], feats, config)

    @classmethod
    def from_features(cls, cameras: list[Camera], feats: list[Features],
                      config: FeatureLocalizerConfig = FeatureLocalizerConfig()) -> "FeatureMap":
        """Map from posed cameras and their already extracted SIFT features (leave-one-out
        evaluation extracts each photo's features once)."""
        return cls(*triangulated_tracks(cameras, feats, config.triangulation), config)

    def __len__(self) -> int:
        return len(self.points)

    def match(self, descriptors: np.ndarray, k: int = 6) -> np.ndarray:
        """(M, 2) pairs (query descriptor index, map point index) passing the ratio test
        against the nearest neighbour that belongs to another 3-D point."""
        if len(descriptors) == 0 or len(self.descriptors) < 2:
            return np.zeros((0, 2), int)
        knn = self.matcher.knnMatch(np.ascontiguousarray(descriptors, np.float32), k=k)
        out = []
        for nbrs in knn:
            if not nbrs:
                continue
            best = self.owner[nbrs[0].trainIdx]
            second = next((m.distance for m in nbrs[1:] if np.linalg.norm(
                self.points[self.owner[m.trainIdx]] - self.points[best]) > self.config.same_point_m), None)
            if second is None or nbrs[0].distance < self.config.ratio * second:
                out.append((nbrs[0].queryIdx, best))
        return np.array(out, dtype=int).reshape(-1, 2)

    def localize(self, image: np.ndarray, camera: Camera, refine_focal: bool = False,
                 tilts: tuple[float, ...] | None = None) -> PnPResult | None:
        """Pose of the camera that took `image` ((H, W, 3) uint8 RGB), with the intrinsics and
        size of `camera` (its pose is ignored), its features described at `tilts` (default
        `query_tilts`). None when fewer than `min_inliers` inliers."""
        tilts = tuple(self.config.query_tilts if tilts is None else tilts)
        feats = tilted_features(image, self.config.query_features, self.config.triangulation.contrast_threshold, tilts)
        return self.localize_features(feats, camera, refine_focal, unique=tilts != (1.0,))

    def localize_features(self, feats: Features, camera: Camera, refine_focal: bool = False,
                          unique: bool = False) -> PnPResult | None:
        """`localize` from already extracted query features; with `unique`, one match per map
        point and per query pixel (`unique_matches`: features pooled over tilts)."""
        m = self.match(feats.descriptors)
        m = unique_matches(m, feats.uv) if unique else m
        if len(m) < max(4, self.config.min_inliers):
            return None
        cfg = self.config
        cam = pycolmap_camera(camera)
        found = ransac_pnp(feats.uv[m[:, 0]], self.points[m[:, 1]], cam, cfg.ransac_max_error_px, refine_focal)
        if found is None or found[1]["num_inliers"] < cfg.min_inliers:
            return None
        T, res = found
        K = camera.K.copy()
        if refine_focal:
            fx, fy = cam.params[0], cam.params[1]
            K[0, 0], K[1, 1] = fx, fy
        inl = np.asarray(res["inlier_mask"], bool)
        return PnPResult(T, len(m), int(res["num_inliers"]), Camera(K, camera.width, camera.height, T, camera.name),
                         feats.uv[m[inl, 0]], self.points[m[inl, 1]])


def pose_errors(cam_from_world: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(position error metres, rotation error degrees) between two cam_from_world (4, 4)."""
    c_est = -cam_from_world[:3, :3].T @ cam_from_world[:3, 3]
    c_true = -truth[:3, :3].T @ truth[:3, 3]
    angle = Rotation.from_matrix(cam_from_world[:3, :3] @ truth[:3, :3].T).magnitude()
    return float(np.linalg.norm(c_est - c_true)), float(np.degrees(angle))
