"""VuePlan Phase II: 3-D next-best-view planning on a voxel space (Blaer & Allen, "View
Planning and Automated Data Acquisition for Three-Dimensional Modeling of Complex Sites",
J. Field Robotics 2009, Sec. 3.2, Algorithm 2).

    procedure 3DPLAN(C, P, threshold)
      initialise voxel space from C                        -> voxel_grid.insert_scan
      U <- unseen voxels with a seen-empty neighbour        -> voxel_grid.boundary_unseen
      loop
        for all potential views p in P: count members of U visible from p  -> count_visible
        if count(p) < threshold: break                     -> threshold = stop_fraction x |U|
        acquire scan at p with largest count; merge into C; update voxels; recompute U
      return C                                              -> plan_phase2

Potential views P are the centres of the ground-layer voxels inside the 2-D map's free
space (every `candidate_stride`-th one), with the scanner at `sensor_height_m`, whose
voxel is seen-empty. A boundary-unseen voxel u counts for view p when the ray from u's
centre to p (Sec. 3.2.2-3.2.4)
  * is within the scanner's min/max range,
  * meets the normal of one of u's exposed faces (the face towards a seen-empty
    neighbour, the estimated surface normal) within the maximum grazing angle; this also
    prunes every view in the half-space behind the exposed faces,
  * crosses no seen-occupied and no unseen voxel (besides u itself).
The test runs for all (u, p) pairs at once, never a Python loop per ray, with one of three
ray backends: "gl" (the default: range, grazing and a voxel walk with a distance-field skip
for every pair in one compute pass, `voxel_visibility.GLVoxelVisibility`; on large grids a
first pass ranks the views on a subsample of the boundary voxels and a second counts the
best few exactly, see `Phase2Config.gl_exact_pairs`), "embree" (the
exact reference: after the range / grazing pruning in numpy, one Embree occlusion query per
ray against the mesh of blocked/open voxel faces, `voxel_occlusion.VoxelOccluder`) or
"walk" (the numpy voxel walk vectorised over the rays, `voxel_grid.segments_clear`). They
agree except for rays through a voxel edge or corner (ties), which they may break differently.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import shapely
import trimesh
from scipy.spatial import cKDTree

from explore.vueplan.voxel_grid import (EMPTY, FACE_NORMALS, OCCUPIED, UNSEEN, VoxelGrid, blocker_distance,
                                boundary_unseen, insert_scan, segments_clear)
from explore.vueplan.voxel_occlusion import VoxelOccluder
from explore.vueplan.voxel_visibility import GLVoxelVisibility

RAY_BACKENDS = ("gl", "embree", "walk")


@dataclass(frozen=True)
class Phase2Config:
    """Settings of the 3-D next-best-view planner."""

    min_range_m: float = 0.5
    """Scanner minimum range (metres)."""
    max_range_m: float = 60.0
    """Scanner maximum range (metres)."""
    max_grazing_rad: float = np.deg2rad(70.0)
    """Largest angle between a ray and the exposed face's normal."""
    stop_fraction: float = 0.02
    """Stop when the best view sees fewer boundary-unseen voxels than this fraction of the
    boundary-unseen voxels (the paper's threshold, relative so that it does not depend on
    the grid's size): the unseen boundary in sight of the potential views is exhausted."""
    max_views: int = 30
    """Stop after this many next-best views at most (a guard; the stop above ends a run)."""
    sensor_height_m: float = 1.6
    """Scanner height above the ground plane (metres)."""
    candidate_stride: int = 1
    """Use every n-th ground voxel (in x and y) as a potential view."""
    candidate_clearance_m: float = 0.3
    """Potential views stand at least this far from the 2-D map's obstacles (metres)."""
    pairs_per_chunk: int = 1_000_000
    """(voxel, view) rays tested per vectorised batch (memory bound)."""
    ray_backend: str = "gl"
    """Visibility test: "gl" (one compute pass over all pairs, voxel walk), "embree" (exact
    reference: compiled ray queries against the blocked voxel faces) or "walk" (numpy
    Amanatides-Woo walk with a distance-field skip)."""

    gl_exact_pairs: int = 4_000_000
    """gl backend: up to this many (voxel, view) pairs every view is counted exactly. Above
    it, the views are first ranked on every gl_estimate_stride-th boundary voxel (the count
    scaled up), and the gl_refine_views best of them counted exactly on all voxels; the NBV
    is the best of those (the other views keep their estimates)."""
    gl_estimate_stride: int = 8
    """gl backend: boundary-voxel subsample of the ranking pass (a stride in `boundary_unseen`
    order, which runs through the grid in x, y, z order, so the subsample is spread evenly)."""
    gl_refine_views: int = 32
    """gl backend: views re-counted exactly after the ranking pass."""

    def __post_init__(self):
        if min(self.gl_exact_pairs, self.gl_estimate_stride, self.gl_refine_views) < 1:
            raise ValueError("gl_exact_pairs, gl_estimate_stride and gl_refine_views must be >= 1")
        if self.ray_backend not in RAY_BACKENDS:
            raise ValueError(f"ray_backend must be one of {RAY_BACKENDS}, got {self.ray_backend!r}")
        if not 0 <= self.stop_fraction < 1:
            raise ValueError(f"stop_fraction must be in [0, 1), got {self.stop_fraction}")


