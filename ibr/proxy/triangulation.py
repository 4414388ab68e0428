"""Triangulation of SIFT matches with fixed, known camera poses.

The first step of the geometric proxy that Foster, Wang & Grupen (section IV-B, V-C) build
from posed photos: features are matched between neighbouring views, each match is checked
against the epipolar geometry that the *known* poses imply (no pose is re-estimated), and the
surviving matches are triangulated linearly (DLT, `cv2.triangulatePoints`). Points with a
large reprojection error, a small triangulation angle or a negative depth are dropped.

Frames: world points in metres (the scene's world frame); pixels (u, v) with centres at
integer coordinates, as `ibr.camera.Camera`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ibr.camera import Camera


@dataclass(frozen=True)
class TriangulationConfig:
    """Settings of `triangulate_views`."""

    n_features: int = 8000
    """SIFT keypoints kept per image (strongest first)."""
    ratio: float = 0.8
    """Lowe's ratio test threshold on the two nearest descriptor distances."""
    neighbours: int = 3
    """Each view is matched with this many neighbouring views (closest centres and axes)."""
    max_epipolar_px: float = 2.0
    """Largest Sampson distance (pixels) of a match to the epipolar geometry of the known poses."""
    max_reprojection_px: float = 2.0
    """Largest reprojection error (pixels) of a triangulated point in either view."""
    min_angle_deg: float = 1.5
    """Smallest angle (degrees) between the two viewing rays of a triangulated point."""
    contrast_threshold: float = 0.04
    """SIFT's contrast threshold (OpenCV's `contrastThreshold`, on intensities scaled to
    [0, 1], so it depends on neither the scene's size nor the image's): lower keeps fainter
    keypoints. 0.04 is OpenCV's default; the capture mission's localiser uses 0.02, as faint
    as COLMAP's SfM detects (`robot.mission.adaptive.AdaptiveConfig.localizer`)."""


@dataclass
class Features:
    """SIFT features of one image: keypoints (N, 2) pixels (u, v), descriptors (N, 128) f32,
    colours (N, 3) uint8 sampled at the keypoints."""

    uv: np.ndarray
    descriptors: np.ndarray
    colors: np.ndarray


@dataclass
class TriangulatedPoints:
    """points (N, 3) world metres; colors (N, 3) uint8; view_pairs (N, 2) indices of the two
    source views each point came from (used to orient normals towards the cameras)."""

    points: np.ndarray
    colors: np.ndarray
    view_pairs: np.ndarray


def sift_features(image: np.ndarray, n_features: int, contrast_threshold: float = 0.04) -> Features:
    """SIFT keypoints and descriptors of an (H, W, 3) uint8 RGB image (OpenCV), at most
    `n_features`, no fainter than `contrast_threshold` (`TriangulationConfig`)."""
    gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    sift = cv2.SIFT_create(nfeatures=n_features, contrastThreshold=contrast_threshold)
    kps, desc = sift.detectAndCompute(gray, None)
    uv = np.array([k.pt for k in kps], dtype=np.float64).reshape(-1, 2)
    if desc is None:
        desc = np.zeros((0, 128), np.float32)
    ij = np.clip(np.round(uv).astype(int), 0, [image.shape[1] - 1, image.shape[0] - 1])
    return Features(uv, desc.astype(np.float32), image[ij[:, 1], ij[:, 0]])


def neighbour_pairs(cameras: list[Camera], k: int) -> np.ndarray:
    """(P, 2) index pairs i < j: each camera with its k nearest others, where the distance is
    the centre distance (metres) scaled up by the angle between the optical axes."""
    C = np.array([c.center for c in cameras])
    F = np.array([c.forward for c in cameras])
    dist = np.linalg.norm(C[:, None] - C[None], axis=2)
    cos = np.clip(F @ F.T, -1.0, 1.0)
    score = dist * (1.0 + 2.0 * np.arccos(cos))
    np.fill_diagonal(score, np.inf)
    score[cos < 0.0] = np.inf  # cameras looking apart share little
    pairs = {(min(i, j), max(i, j)) for i in range(len(cameras))
             for j in np.argsort(score[i])[:k] if np.isfinite(score[i, j])}
    return np.array(sorted(pairs), dtype=int).reshape(-1, 2)


def fundamental_matrix(a: Camera, b: Camera) -> np.ndarray:
    """F with x_b^T F x_a = 0 for homogeneous pixels of the same world point (known poses)."""
    b_from_a = b.cam_from_world @ a.world_from_cam
    R, t = b_from_a[:3, :3], b_from_a[:3, 3]
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    return np.linalg.inv(b.K).T @ tx @ R @ np.linalg.inv(a.K)


def sampson_distance(F: np.ndarray, xa: np.ndarray, xb: np.ndarray) -> np.ndarray:
    """First-order geometric error (pixels) of matches xa (N, 2) <-> xb (N, 2) under F."""
    ha, hb = np.c_[xa, np.ones(len(xa))], np.c_[xb, np.ones(len(xb))]
    Fa, Ftb = ha @ F.T, hb @ F
    num = np.einsum("ij,ij->i", hb, Fa) ** 2
    return np.sqrt(num / (Fa[:, 0] ** 2 + Fa[:, 1] ** 2 + Ftb[:, 0] ** 2 + Ftb[:, 1] ** 2 + 1e-12))


