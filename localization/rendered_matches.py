"""Pose proposals from features of rendered views: the model's own views, matched to the photo.

The particle filter (`pose6_filter`) searches by comparing whole rendered views with the photo
at 24-48 pixels. When the model explains only a small share of the photo (a sparse proxy whose
trusted faces cover a few per cent of the image), that comparison is flat over most of a wide
prior and the filter can settle in the wrong basin although Gauss-Newton from the truth stays
at the truth. Local features are not flat: the rendered views carry the map photos' texture,
so SIFT keypoints of a view rendered near the prior match the photo's, and every matched
keypoint has a 3-D point (the rendered G-buffer's world position). RANSAC PnP on those 2-D/3-D
matches (pycolmap) proposes a pose, as render-and-compare localisers initialise from matches
against rendered views (e.g. PixLoc, Sarlin et al. 2021; iComMa, Sun et al. 2023).

A proposal is only a starting point: it is aligned by photometric Gauss-Newton and judged by
the rendered verdict beside the filter's modes (`render_localizer`), so a wrong proposal costs
one alignment and cannot be accepted on its own. Nothing but the model is used (no map
descriptors), so the render-only localiser stays render-only.

Viewpoints: the prior pose, the prior turned by `turn_fraction` of the prior's rotation spread
to each side (yaw and pitch, so the views together see what a photo turned anywhere inside the
prior sees), and the filter's best modes. Frames: cam_from_world (4, 4), world metres; pixels
as `ibr.camera.Camera`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage
from scipy.spatial.transform import Rotation

from ibr.camera import Camera
from ibr.proxy.triangulation import Features, sift_features
from localization.feature_localizer import pycolmap_camera, ransac_pnp
from localization.render_likelihood import comparison_camera


@dataclass(frozen=True)
class RenderedMatchConfig:
    """Settings of `rendered_proposals` (counts, shares and pixels at the matching width:
    none depends on the scene's size)."""

    width: int = 384
    """Width (pixels) of the photo and the rendered views when matched (capped at the photo's)."""
    n_features: int = 4000
    """SIFT keypoints per image."""
    ratio: float = 0.8
    """Lowe's ratio test between the nearest and second nearest rendered descriptor."""
    turn_fraction: float = 0.6
    """The side views turn the prior by this fraction of its rotation spread."""
    edge_px: int = 3
    """Keypoints closer than this to the edge of the rendered model are dropped: the edge
    against the empty background is not in the photo."""
    ransac_max_error_px: float = 3.0
    """RANSAC inlier threshold on the reprojection error (pixels at the matching width)."""
    min_inliers: int = 12
    """Fewer inliers than this: no proposal from these matches."""
    rounds: int = 2
    """Rounds of rendering and matching (the later ones at the best proposals so far)."""
    keep: int = 2
    """Proposals of one round rendered again in the next."""


def turned(cam_from_world: np.ndarray, yaw: float, pitch: float) -> np.ndarray:
    """The pose turned about its own centre by yaw (about camera y) and pitch (about camera
    x), radians."""
    R = Rotation.from_euler("yx", [yaw, pitch]).as_matrix()
    T = cam_from_world.copy()
    T[:3, :3] = R.T @ cam_from_world[:3, :3]
    T[:3, 3] = R.T @ cam_from_world[:3, 3]
    return T


def proposal_viewpoints(prior: np.ndarray, spread_rad: float, modes: list[np.ndarray],
                        turn_fraction: float) -> list[np.ndarray]:
    """The poses (4, 4) the model is rendered at: the prior, the prior turned to four sides
    by turn_fraction x spread_rad, and the filter's `modes`."""
    a = turn_fraction * spread_rad
    sides = [turned(prior, y, p) for y, p in ((a, 0.0), (-a, 0.0), (0.0, a), (0.0, -a))] if a > 0 else []
    return [prior, *sides, *modes]


def rendered_features(renderer, camera: Camera, n_features: int, edge_px: int,
                      light=None) -> tuple[Features, np.ndarray]:
    """SIFT of the model rendered at `camera` (lit by `light` when given) and the world point
    (K, 3) of each keypoint, keeping keypoints at least edge_px inside the rendered model."""
    g = renderer.render(camera, light)
    inside = ndimage.binary_erosion(g.mask, iterations=edge_px) if edge_px > 0 else g.mask
    f = sift_features(g.color, n_features)
    ij = np.clip(np.round(f.uv).astype(int), 0, [camera.width - 1, camera.height - 1])
    keep = inside[ij[:, 1], ij[:, 0]]
    return Features(f.uv[keep], f.descriptors[keep], f.colors[keep]), g.world[ij[keep, 1], ij[keep, 0]]


def match_ratio(query: np.ndarray, train: np.ndarray, ratio: float) -> np.ndarray:
    """(M, 2) index pairs (query, train) passing Lowe's ratio test (exhaustive L2 matching)."""
    if len(query) == 0 or len(train) < 2:
        return np.zeros((0, 2), int)
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(query, train, k=2)
    pairs = [(m[0].queryIdx, m[0].trainIdx) for m in knn if len(m) == 2 and m[0].distance < ratio * m[1].distance]
    return np.array(pairs, int).reshape(-1, 2)


def pnp_pose(uv: np.ndarray, xyz: np.ndarray, camera: Camera, max_error_px: float,
             min_inliers: int) -> tuple[np.ndarray, int] | None:
    """RANSAC PnP (`feature_localizer.ransac_pnp`) of pixels (M, 2) of `camera` onto world
    points (M, 3): (cam_from_world (4, 4), inliers), or None below min_inliers."""
    if len(uv) < max(4, min_inliers):
        return None
    found = ransac_pnp(uv, xyz, pycolmap_camera(camera), max_error_px)
    if found is None or found[1]["num_inliers"] < min_inliers:
        return None
    return found[0], int(found[1]["num_inliers"])


def rendered_proposals(renderer, focus, image: np.ndarray, camera: Camera, prior: np.ndarray,
                       spread_rad: float, modes: list[np.ndarray],
                       config: RenderedMatchConfig = RenderedMatchConfig(), light=None) -> list[tuple[np.ndarray, int]]:
    """Pose proposals (cam_from_world (4, 4), inliers), most inliers first, for `image`
    ((H, W, 3) uint8, intrinsics of `camera`) from the model `renderer` (a textured
    `MeshRenderer`, lit by `light` when given; `focus(eye)` re-chooses its textures, None
    for a mesh with fixed colours). The first round renders the prior
    (4, 4), its turned views and the filter's `modes`; each further round renders again at
    the best `keep` proposals of the round before, whose views are closer to the photo's and
    match it better (as an iterated closest-view matching)."""
    cam = comparison_camera(camera, min(config.width, camera.width))
    small = cv2.resize(image, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
    query = sift_features(small, config.n_features)
    if focus is not None:
        focus(np.linalg.inv(prior)[:3, 3])
    views = proposal_viewpoints(prior, spread_rad, modes, config.turn_fraction)
    proposals: list[tuple[np.ndarray, int]] = []
    for _ in range(config.rounds):
        found = proposals_from_views(renderer, query, cam, views, config, light)
        proposals = sorted(proposals + found, key=lambda p: -p[1])
        views = [T for T, _ in found[:config.keep]]
        if not views:
            break
    return proposals


def proposals_from_views(renderer, query: Features, cam: Camera, views: list[np.ndarray],
                         config: RenderedMatchConfig, light=None) -> list[tuple[np.ndarray, int]]:
    """Proposals, most inliers first, of the query features (pixels of `cam`) matched to the
    model rendered at `views` (cam_from_world (4, 4) each): one PnP on the matches of all
    views together and one per view."""
    uv, xyz = [], []
    for T in views:
        feats, world = rendered_features(renderer, cam.with_pose(T), config.n_features, config.edge_px, light)
        m = match_ratio(query.descriptors, feats.descriptors, config.ratio)
        uv.append(query.uv[m[:, 0]])
        xyz.append(world[m[:, 1]])
    sets = [(np.concatenate(uv), np.concatenate(xyz))] + (list(zip(uv, xyz)) if len(views) > 1 else [])
    found = [pnp_pose(u, x, cam, config.ransac_max_error_px, config.min_inliers) for u, x in sets]
    return sorted((p for p in found if p is not None), key=lambda p: -p[1])
