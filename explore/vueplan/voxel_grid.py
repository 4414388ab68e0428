"""The voxel space of VuePlan Phase II (Blaer & Allen 2009, Sec. 3.2.1): every voxel is
*unseen*, *seen-empty* or *seen-occupied*. A scan is inserted by marking the voxels that
hold a returned point occupied (even if an earlier scan called them empty) and tracing a
ray from each point back to the scanner that turns the *unseen* voxels it crosses into
*seen-empty*; occupied voxels it passes stay occupied (they are only partly filled).
Beams with no return carve the whole beam up to the scanner's maximum range (an addition
to the paper, whose scanner data we do not have: without it the open sky would stay
*unseen* forever).

Ray traversal is Amanatides & Woo's voxel walk, vectorised over all rays at once (one
numpy step advances every active ray by one voxel); `segments_clear` adds a distance-field
skip so rays cross open space in a few long steps.

Frames and units: world metres, z up; a grid has its lower corner at `origin` and voxel
(i, j, k) spans origin + voxel_m * [i, i+1) x [j, j+1) x [k, k+1). "Voxel coordinates"
are world coordinates shifted by origin and divided by voxel_m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

UNSEEN, EMPTY, OCCUPIED = np.int8(0), np.int8(1), np.int8(2)
FACE_NORMALS = np.array([[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1]])


@dataclass
class VoxelGrid:
    """origin (3,) metres: the grid's lower corner; voxel_m: edge length (metres);
    state (nx, ny, nz) int8: UNSEEN / EMPTY / OCCUPIED."""

    origin: np.ndarray
    voxel_m: float
    state: np.ndarray

    @classmethod
    def covering(cls, lo, hi, voxel_m: float) -> "VoxelGrid":
        """An all-unseen grid whose voxels cover the box lo..hi (3,) metres."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        shape = np.maximum(1, np.ceil((hi - lo) / voxel_m - 1e-9).astype(int))
        return cls(lo, float(voxel_m), np.zeros(tuple(shape), np.int8))

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.state.shape

    def to_voxel(self, xyz: np.ndarray) -> np.ndarray:
        """World points (N, 3) -> voxel coordinates (N, 3) float."""
        return (np.asarray(xyz, float) - self.origin) / self.voxel_m

    def centers(self, idx: np.ndarray) -> np.ndarray:
        """World centres (N, 3) of voxels idx (N, 3)."""
        return self.origin + (np.asarray(idx) + 0.5) * self.voxel_m

    def inside(self, idx: np.ndarray) -> np.ndarray:
        return np.all((idx >= 0) & (idx < np.array(self.shape)), axis=-1)

    def counts(self) -> dict[str, int]:
        s = self.state
        return {"seen_occupied": int((s == OCCUPIED).sum()), "seen_empty": int((s == EMPTY).sum()),
                "unseen": int((s == UNSEEN).sum())}


# ---------------------------------------------------------------- ray walking