def match_features(fa: Features, fb: Features, ratio: float) -> np.ndarray:
    """(M, 2) indices of mutual-ratio-test SIFT matches between two feature sets."""
    if len(fa.uv) < 2 or len(fb.uv) < 2:
        return np.zeros((0, 2), int)
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(fa.descriptors, fb.descriptors, k=2)
    m = np.array([(p[0].queryIdx, p[0].trainIdx) for p in knn
                  if len(p) == 2 and p[0].distance < ratio * p[1].distance], dtype=int)
    return m.reshape(-1, 2)


def projection_matrix(camera: Camera) -> np.ndarray:
    """3x4 pixel_from_world matrix K [R | t]."""
    return camera.K @ camera.cam_from_world[:3, :]


def triangulate_pair(a: Camera, b: Camera, xa: np.ndarray, xb: np.ndarray,
                     cfg: TriangulationConfig) -> tuple[np.ndarray, np.ndarray]:
    """Linear triangulation of matches xa, xb (N, 2). Returns world points (M, 3) and the
    (M,) indices of the matches that pass the depth, reprojection and angle checks."""
    if len(xa) == 0:
        return np.zeros((0, 3)), np.zeros(0, int)
    X = cv2.triangulatePoints(projection_matrix(a), projection_matrix(b),
                              np.ascontiguousarray(xa.T, np.float64), np.ascontiguousarray(xb.T, np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        P = (X[:3] / X[3]).T
    ok = np.isfinite(P).all(axis=1)
    for cam, x in ((a, xa), (b, xb)):
        uv, z = cam.project(np.nan_to_num(P))
        ok &= (z > 0) & (np.linalg.norm(uv - x, axis=1) < cfg.max_reprojection_px)
    ra, rb = P - a.center, P - b.center
    cos = np.einsum("ij,ij->i", ra, rb) / (np.linalg.norm(ra, axis=1) * np.linalg.norm(rb, axis=1) + 1e-12)
    ok &= cos < np.cos(np.radians(cfg.min_angle_deg))
    idx = np.flatnonzero(ok)
    return P[idx], idx


def triangulate_matches(a: Camera, b: Camera, fa: Features, fb: Features, cfg: TriangulationConfig,
                        matches: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Match the features of two posed views (or take their `matches` (M, 2), from
    `match_features` before), keep the epipolar-consistent matches and triangulate them.
    Returns world points (M, 3) and each point's feature indices (M, 2) into fa and fb."""
    m = match_features(fa, fb, cfg.ratio) if matches is None else matches
    xa, xb = fa.uv[m[:, 0]], fb.uv[m[:, 1]]
    good = np.flatnonzero(sampson_distance(fundamental_matrix(a, b), xa, xb) < cfg.max_epipolar_px)
    P, idx = triangulate_pair(a, b, xa[good], xb[good], cfg)
    return P, m[good[idx]]


def triangulate_views(cameras: list[Camera], features: list[Features],
                      cfg: TriangulationConfig = TriangulationConfig()) -> TriangulatedPoints:
    """Match every view with its neighbours, keep epipolar-consistent matches and triangulate
    them with the known poses. Returns the union of all pairs' points."""
    pts, cols, pairs = [], [], []
    for i, j in neighbour_pairs(cameras, cfg.neighbours):
        P, mi = triangulate_matches(cameras[i], cameras[j], features[i], features[j], cfg)
        pts.append(P)
        cols.append(features[i].colors[mi[:, 0]])
        pairs.append(np.tile([i, j], (len(P), 1)))
    if not pts:
        return TriangulatedPoints(np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros((0, 2), int))
    return TriangulatedPoints(np.concatenate(pts), np.concatenate(cols).astype(np.uint8),
                              np.concatenate(pairs))


def pair_tracks(cameras: list[Camera], feats: list[Features], pairs: np.ndarray, cfg: TriangulationConfig,
                matches=None):
    """Triangulate the epipolar-consistent SIFT matches of the given view `pairs` (P, 2)
    with the poses fixed (`matches(i, j)`, when given, gives views i and j's matches).
    Returns points (N, 3), colours (N, 3) uint8, the two descriptors of each point's features
    (2N, 128) with their owners (2N,), and the first view of each point (a map a feature
    localiser can match against)."""
    pts, cols, descs, owners, first = [], [], [], [], []
    n = 0
    for i, j in pairs:
        P, mi = triangulate_matches(cameras[i], cameras[j], feats[i], feats[j], cfg,
                                    None if matches is None else matches(i, j))
        pts.append(P)
        cols.append(feats[i].colors[mi[:, 0]])
        descs += [feats[i].descriptors[mi[:, 0]], feats[j].descriptors[mi[:, 1]]]
        owners += [np.arange(n, n + len(P))] * 2
        first.append(np.full(len(P), i))
        n += len(P)
    if n == 0:
        return (np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros((0, 128), np.float32),
                np.zeros(0, int), np.zeros(0, int))
    return (np.concatenate(pts), np.concatenate(cols).astype(np.uint8), np.concatenate(descs).astype(np.float32),
            np.concatenate(owners), np.concatenate(first))
