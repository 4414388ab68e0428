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
prior sees), the filter's best modes, and the map photos near the prior at their own poses
(`near_map_views`). Each view is rendered with the textures chosen for its own eye. Frames:
cam_from_world (4, 4), world metres; pixels as `ibr.camera.Camera`.

Why the map photos' own poses: the model's texture comes from them, so at their poses its
rendered views are sharp and whole, while a view from the prior (up to a prior's spread and
30 degrees off) shows the texture warped, in part or not at all. On the courtyard (seed 4,
its ring of 56 photos, 20 novel queries from a prior of 10 % of the scene's depth and 30
degrees), the prior's views proposed a pose within 25 cm for 1 of the 7 queries the filter
missed; the six map photos nearest the prior proposed one within 10 cm for 6 of them.
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
    map_views: int = 6
    """Map photos (`near_map_views`, nearest the prior first) the first round also renders
    at, at their own poses."""


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


def near_map_views(prior: np.ndarray, spread_m: float, spread_rad: float, cameras: list[Camera],
                   n: int) -> list[np.ndarray]:
    """The poses cam_from_world (4, 4) of up to `n` map photos (`cameras`), nearest the prior
    (4, 4) first, that could see what a photo inside the prior sees: the photo's centre within
    twice the prior's position spread `spread_m` (metres) of the prior's on every axis (within
    one spread of a centre the prior allows), and its optical axis within `spread_rad` plus
    half its horizontal field of view of the prior's (their views overlap)."""
    centre, axis = np.linalg.inv(prior)[:3, 3], prior[2, :3]
    near = []
    for c in cameras:
        half_fov = np.arctan2(c.width / 2, c.K[0, 0])
        if (np.all(np.abs(c.center - centre) <= 2 * spread_m)
                and c.cam_from_world[2, :3] @ axis >= np.cos(min(spread_rad + half_fov, np.pi))):
            near.append(c)
    near.sort(key=lambda c: np.linalg.norm(c.center - centre))
    return [c.cam_from_world for c in near[:n]]


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
                       config: RenderedMatchConfig = RenderedMatchConfig(), light=None,
                       map_views: list[np.ndarray] = ()) -> list[tuple[np.ndarray, int]]:
    """Pose proposals (cam_from_world (4, 4), inliers), most inliers first, for `image`
    ((H, W, 3) uint8, intrinsics of `camera`) from the model `renderer` (a textured
    `MeshRenderer`, lit by `light` when given; `focus(eye)` re-chooses its textures, None
    for a mesh with fixed colours). The first round renders the prior
    (4, 4), its turned views, the filter's `modes` and `map_views` (the map photos' poses,
    `near_map_views`); each further round renders again at the best `keep` proposals of the
    round before, whose views are closer to the photo's and match it better (as an iterated
    closest-view matching)."""
    cam = comparison_camera(camera, min(config.width, camera.width))
    small = cv2.resize(image, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
    query = sift_features(small, config.n_features)
    views = proposal_viewpoints(prior, spread_rad, modes, config.turn_fraction) + list(map_views)
    proposals: list[tuple[np.ndarray, int]] = []
    for _ in range(config.rounds):
        found = proposals_from_views(renderer, focus, query, cam, views, config, light)
        proposals = sorted(proposals + found, key=lambda p: -p[1])
        views = [T for T, _ in found[:config.keep]]
        if not views:
            break
    return proposals


def proposals_from_views(renderer, focus, query: Features, cam: Camera, views: list[np.ndarray],
                         config: RenderedMatchConfig, light=None) -> list[tuple[np.ndarray, int]]:
    """Proposals, most inliers first, of the query features (pixels of `cam`) matched to the
    model rendered at `views` (cam_from_world (4, 4) each, its textures chosen for its eye by
    `focus` when given): one PnP on the matches of all views together and one per view."""
    uv, xyz, focused = [], [], None
    for T in views:
        eye = np.linalg.inv(T)[:3, 3]
        if focus is not None and (focused is None or not np.allclose(eye, focused, rtol=0.0, atol=1e-9)):
            focus(eye)  # the prior and its turned views share one eye: choose its textures once
            focused = eye
        feats, world = rendered_features(renderer, cam.with_pose(T), config.n_features, config.edge_px, light)
        m = match_ratio(query.descriptors, feats.descriptors, config.ratio)
        uv.append(query.uv[m[:, 0]])
        xyz.append(world[m[:, 1]])
    sets = [(np.concatenate(uv), np.concatenate(xyz))] + (list(zip(uv, xyz)) if len(views) > 1 else [])
    found = [pnp_pose(u, x, cam, config.ransac_max_error_px, config.min_inliers) for u, x in sets]
    return sorted((p for p in found if p is not None), key=lambda p: -p[1])
