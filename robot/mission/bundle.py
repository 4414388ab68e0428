"""Bundle adjustment of the photos the adaptive stage posed, on the first map's frame.

The first map's photos are SfM's, adjusted on the robot's rig (`rig_adjustment`); every
later photo is posed by a PnP fix against the map's points (or by re-posing), and the points
it adds are triangulated with that pose held (`map_building.stereo_tracks`), so they keep
its error. Measured (stop of 2026-12-01, apartments 1 and 3, against the true mesh): the
grown points lay 2-7 cm off at the median at every ray angle, the first map's 1-2 cm; a
third view confirming a point did not make it more accurate. No check on points can see an
error that lies in the poses; an adjustment of the poses with every view of each point can
(Triggs et al., "Bundle adjustment: a modern synthesis", 2000; COLMAP's adjuster via
pycolmap, Cauchy-robust reprojection errors).

`adjust_grown` joins the stereo pairs' matches into multi-view tracks, holds the first map's
photos as the frame (their poses fix the gauge: place, heading and scale), and refines the
other photos and every point, each free photo's centre held to a prior position (where the
mission put it when it joined the tracks, `BundleConfig.position_sigma_m`). Without the
priors a block of photos that the tracks join weakly to the held ones slides: offline, on
apartment 1's final state, 24 cm together. Photos with few points, and blocks the tracks do
not join to a held photo, stay as they are. Offline, on the final state of main's missions
(grown photos' centre error against the simulator's truth, median / p95): apartment 1 (where
the settings were chosen) 3.6 / 8.1 -> 1.9 / 6.6 cm; held out, office 0 3.2 / 16.8 -> 1.9 /
3.0, apartment 8 0.9 / 7.2 -> 0.6 / 2.6, apartment 6 4.2 / 10.1 -> 4.6 / 7.3, apartment 3
1.7 / 11.2 -> 1.3 / 12.0.

Frames: world metres, z up; pixels with ibrnav's convention (pixel centres at integers).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ibr.camera import Camera
from ibr.colmap import colmap_errors_only
from ibr.proxy.triangulation import Features, TriangulationConfig, match_features, triangulate_matches
from robot.mission.map_building import stereo_pairs

@dataclass(frozen=True)
class BundleConfig:
    """Settings of `adjust_grown`."""

    position_sigma_m: float = 0.1
    """Standard deviation (m, isotropic) of a free photo's centre about its prior position.
    The accuracy of the robot's fixes, not a scene's: a fix is believed within
    `AdaptiveConfig.max_fix_jump_m` (0.15 m) of the filter. Chosen offline on apartment 1's
    final state (0.05 m: centre error median 2.6 cm, 0.1 m: 1.9, 0.2 m: 1.7 with the block
    that slides without priors at 0.2 m already pulling its tail), held out on four missions."""
    min_points: int = 30
    """A free photo observing fewer tracks' points than this is held where it is: too few
    views to place it better than its fix did (a PnP fix needs `min_inliers`, 12)."""
    min_shared_points: int = 15
    """Two free photos sharing this many points are one block; a block whose photos share fewer
    points than this with the held photos is held (nothing but the priors would place it).
    A count of matches (a PnP fix needs `min_inliers`, 12), not a scene's size; chosen with
    `min_points` on apartment 1's final state, held out on four missions (`BundleConfig`)."""
    loss_scale_px: float = 1.0
    """Scale of the Cauchy loss on reprojection errors (pixels): SIFT's localisation, about a
    pixel at any image size, as in `ibr.proxy.refine.RefineConfig.loss_scale_px`."""
    max_iterations: int = 10
    """Most iterations of the solver (Levenberg-Marquardt from the fixes' poses, which are a
    few centimetres off: it gets there in a few steps). Offline on the final states of four
    missions, with the matches cached as in a mission, 10 iterations left the adjusted centres
    as 100 did (median / p95 within 0.1 cm: office 0 1.9 / 3.0 -> 1.9 / 3.1 cm, apartments 1, 3
    and 8 the same) in a fifth to a third of the time (office 0, 309 photos: 12.0 -> 2.3 s,
    apartment 1 6.1 -> 1.4 s). The sweep of the issue's worlds (`AdaptiveConfig.bundle`) ran
    with 100; missions with 10 have not been swept."""


class PairMatches:
    """SIFT matches between photos, matched once per mission: they do not depend on the poses
    (the adjustment changes those), while triangulating them again is cheap. `features(i)`
    gives photo i's features; `ratio` is Lowe's ratio test's."""

    def __init__(self, features: Callable[[int], Features], ratio: float):
        self.features, self.ratio = features, ratio
        self._matches: dict[tuple[int, int], np.ndarray] = {}

    def __call__(self, i: int, j: int) -> np.ndarray:
        """(M, 2) indices of matching features of photos i and j."""
        if (i, j) not in self._matches:
            self._matches[(i, j)] = match_features(self.features(i), self.features(j), self.ratio)
        return self._matches[(i, j)]


