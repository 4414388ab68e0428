"""Where a camera of the Scenic Route Planner may be: the empty voxels Ve of the map
(Mendez et al., Sec. 3.1: "empty space the sensor can occupy") inside a height band and a
navigable floor region, and the collision check of the planners' edges against the map.

The navigable region stands in for the navigability a robot computes (the paper's Sec. 5
limits ground robots to SE(2)); every planner (scenic, PRM, RRT*) gets the same one.
Units: metres; poses are 4-DoF (x, y, z, yaw).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from explore.scenic.map import EMPTY, OCCUPIED, ScenicMap


@dataclass(frozen=True)
class Workspace:
    """navigable: shapely (Multi)Polygon on the floor (metres) a camera centre may be over;
    z_min, z_max: height band of camera centres (metres);
    clearance_m: an edge may pass no closer than this to an occupied voxel centre."""

    navigable: shapely.Geometry
    z_min: float
    z_max: float
    clearance_m: float = 0.15

    def contains(self, points: np.ndarray) -> np.ndarray:
        """(N,) whether positions (N, 3) lie in the band over the navigable region."""
        p = np.atleast_2d(points)
        return ((p[:, 2] >= self.z_min) & (p[:, 2] <= self.z_max)
                & shapely.contains_xy(self.navigable, p[:, 0], p[:, 1]))


def candidate_voxels(vmap: ScenicMap, ws: Workspace) -> np.ndarray:
    """(M, 3) centres of the empty voxels (Ve) a camera may occupy, metres."""
    centres = vmap.voxel_centres(np.argwhere(vmap.state == EMPTY))
    return centres[ws.contains(centres)]


def uniform_positions(vmap: ScenicMap, ws: Workspace, n: int, rng: np.random.Generator) -> np.ndarray:
    """n positions (n, 3) drawn uniformly from the candidate voxels (uniform inside each);
    from the whole workspace box over the navigable region when Ve has no candidate yet."""
    centres = candidate_voxels(vmap, ws)
    if len(centres):
        pick = centres[rng.integers(len(centres), size=n)]
        p = pick + rng.uniform(-0.5, 0.5, (n, 3)) * vmap.voxel_m
        p[:, 2] = np.clip(p[:, 2], ws.z_min, ws.z_max)
        inside = ws.contains(p)
        return np.where(inside[:, None], p, pick)
    lo, hi = np.array(ws.navigable.bounds[:2]), np.array(ws.navigable.bounds[2:])
    out = np.zeros((0, 3))
    while len(out) < n:
        p = np.c_[rng.uniform(lo, hi, (4 * n, 2)), rng.uniform(ws.z_min, ws.z_max, 4 * n)]
        out = np.r_[out, p[ws.contains(p)]]
    return out[:n]


def positions_free(vmap: ScenicMap, ws: Workspace, points: np.ndarray) -> np.ndarray:
    """(N,) whether positions (N, 3) are in the workspace and clearance_m from occupied voxels."""
    p = np.atleast_2d(points)[:, :3]
    occ = _occupied_dilated(vmap, ws.clearance_m)
    ijk, inside = vmap.voxel_of(p)
    ijk = np.where(inside[:, None], ijk, 0)
    return ws.contains(p) & ~(inside & occ[ijk[:, 0], ijk[:, 1], ijk[:, 2]])


def segments_free(vmap: ScenicMap, ws: Workspace, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(E,) whether each straight segment a -> b (positions (E, 3)) stays in the workspace and
    at least clearance_m from occupied voxels; all segments sampled every half voxel at once.
    A start that is itself within the clearance (a camera that stood near geometry when it
    was mapped) may still leave: hits within clearance_m + one voxel of it are ignored."""
    a, b = np.atleast_2d(a)[:, :3], np.atleast_2d(b)[:, :3]
    length = np.linalg.norm(b - a, axis=1)
    n = int(np.ceil(length.max() / (0.5 * vmap.voxel_m))) + 1 if len(a) else 1
    s = np.linspace(0.0, 1.0, n)
    pts = a[:, None, :] + s[None, :, None] * (b - a)[:, None, :]          # (E, n, 3)
    flat = pts.reshape(-1, 3)
    ok = ws.contains(flat).reshape(len(a), n).all(axis=1)
    hit = ~positions_free(vmap, ws, flat).reshape(len(a), n)
    hit &= ~hit[:, :1] | ((s[None, :] * length[:, None]) > ws.clearance_m + vmap.voxel_m)
    return ok & ~hit.any(axis=1)


def _occupied_dilated(vmap: ScenicMap, clearance_m: float) -> np.ndarray:
    """Occupied voxels grown by clearance_m (bool grid), cached on the map until it changes."""
    def dilate():
        from scipy import ndimage

        occ = vmap.state == OCCUPIED
        r = int(np.ceil(clearance_m / vmap.voxel_m))
        if r > 0 and occ.any():
            occ = ndimage.binary_dilation(occ, ndimage.generate_binary_structure(3, 1), iterations=r)
        return occ
    return vmap.cached(("dilated", clearance_m), dilate)