def ground_candidates(grid: VoxelGrid, free_space: shapely.Geometry, cfg: Phase2Config) -> np.ndarray:
    """Potential views (P, 3) world metres: ground-voxel centres (every candidate_stride-th
    in x and y) inside the free space, at the sensor height."""
    nx, ny, _ = grid.shape
    i, j = np.meshgrid(np.arange(0, nx, cfg.candidate_stride), np.arange(0, ny, cfg.candidate_stride),
                       indexing="ij")
    xy = grid.origin[:2] + (np.c_[i.ravel(), j.ravel()] + 0.5) * grid.voxel_m
    region = free_space.buffer(-cfg.candidate_clearance_m) if cfg.candidate_clearance_m > 0 else free_space
    xy = xy[shapely.contains_xy(region, xy[:, 0], xy[:, 1])]
    return np.c_[xy, np.full(len(xy), cfg.sensor_height_m)]


def reachable_views(views: np.ndarray, free_space: shapely.Geometry, starts: np.ndarray,
                    clearance_m: float) -> np.ndarray:
    """(P,) bool: the potential views (P, 3) in a part of the free space (shrunk by
    clearance_m, as `ground_candidates`) that holds one of the start positions (S, 2) (the
    Phase I views the robot drives between); the other parts cannot be reached."""
    region = free_space.buffer(-clearance_m) if clearance_m > 0 else free_space
    parts = [g for g in getattr(region, "geoms", [region]) if not g.is_empty]
    keep = np.zeros(len(views), bool)
    for part in parts:
        if shapely.contains_xy(part.buffer(1e-9), starts[:, 0], starts[:, 1]).any():
            keep |= shapely.contains_xy(part, views[:, 0], views[:, 1])
    return keep


def usable_views(grid: VoxelGrid, views: np.ndarray) -> np.ndarray:
    """(P,) bool: the view's own voxel is seen-empty (a scanner cannot stand in unknown
    or occupied space)."""
    idx = np.floor(grid.to_voxel(views)).astype(int)
    ok = grid.inside(idx)
    c = np.clip(idx, 0, np.array(grid.shape) - 1)
    return ok & (grid.state[c[:, 0], c[:, 1], c[:, 2]] == EMPTY)