def clip_to_box(p0: np.ndarray, p1: np.ndarray, shape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Slab-clip segments p0 -> p1 (R, 3) (voxel coordinates) to the box [0, shape].
    Returns t_enter, t_exit (R,) in [0, 1] and a mask of segments that touch the box."""
    d = p1 - p0
    hi = np.asarray(shape, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = (0.0 - p0) / d, (hi - p0) / d
    inside_axis = (p0 >= 0) & (p0 <= hi)
    tlo = np.where(d == 0, np.where(inside_axis, -np.inf, np.inf), np.minimum(ta, tb))
    thi = np.where(d == 0, np.where(inside_axis, np.inf, -np.inf), np.maximum(ta, tb))
    t0, t1 = np.maximum(tlo.max(axis=1), 0.0), np.minimum(thi.min(axis=1), 1.0)
    return t0, t1, t0 <= t1


class _Walk:
    """Amanatides-Woo state of R rays p0 + t (p1 - p0), t in [t, t_end], voxel coordinates."""

    def __init__(self, p0: np.ndarray, p1: np.ndarray, t: np.ndarray, t_end: np.ndarray):
        self.p0, self.d, self.t_end = p0, p1 - p0, t_end
        self.step = np.where(self.d > 0, 1, -1).astype(np.int64)
        with np.errstate(divide="ignore"):
            self.t_delta = np.where(self.d != 0, 1.0 / np.abs(self.d), np.inf)
        self.restart(t)

    def restart(self, t: np.ndarray, rows: slice | np.ndarray = slice(None)) -> None:
        """Re-enter the walk at parameter t for rays `rows` (or all)."""
        if isinstance(rows, slice):
            self.t = t.copy()
            p0, d, step = self.p0, self.d, self.step
        else:
            self.t[rows] = t
            p0, d, step = self.p0[rows], self.d[rows], self.step[rows]
        idx = np.floor(p0 + t[:, None] * d + 1e-9 * np.sign(d)).astype(np.int64)
        with np.errstate(divide="ignore", invalid="ignore"):
            tmax = np.where(d != 0, (idx + (step > 0) - p0) / d, np.inf)
        if isinstance(rows, slice):
            self.idx, self.t_max = idx, tmax
        else:
            self.idx[rows], self.t_max[rows] = idx, tmax

    def advance(self) -> np.ndarray:
        """Move every ray into its next voxel; returns the rays still before t_end."""
        axis = np.argmin(self.t_max, axis=1)
        r = np.arange(len(axis))
        self.t = self.t_max[r, axis]
        self.idx[r, axis] += self.step[r, axis]
        self.t_max[r, axis] += self.t_delta[r, axis]
        return self.t < self.t_end

    def take(self, keep: np.ndarray) -> None:
        """Keep only rays `keep` (bool mask)."""
        for name in ("p0", "d", "t_end", "step", "t_delta", "t", "idx", "t_max"):
            setattr(self, name, getattr(self, name)[keep])


def ray_voxels(shape, p0: np.ndarray, p1: np.ndarray, skip_first: bool = False
               ) -> tuple[np.ndarray, np.ndarray]:
    """Every in-grid voxel crossed by segments p0 -> p1 (R, 3) (voxel coordinates), as
    (ray index (K,), voxel index (K, 3)); skip_first leaves out the voxel holding p0."""
    t0, t1, hit = clip_to_box(p0, p1, shape)
    rays = np.flatnonzero(hit)
    w = _Walk(p0[rays], p1[rays], t0[rays], t1[rays])
    dims = np.asarray(shape)
    out_r, out_i = [], []
    first_voxel = np.floor(p0[rays] + 1e-9 * np.sign(p1[rays] - p0[rays])).astype(np.int64)
    while len(rays):
        ok = np.all((w.idx >= 0) & (w.idx < dims), axis=1)
        if skip_first:
            ok &= ~np.all(w.idx == first_voxel, axis=1)
        out_r.append(rays[ok])
        out_i.append(w.idx[ok].copy())
        active = w.advance()
        rays, first_voxel = rays[active], first_voxel[active]
        w.take(active)
    if not out_r:
        return np.empty(0, int), np.empty((0, 3), int)
    return np.concatenate(out_r), np.concatenate(out_i)


def blocker_distance(blocked: np.ndarray) -> np.ndarray:
    """(nx, ny, nz) float32: distance in voxels from each voxel centre to the nearest
    blocked voxel's centre (0 on blocked voxels), outside the grid counting as open."""
    if not blocked.any():
        return np.full(blocked.shape, np.float32(np.sum(np.square(blocked.shape)) ** 0.5 + 2))
    return ndimage.distance_transform_edt(~blocked).astype(np.float32)


def segments_clear(blocked: np.ndarray, p0: np.ndarray, p1: np.ndarray,
                   distance: np.ndarray | None = None) -> np.ndarray:
    """(R,) bool: true where segment p0 -> p1 (R, 3) (voxel coordinates) crosses no
    blocked voxel other than the one holding p0 (parts outside the grid are open).
    `distance` (from `blocker_distance`) lets a ray at a voxel whose nearest blocker is D
    voxels away jump D - sqrt(3) voxels at once: no point that close lies in a blocked
    voxel, so the answer is the plain voxel walk's (up to rays that pass exactly through a
    voxel edge or corner, where the two may break the tie differently)."""
    clear = np.ones(len(p0), bool)
    t0, t1, hit = clip_to_box(p0, p1, blocked.shape)
    rays = np.flatnonzero(hit)
    w = _Walk(p0[rays], p1[rays], t0[rays], t1[rays])
    # one voxel of open padding: a clipped ray never leaves [-1, n], so no bounds checks
    pad_block = np.pad(blocked, 1).ravel()
    pad_dist = None if distance is None else np.pad(distance, 1).ravel()
    strides = np.array([(blocked.shape[1] + 2) * (blocked.shape[2] + 2), blocked.shape[2] + 2, 1])
    start = (np.floor(p0[rays] + 1e-9 * np.sign(p1[rays] - p0[rays])).astype(np.int64) + 1) @ strides
    length = np.linalg.norm(w.d, axis=1)
    dims = np.asarray(blocked.shape)
    while len(rays):
        flat = (w.idx + 1) @ strides
        hit_now = pad_block[flat] & (flat != start)
        clear[rays[hit_now]] = False
        active = ~hit_now & w.advance()
        if pad_dist is not None:  # jump across open space from the voxel just entered
            D = pad_dist[(np.clip(w.idx, -1, dims) + 1) @ strides]
            rows = np.flatnonzero(active & (D >= 3.0))
            if len(rows):
                tj = np.minimum(w.t[rows] + (D[rows] - np.sqrt(3.0)) / length[rows], w.t_end[rows])
                w.restart(tj, rows)
                active[rows] = tj < w.t_end[rows]
        rays, start, length = rays[active], start[active], length[active]
        w.take(active)
    return clear


# ---------------------------------------------------------------- scan insertion

def insert_points(grid: VoxelGrid, points: np.ndarray) -> None:
    """Mark the voxels holding world points (N, 3) seen-occupied."""
    idx = np.floor(grid.to_voxel(points)).astype(np.int64)
    idx = idx[grid.inside(idx)]
    grid.state[idx[:, 0], idx[:, 1], idx[:, 2]] = OCCUPIED


def carve(grid: VoxelGrid, starts: np.ndarray, ends: np.ndarray, skip_first: bool,
          chunk: int = 50_000) -> None:
    """Turn unseen voxels crossed by world segments starts -> ends (R, 3) into seen-empty;
    occupied voxels are passed through unchanged."""
    a, b = grid.to_voxel(starts), grid.to_voxel(ends)
    for s in range(0, len(a), chunk):
        _, idx = ray_voxels(grid.shape, a[s:s + chunk], b[s:s + chunk], skip_first)
        flat = np.unique(np.ravel_multi_index(idx.T, grid.shape))
        st = grid.state.reshape(-1)
        st[flat[st[flat] == UNSEEN]] = EMPTY


def insert_scan(grid: VoxelGrid, origin: np.ndarray, points: np.ndarray,
                no_return: np.ndarray | None = None, max_range_m: float = 0.0) -> None:
    """Insert one scan (Sec. 3.2.1): points (N, 3) mark occupied, then rays from each point
    back to `origin` (3,) carve unseen voxels to seen-empty (not the point's own voxel);
    no-return beam directions (M, 3) carve from origin out to max_range_m."""
    origin = np.asarray(origin, float)
    insert_points(grid, points)
    carve(grid, points, np.broadcast_to(origin, points.shape), skip_first=True)
    if no_return is not None and len(no_return) and max_range_m > 0:
        carve(grid, np.broadcast_to(origin, no_return.shape), origin + max_range_m * no_return,
              skip_first=False)


# ---------------------------------------------------------------- frontier

def boundary_unseen(grid: VoxelGrid) -> tuple[np.ndarray, np.ndarray]:
    """The *boundary unseen* voxels (unseen with at least one seen-empty face neighbour):
    indices (m, 3) and exposed-face flags (m, 6) in FACE_NORMALS order (true where the
    neighbour across that face is seen-empty)."""
    s = grid.state
    empty = np.pad(s == EMPTY, 1)
    faces = []
    for n in FACE_NORMALS:
        sl = tuple(slice(1 + k, s.shape[a] + 1 + k) for a, k in enumerate(n))
        faces.append(empty[sl])
    faces = np.stack(faces, axis=-1)  # (nx, ny, nz, 6)
    mask = (s == UNSEEN) & faces.any(axis=-1)
    idx = np.argwhere(mask)
    return idx, faces[mask]