@dataclass
class ViewTracks:
    """Multi-view tracks: `points` (N, 3) metres, and each observation's `point` (O,),
    `photo` (O,) and `feature` (O,) index."""

    points: np.ndarray
    point: np.ndarray
    photo: np.ndarray
    feature: np.ndarray


def view_tracks(cameras: dict[int, Camera], features: Callable[[int], Features], matches: PairMatches,
                cfg: TriangulationConfig) -> ViewTracks:
    """The `stereo_pairs` of `cameras` {photo: Camera} matched and triangulated with the poses
    held (`triangulate_matches`, its epipolar and reprojection checks), and the features they
    join linked into tracks (connected components of the matches). A track holding two
    features of one photo is dropped (a wrong match joined two places); a track's point
    starts at the mean of its pairs' points."""
    order = np.array(sorted(cameras))
    pairs = order[stereo_pairs([cameras[i] for i in order], cfg.neighbours)] if len(order) else np.zeros((0, 2), int)
    starts = np.cumsum([0] + [len(features(int(i)).uv) for i in order])
    offset, n = dict(zip(order.tolist(), starts[:-1].tolist())), int(starts[-1])
    a_node, b_node, xyz = [], [], []
    for i, j in pairs.tolist():
        P, m = triangulate_matches(cameras[i], cameras[j], features(i), features(j), cfg, matches(i, j))
        a_node.append(offset[i] + m[:, 0])
        b_node.append(offset[j] + m[:, 1])
        xyz.append(P)
    if not xyz or sum(len(p) for p in xyz) == 0:
        return ViewTracks(np.zeros((0, 3)), *(np.zeros(0, int),) * 3)
    a_node, b_node, xyz = np.concatenate(a_node), np.concatenate(b_node), np.concatenate(xyz)
    graph = sp.coo_matrix((np.ones(len(a_node)), (a_node, b_node)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    nodes = np.unique(np.r_[a_node, b_node])
    slot = np.searchsorted(starts, nodes, side="right") - 1
    photo_of = order[slot]
    track = label[nodes]
    n_tracks = label.max() + 1
    views = np.bincount(np.unique(np.c_[track, photo_of], axis=0)[:, 0], minlength=n_tracks)
    keep = (views == np.bincount(track, minlength=n_tracks))[track]  # no photo twice in a track
    ids, point = np.unique(track[keep], return_inverse=True)
    sums, counts = np.zeros((n_tracks, 3)), np.zeros(n_tracks)
    np.add.at(sums, label[a_node], xyz)
    np.add.at(counts, label[a_node], 1)
    points = sums[ids] / counts[ids, None]
    return ViewTracks(points, point, photo_of[keep], nodes[keep] - starts[slot[keep]])


@dataclass
class Adjustment:
    """What `adjust_grown` did: `cameras` {photo: Camera} the adjusted free photos; `held`
    how many photos stayed as they were (the first map's and those too weakly placed);
    `points` the tracks adjusted with them; `error_px` the median reprojection error
    before and after (pixels, `_median_error_px`); `moved_m` {photo: how far its centre moved (m)}."""

    cameras: dict[int, Camera]
    held: int
    points: int
    error_px: tuple[float, float]
    moved_m: dict[int, float]


def adjust_grown(cameras: dict[int, Camera], held: set[int], prior: dict[int, np.ndarray],
                 features: Callable[[int], Features], matches: PairMatches, cfg: TriangulationConfig,
                 config: BundleConfig = BundleConfig()) -> Adjustment | str:
    """Bundle-adjust the photos of `cameras` {photo: Camera, world} not in `held` with their
    multi-view tracks (`view_tracks`), the `held` photos constant, each free photo's centre
    held to `prior` {photo: (3,) world m} by `position_sigma_m`. Free photos observing fewer
    than `min_points` points, or in a block that shares fewer than `min_shared_points` with the
    held photos (`_weakly_placed`), stay too.
    Returns the adjustment, or why nothing was adjusted (str): no free or no held photo,
    no tracks, or a solver that found no usable solution."""
    import pycolmap

    free = [i for i in sorted(cameras) if i not in held]
    if not free or not set(held) & set(cameras):
        return f"nothing to adjust ({len(free)} free photos, {len(set(held) & set(cameras))} held)"
    tracks = view_tracks(cameras, features, matches, cfg)
    if len(tracks.points) == 0:
        return "the photos share no tracks"
    rec, image_id = _reconstruction(cameras, features, tracks)
    still = _weakly_placed(rec, image_id, set(held), config)
    free = [i for i in free if i not in still]
    if not free:
        return f"every free photo is weakly placed ({len(still)}: < {config.min_points} points or no held neighbour)"
    ba = pycolmap.BundleAdjustmentConfig()
    for i, n in image_id.items():
        ba.add_image(n)
        if i not in free:
            ba.set_constant_rig_from_world_pose(rec.image(n).frame_id)
    priors = [pycolmap.PosePrior(corr_data_id=rec.image(image_id[i]).data_id, position=np.asarray(prior[i], float),
                                 position_covariance=np.eye(3) * config.position_sigma_m ** 2,
                                 coordinate_system=pycolmap.PosePriorCoordinateSystem.CARTESIAN) for i in free]
    options = pycolmap.BundleAdjustmentOptions(refine_focal_length=False, refine_principal_point=False,
                                               refine_extra_params=False)
    options.ceres.solver_options.max_num_iterations = config.max_iterations
    options.ceres.loss_function_type = pycolmap.LossFunctionType.CAUCHY
    options.ceres.loss_function_scale = config.loss_scale_px
    before = _median_error_px(rec)
    with colmap_errors_only():
        summary = pycolmap.create_pose_prior_bundle_adjuster(
            options, pycolmap.PosePriorBundleAdjustmentOptions(), ba, priors, rec).solve()
    if not summary.is_solution_usable():
        return f"the solver found no usable solution ({summary.termination_type})"
    adjusted = {}
    for i in free:
        T = np.eye(4)
        T[:3] = rec.image(image_id[i]).cam_from_world().matrix()
        adjusted[i] = cameras[i].with_pose(T)
    moved = {i: float(np.linalg.norm(adjusted[i].center - cameras[i].center)) for i in free}
    return Adjustment(adjusted, len(cameras) - len(free), len(tracks.points),
                      (before, _median_error_px(rec)), moved)


def _median_error_px(rec) -> float:
    """The median over points of each point's mean reprojection error (pixels): a wrong
    match joined into a track can leave a point far off in one view (the robust loss
    ignores it), which a mean would report."""
    rec.update_point_3d_errors()
    return float(np.median([p.error for p in rec.points3D.values()])) if rec.num_points3D() else 0.0


def _reconstruction(cameras: dict[int, Camera], features: Callable[[int], Features], tracks: ViewTracks):
    """A `pycolmap.Reconstruction` of the photos at their poses with every feature as a 2D
    point and the tracks as 3D points; and {photo: image id}. One intrinsics for all
    (the robot's camera)."""
    import pycolmap

    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(next(iter(cameras.values())).to_pycolmap(1))
    image_id = {}
    for n, i in enumerate(sorted(cameras), start=1):
        im = pycolmap.Image(name=f"{i:05d}", camera_id=1, image_id=n)
        im.points2D = pycolmap.Point2DList([pycolmap.Point2D(uv + 0.5) for uv in features(i).uv])
        rec.add_image_with_trivial_frame(im, pycolmap.Rigid3d(cameras[i].cam_from_world[:3, :]))
        image_id[i] = n
    order = np.argsort(tracks.point, kind="stable")
    bounds = np.searchsorted(tracks.point[order], np.arange(len(tracks.points) + 1))
    for k, xyz in enumerate(tracks.points):
        track = pycolmap.Track()
        for o in order[bounds[k]:bounds[k + 1]]:
            track.add_element(image_id[int(tracks.photo[o])], int(tracks.feature[o]))
        rec.add_point3D(xyz, track)
    return rec, image_id


def _weakly_placed(rec, image_id: dict[int, int], held: set[int], config: BundleConfig) -> set[int]:
    """The free photos the tracks place too weakly to adjust: those observing fewer than
    `min_points` points, and blocks of free photos (joined where two share
    `min_shared_points`) that together share fewer than `min_shared_points` points with the
    held photos: nothing but their priors would place them."""
    num = {i: rec.image(n).num_points3D for i, n in image_id.items()}
    free = sorted(i for i in image_id if i not in held and num[i] >= config.min_points)
    col = {image_id[i]: k for k, i in enumerate(free)}
    held_ids = {image_id[i] for i in held if i in image_id}
    rows, cols, by_held = [], [], []
    for p, point in enumerate(rec.points3D.values()):
        ids = [e.image_id for e in point.track.elements]
        by_held.append(any(i in held_ids for i in ids))
        for i in ids:
            if i in col:
                rows.append(p)
                cols.append(col[i])
    seen = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(rec.num_points3D(), len(free)))
    shared = (seen.T @ seen).tocoo()
    big = shared.data >= config.min_shared_points
    n_blocks, block = connected_components(sp.coo_matrix((np.ones(big.sum()), (shared.row[big], shared.col[big])),
                                                         shape=(len(free), len(free))), directed=False)
    in_block = seen @ sp.csr_matrix((np.ones(len(free)), (np.arange(len(free)), block)), shape=(len(free), n_blocks))
    with_held = np.asarray((in_block[np.flatnonzero(by_held)] > 0).sum(axis=0)).ravel()
    return ({i for i in image_id if i not in held and num[i] < config.min_points}
            | {i for k, i in enumerate(free) if with_held[block[k]] < config.min_shared_points})