def exposed_face_projection(d: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(b, p) the largest projection of the rays d (b, p, 3) (voxel centre -> view) onto
    the outward normal of one of the voxel's exposed faces (b, 6) (FACE_NORMALS order);
    -inf where no face is exposed. Divided by the ray length it is the cosine of the
    grazing angle at the best face; negative behind every exposed face (the half-space
    pruning)."""
    best = np.full(d.shape[:2], -np.inf)
    for f, n in enumerate(FACE_NORMALS):
        a = int(np.flatnonzero(n)[0])
        proj = d[..., a] if n[a] > 0 else -d[..., a]
        np.maximum(best, np.where(faces[:, f, None], proj, -np.inf), out=best)
    return best


def count_visible(grid: VoxelGrid, views: np.ndarray, cfg: Phase2Config,
                  frontier: tuple[np.ndarray, np.ndarray] | None = None,
                  stats: dict | None = None) -> np.ndarray:
    """(P,) number of boundary-unseen voxels visible from each view (P, 3) world metres
    under the occlusion, range and grazing-angle constraints; 0 for unusable views.
    `stats`, when given, receives "pairs" (voxel, view pairs considered) and "rays"
    (rays tested for occlusion after the range / grazing / half-space pruning)."""
    idx, faces = boundary_unseen(grid) if frontier is None else frontier
    counts = np.zeros(len(views), np.int64)
    ok_view = np.flatnonzero(usable_views(grid, views))
    if len(idx) == 0 or len(ok_view) == 0:
        return counts
    blocked = grid.state != EMPTY  # occupied and unseen both block
    if cfg.ray_backend == "gl":
        counts[ok_view] = _count_gl(grid, blocked, idx, faces, views[ok_view], cfg, stats)
        return counts
    if cfg.ray_backend == "embree":
        occluder = VoxelOccluder(blocked)
        clear_fn = occluder.clear
    else:
        dist = blocker_distance(blocked)
        clear_fn = lambda a, b: segments_clear(blocked, a, b, dist)  # noqa: E731
    u_c = grid.centers(idx)                      # (m, 3)
    v_c = views[ok_view]                         # (p, 3)
    v_vox = grid.to_voxel(v_c)
    cos_max = np.cos(cfg.max_grazing_rad)
    block = max(1, cfg.pairs_per_chunk // len(v_c))
    for s in range(0, len(idx), block):
        d = v_c[None, :, :] - u_c[s:s + block, None, :]        # (b, p, 3)
        r = np.sqrt(np.einsum("bpk,bpk->bp", d, d))
        ok = (r >= cfg.min_range_m) & (r <= cfg.max_range_m)
        ok &= exposed_face_projection(d, faces[s:s + block]) >= cos_max * r
        ui, pj = np.nonzero(ok)
        if stats is not None:
            stats["pairs"] = stats.get("pairs", 0) + ok.size
            stats["rays"] = stats.get("rays", 0) + len(ui)
        if len(ui) == 0:
            continue
        clear = clear_fn(idx[s + ui] + 0.5, v_vox[pj])  # voxel coordinates
        counts[ok_view] += np.bincount(pj[clear], minlength=len(v_c))
    return counts


def _count_gl(grid: VoxelGrid, blocked: np.ndarray, idx: np.ndarray, faces: np.ndarray, views: np.ndarray,
              cfg: Phase2Config, stats: dict | None) -> np.ndarray:
    """`count_visible` on the GL pass: exact for every view up to cfg.gl_exact_pairs pairs,
    else ranked on a voxel subsample and exact for the best cfg.gl_refine_views views."""
    gl = _gl_counter()
    dist = blocker_distance(blocked)
    v_vox = grid.to_voxel(views)
    args = (grid.voxel_m, cfg.min_range_m, cfg.max_range_m, np.cos(cfg.max_grazing_rad))
    passes = []

    def run(sel_voxels, sel_views):
        c, rays = gl.count(dist, idx[sel_voxels], faces[sel_voxels], v_vox[sel_views], *args)
        passes.append((len(idx[sel_voxels]) * len(v_vox[sel_views]), rays))
        return c

    every = slice(None)
    if len(idx) * len(views) <= cfg.gl_exact_pairs or len(views) <= cfg.gl_refine_views:
        counts = run(every, every)
    else:
        stride = cfg.gl_estimate_stride
        counts = run(slice(None, None, stride), every) * stride
        top = np.argsort(-counts, kind="stable")[:cfg.gl_refine_views]
        counts[top] = run(every, top)
    if stats is not None:
        stats["pairs"] = stats.get("pairs", 0) + sum(p for p, _ in passes)
        stats["rays"] = stats.get("rays", 0) + sum(r for _, r in passes)
    return counts


@functools.cache
def _gl_counter() -> GLVoxelVisibility:
    """One compiled program per process (on the shared GL context)."""
    return GLVoxelVisibility()


def count_visible_per_ray(grid: VoxelGrid, views: np.ndarray, cfg: Phase2Config) -> np.ndarray:
    """Reference implementation for the benchmark: the same count, one Python-level voxel
    walk per (voxel, view) ray, no vectorisation and no distance skip."""
    idx, faces = boundary_unseen(grid)
    blocked = grid.state != EMPTY
    ok_view = usable_views(grid, views)
    counts = np.zeros(len(views), np.int64)
    cos_max = np.cos(cfg.max_grazing_rad)
    for u, f in zip(idx, faces):
        c = grid.centers(u[None])[0]
        for j, v in enumerate(views):
            if not ok_view[j]:
                continue
            d = v - c
            r = np.linalg.norm(d)
            if not (cfg.min_range_m <= r <= cfg.max_range_m):
                continue
            if max(float(FACE_NORMALS[k] @ d) / r for k in range(6) if f[k]) < cos_max:
                continue
            counts[j] += walk_one(blocked, grid.to_voxel(c[None])[0], grid.to_voxel(v[None])[0])
    return counts


def walk_one(blocked: np.ndarray, a: np.ndarray, b: np.ndarray) -> bool:
    """Scalar Amanatides-Woo walk from a to b (voxel coordinates); true if no blocked
    voxel except a's own is crossed."""
    d = b - a
    idx = np.floor(a).astype(int)
    start = idx.copy()
    step = np.where(d > 0, 1, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_max = np.where(d != 0, (idx + (step > 0) - a) / d, np.inf)
        t_delta = np.where(d != 0, 1 / np.abs(d), np.inf)
    dims = blocked.shape
    while True:
        if (idx != start).any() and all(0 <= idx[k] < dims[k] for k in range(3)) and blocked[tuple(idx)]:
            return False
        k = int(np.argmin(t_max))
        if t_max[k] >= 1:
            return True
        idx[k] += step[k]
        t_max[k] += t_delta[k]


# ---------------------------------------------------------------- evaluation

class SurfaceCoverage:
    """Fraction of the true surface acquired: `n` area-uniform samples of the ground-truth
    mesh; a sample is covered once a scan point lies within tol_m of it."""

    def __init__(self, mesh: trimesh.Trimesh, n: int, rng: np.random.Generator, tol_m: float = 0.25):
        area = mesh.area_faces
        face = rng.choice(len(area), n, p=area / area.sum())
        uv = rng.random((n, 2))
        flip = uv.sum(axis=1) > 1
        uv[flip] = 1 - uv[flip]
        tri = mesh.triangles[face]
        self.samples = tri[:, 0] + uv[:, :1] * (tri[:, 1] - tri[:, 0]) + uv[:, 1:] * (tri[:, 2] - tri[:, 0])
        self.covered = np.zeros(n, bool)
        self.tol_m = tol_m

    def in_sight(self, mesh: trimesh.Trimesh, views: np.ndarray, min_range_m: float, max_range_m: float,
                 views_per_batch: int = 64) -> np.ndarray:
        """(n,) bool: the samples a scanner at one of `views` (P, 3) could return, i.e. within
        [min_range_m, max_range_m] of it and with a clear line of sight on the true `mesh`
        (Embree occlusion queries; the ray stops tol_m short of the sample, the distance
        at which a scan point counts as covering it). The covered fraction cannot exceed
        the mean of this over views the robot can reach."""
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        scene = rtcore_scene.EmbreeScene(robust=True)
        TriangleMesh(scene=scene, vertices=np.asarray(mesh.vertices, np.float32),
                     indices=np.asarray(mesh.faces, np.int32))
        seen = np.zeros(len(self.samples), bool)
        for s in range(0, len(views), views_per_batch):
            todo = np.flatnonzero(~seen)
            if len(todo) == 0:
                break
            v = views[s:s + views_per_batch]
            d = self.samples[todo][None] - v[:, None]          # (b, t, 3)
            r = np.linalg.norm(d, axis=2)
            bi, ti = np.nonzero((r >= min_range_m) & (r <= max_range_m) & (r > self.tol_m))
            if len(bi) == 0:
                continue
            u = d[bi, ti] / r[bi, ti, None]
            hit = scene.run(v[bi].astype(np.float32), u.astype(np.float32),
                            dists=(r[bi, ti] - self.tol_m).astype(np.float32), query="OCCLUDED")
            seen[todo[np.unique(ti[hit < 0])]] = True
        return seen

    def add(self, points: np.ndarray) -> float:
        """Mark samples near the scan points (N, 3); returns the covered fraction."""
        if len(points):
            d, _ = cKDTree(points).query(self.samples[~self.covered], distance_upper_bound=self.tol_m)
            self.covered[np.flatnonzero(~self.covered)[np.isfinite(d)]] = True
        return self.fraction

    @property
    def fraction(self) -> float:
        return float(self.covered.mean())


# ---------------------------------------------------------------- Algorithm 2

@dataclass
class Phase2Row:
    """One row of the paper's Table I/II: the voxel counts at the end of a stage, the
    number of boundary-unseen voxels the next best view would see, the true-surface
    coverage and the seconds the NBV computation took. nbv: the chosen view (3,) or None."""

    seen_occupied: int
    unseen: int
    boundary_unseen: int
    visible_to_nbv: int
    surface_coverage: float
    seconds: float
    nbv: np.ndarray | None = field(default=None, repr=False)
    stop: str = ""
    """On the last row: "exhausted" (the best view sees fewer than stop_fraction of the
    boundary) or "max_views" (the guard); empty on the others."""

    def as_json(self) -> dict:
        return {"seen_occupied": self.seen_occupied, "unseen": self.unseen,
                "boundary_unseen": self.boundary_unseen, "visible_to_nbv": self.visible_to_nbv,
                "surface_coverage": self.surface_coverage, "seconds": self.seconds, "stop": self.stop}


def plan_phase2(grid: VoxelGrid, views: np.ndarray, acquire: Callable[[np.ndarray], object],
                cfg: Phase2Config, coverage: Callable[[], float] = lambda: float("nan"),
                on_row: Callable[[Phase2Row, np.ndarray], None] | None = None) -> list[Phase2Row]:
    """Algorithm 2 (3DPLAN) on a voxel grid that already holds the Phase I scans.
    views (P, 3) potential views; acquire(view) scans at a view and returns a Scan
    (origin, points, no_return, max_range_m), which is inserted into the grid; coverage()
    reports the current true-surface coverage. on_row(row, counts) is called per row
    (row.nbv is None on the last row: no view is acquired).
    Returns one row for the state after Phase I and after each NBV; the last row's
    visible_to_nbv is the count that fell below stop_fraction of its boundary-unseen voxels
    (or none is visible at all), or max_views was hit; its `stop` says which."""
    rows = []
    while True:
        t = time.perf_counter()
        frontier = boundary_unseen(grid)
        counts = count_visible(grid, views, cfg, frontier)
        best = int(np.argmax(counts)) if len(counts) else 0
        c = grid.counts()
        row = Phase2Row(c["seen_occupied"], c["unseen"], len(frontier[0]),
                        int(counts[best]) if len(counts) else 0, coverage(),
                        time.perf_counter() - t, views[best] if len(counts) else None)
        rows.append(row)
        if row.visible_to_nbv == 0 or row.visible_to_nbv < cfg.stop_fraction * row.boundary_unseen:
            row.stop = "exhausted"
        elif len(rows) > cfg.max_views:
            row.stop = "max_views"
        stop = bool(row.stop)
        if stop:
            row.nbv = None
        if on_row is not None:
            on_row(row, counts)
        if stop:
            return rows
        scan = acquire(views[best])
        insert_scan(grid, scan.origin, scan.points, scan.no_return, scan.max_range_m)


__all__ = ["EMPTY", "OCCUPIED", "UNSEEN", "RAY_BACKENDS", "Phase2Config", "Phase2Row", "SurfaceCoverage",
           "count_visible", "count_visible_per_ray", "ground_candidates", "plan_phase2", "reachable_views"]
