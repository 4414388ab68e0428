"""Next-Best-View cost of the Scenic Route Planner (Mendez et al., Sec. 3.2.2, after Mendez
et al.'s NBV cost): cast a set of rays S_r from a candidate pose through its image plane into
the voxel map. A ray that meets an occupied voxel v ∈ Vo costs the average over the voxel's
points p ∈ P_v of

    φ(r, p) = exp(-‖λ_p e_p × r‖)                                   (2)
    ψ(r, v) = 1/|P_v| Σ_p φ(r, p)                                    (3)

with λ_p, e_p the largest eigenvalue and eigenvector of the point's covariance Σ_p; φ is
lowest for rays perpendicular to e_p, where a new view shrinks the point's uncertainty most.
A ray that meets no occupied voxel (it reaches an unobserved voxel or leaves the map) costs
γ ∈ [0, 1]: γ = 0 biases the cost space to exploration, γ = 1 to refinement. The view cost
is the mean over the rays (4). One addition to the paper: occupied voxels nearer than a
near limit `min_range_m` cost 1 (see NBVConfig).

λ_p is in m²; `eigen_scale` (1/m²) makes it dimensionless before the exponential (the paper
leaves the unit implicit). Rays are traversed through the voxels by marching every half
voxel, all rays of a batch of poses in one array (no loop per ray), a block of samples at a
time with the rays that already stopped dropping out; rays pass through empty voxels and
stop at the first non-empty one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from explore.scenic.map import EMPTY, OCCUPIED, ScenicMap
from explore.scenic.pose import CameraModel, world_from_cam_rotations


@dataclass(frozen=True)
class NBVConfig:
    gamma: float = 0.7
    """Cost of a ray that meets no occupied voxel: 0 = explore, 1 = refine (paper: 0.7)."""
    ray_cols: int = 16
    """Rays cast across the image width."""
    ray_rows: int = 12
    """Rays cast down the image height."""
    max_range_m: float = 12.0
    """Rays stop after this distance (metres); a ray that gets there costs γ."""
    eigen_scale: float = 100.0
    """Multiplies λ_p (m^2) to make it dimensionless: 1 / (0.1 m)^2 by default, the scale of
    the σ of a fresh two-view point at a few metres."""
    min_range_m: float = 1.0
    """Near limit (metres): a ray whose first occupied voxel is nearer than this costs 1, as
    a stereo pair cannot reconstruct geometry that close (its two views barely overlap at
    the planner's step). Not in the paper (its poses snap to a recorded dataset, which keeps
    them off the walls); 0 turns it off."""
    poses_per_chunk: int = 128
    """Poses whose rays are marched in one array (bounds memory)."""


def camera_rays(model: CameraModel, cols: int, rows: int) -> np.ndarray:
    """(R, 3) unit ray directions in camera axes through a cols x rows grid of pixels."""
    u = (np.arange(cols) + 0.5) * model.width / cols - 0.5
    v = (np.arange(rows) + 0.5) * model.height / rows - 0.5
    uu, vv = np.meshgrid(u, v)
    pix = np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)], -1)
    d = pix @ np.linalg.inv(model.K).T
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def pose_rays(poses: np.ndarray, model: CameraModel, config: NBVConfig) -> np.ndarray:
    """(P, R, 3) world unit rays S_r of 4-DoF poses (P, 4)."""
    R = world_from_cam_rotations(poses[:, 3], model.pitch_rad)            # (P, 3, 3)
    return np.einsum("pij,rj->pri", R, camera_rays(model, config.ray_cols, config.ray_rows))


def first_occupied(vmap: ScenicMap, origins: np.ndarray, rays: np.ndarray,
                   max_range_m: float, block: int = 24) -> np.ndarray:
    """Flat index of the occupied voxel each ray meets first (P, R), or -1 when the ray
    first meets an unobserved voxel, leaves the map or runs out of range. origins (P, 3).
    Rays march every half voxel, `block` samples at a time for all still-active rays at
    once; rays that stopped drop out of the next block."""
    P, R = rays.shape[:2]
    o = np.repeat(origins, R, axis=0)
    d = rays.reshape(-1, 3)
    out = np.full(P * R, -1, dtype=np.int64)
    active = np.arange(P * R)
    step = 0.5 * vmap.voxel_m
    shape = np.array(vmap.state.shape)
    flat_state = vmap.state.ravel()
    strides = np.array([shape[1] * shape[2], shape[2], 1])
    for t0 in np.arange(0.5 * step, max_range_m, block * step):
        if len(active) == 0:
            break
        t = t0 + step * np.arange(block)
        t = t[t < max_range_m]
        pts = (o[active, None, :] + d[active, None, :] * t[:, None] - vmap.origin) / vmap.voxel_m
        ijk = np.floor(pts).astype(np.int64)                              # (A, B, 3)
        inside = np.all((ijk >= 0) & (ijk < shape), axis=-1)
        flat = np.where(inside, ijk @ strides, 0)
        state = np.where(inside, flat_state[flat], -1)
        stop = state != EMPTY
        ever = stop.any(axis=1)
        first = np.argmax(stop, axis=1)
        rows = np.flatnonzero(ever)
        hit = state[rows, first[rows]] == OCCUPIED
        out[active[rows[hit]]] = flat[rows[hit], first[rows[hit]]]
        active = active[~ever]
    return out.reshape(P, R)


def point_cost(lam: np.ndarray, e: np.ndarray, r: np.ndarray, eigen_scale: float = 1.0) -> np.ndarray:
    """φ(r, p) = exp(-‖λ_p e_p × r‖), eq. (2); lam (N,) m^2, e (N, 3), r (N, 3) unit."""
    return np.exp(-np.linalg.norm(eigen_scale * lam[:, None] * np.cross(e, r), axis=1))


def ray_costs(vmap: ScenicMap, hit: np.ndarray, rays: np.ndarray, config: NBVConfig) -> np.ndarray:
    """Cost of each ray (M,): ψ(r, v) of eq. (3) for rays whose hit (M,) is a voxel, γ else."""
    cost = np.full(len(hit), config.gamma, dtype=np.float64)
    if len(vmap) == 0:
        return cost
    order, start, count = vmap.points_by_voxel()
    n = np.where(hit >= 0, count[np.maximum(hit, 0)], 0)
    rows = np.flatnonzero(n)
    if len(rows) == 0:
        return cost
    reps = n[rows]
    ray_id = np.repeat(np.arange(len(rows)), reps)
    offset = np.arange(reps.sum()) - np.repeat(np.cumsum(reps) - reps, reps)
    pts = order[start[hit[rows]][ray_id] + offset]
    lam, e = vmap.principal_axes()
    phi = point_cost(lam[pts], e[pts], rays[rows][ray_id], config.eigen_scale)
    cost[rows] = np.bincount(ray_id, phi, minlength=len(rows)) / reps
    return cost


def too_near(vmap: ScenicMap, origins: np.ndarray, hit: np.ndarray, min_range_m: float) -> np.ndarray:
    """(P, R) whether the occupied voxel each ray hits (flat index, -1 none) has its centre
    nearer than min_range_m to the ray's origin (P, 3)."""
    if min_range_m <= 0:
        return np.zeros(hit.shape, bool)
    centres = vmap.voxel_centres(np.stack(np.unravel_index(np.maximum(hit, 0), vmap.state.shape), -1))
    return (hit >= 0) & (np.linalg.norm(centres - origins[:, None, :], axis=-1) < min_range_m)


def view_costs(vmap: ScenicMap, poses: np.ndarray, model: CameraModel,
               config: NBVConfig = NBVConfig()) -> np.ndarray:
    """C_view (P,) in [0, 1] of 4-DoF poses (P, 4), eq. (4): the mean ray cost."""
    poses = np.atleast_2d(np.asarray(poses, float))
    out = np.empty(len(poses))
    for a in range(0, len(poses), config.poses_per_chunk):   # chunks of poses, not rays
        chunk = poses[a:a + config.poses_per_chunk]
        rays = pose_rays(chunk, model, config)
        hit = first_occupied(vmap, chunk[:, :3], rays, config.max_range_m)
        c = ray_costs(vmap, hit.ravel(), rays.reshape(-1, 3), config).reshape(hit.shape)
        c[too_near(vmap, chunk[:, :3], hit, config.min_range_m)] = 1.0
        out[a:a + len(chunk)] = c.mean(axis=1)
    return out
