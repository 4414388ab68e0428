"""Free space and candidate goals for adaptive exploration (Foster, Wang & Grupen, "A
Mobile Robot for Autonomous Scene Capture and Rendering", Sec. IV-B, "Choosing a goal"):
"Intersecting the mesh with the plane defined by the camera positions yields a rough
approximation of the boundaries of the robot's space. We choose our goal locations from
a set of randomly-selected points within this boundary."

Frames: world metres, z up; free space is a shapely (Multi)Polygon in the xy plane;
candidate poses are SE(2) (x, y, theta) in metres and radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
import trimesh

from explore.floorplan import FloorPlanError, as_free_space
from ibr.errors import InputError


@dataclass(frozen=True)
class FreeSpaceConfig:
    seal_buffers_m: tuple[float, ...] = (0.05, 0.1, 0.2, 0.35)
    """Half-widths (metres) tried in turn for thickening the slice's segments into walls:
    a gap narrower than twice the buffer is sealed. The first that encloses most of the
    cameras wins."""
    hull_margin_m: float = 0.75
    """The cameras' convex hull grown by this much (metres) is always free space: the whole
    fallback when the slice is empty or no reading of it holds most of the cameras, part of
    the "closed" one (the robot stood there)."""


def slice_segments(mesh: trimesh.Trimesh, plane_z: float) -> np.ndarray:
    """(S, 2, 2) xy segments (metres) where `mesh` crosses the plane z = plane_z."""
    segs = trimesh.intersections.mesh_plane(mesh, plane_normal=(0.0, 0.0, 1.0),
                                            plane_origin=(0.0, 0.0, plane_z))
    return np.asarray(segs, dtype=np.float64).reshape(-1, 2, 3)[:, :, :2]


def free_space_from_slice(segments: np.ndarray, inside_xy: np.ndarray,
                          config: FreeSpaceConfig = FreeSpaceConfig()) -> tuple[shapely.Geometry, str]:
    """The free space bounded by slice segments (S, 2, 2) around the camera positions
    inside_xy (M, 2), and how it was found:

    - "sealed:<b>": the segments thickened by b metres (walls b thick on each side of the
      slice) split the plane; the faces holding cameras, when they do not reach the frame
      around everything (i.e. are enclosed) and hold most of the cameras, are the free
      space. Buffers from `config.seal_buffers_m` are tried smallest first, so small leaks
      of a rough Poisson mesh are sealed while a genuinely open side is not mistaken for
      closed.
    - "closed": no buffer encloses most of the cameras (the mesh is open on a side, e.g. where
      far or plain walls gave SfM no points): the slice is closed by its convex hull, i.e.
      the free space is the convex hull of the segments and of the cameras' grown hull
      (`config.hull_margin_m`), minus the thinnest walls, the part holding the cameras.
      The walls the map does know still bound it; only its open sides become straight.
    - "hull": the slice is empty, or neither reading above holds more than half of the
      cameras (`_holds_most`: the robot stood there): the cameras' convex hull grown by
      `config.hull_margin_m`.

    The free space excludes the thickened walls, so it lies a buffer inside the slice."""
    inside_xy = np.asarray(inside_xy, dtype=np.float64).reshape(-1, 2)
    if len(inside_xy) == 0 or not np.all(np.isfinite(inside_xy)):
        raise InputError("free space: inside_xy needs at least one finite camera position")
    hull = shapely.MultiPoint(inside_xy).convex_hull.buffer(config.hull_margin_m)
    if len(segments) == 0:
        return hull, "hull"
    lines = shapely.MultiLineString(list(segments))
    lo = np.minimum(segments.reshape(-1, 2).min(0), inside_xy.min(0)) - 1.0
    hi = np.maximum(segments.reshape(-1, 2).max(0), inside_xy.max(0)) + 1.0
    frame = shapely.box(*lo, *hi)
    for b in config.seal_buffers_m:
        walls = lines.buffer(b, cap_style="square")
        held = _holding(frame.difference(walls), inside_xy)
        if held is not None and not held.intersects(frame.exterior) and _holds_most(held, inside_xy):
            return held, f"sealed:{b:g}"
    walls = lines.buffer(config.seal_buffers_m[0], cap_style="square")
    outline = shapely.union(hull, shapely.MultiPoint(segments.reshape(-1, 2))).convex_hull
    closed = _holding(outline.difference(walls), inside_xy)
    if closed is not None and _holds_most(closed, inside_xy):
        return closed, "closed"
    return hull, "hull"


def _holds_most(region: shapely.Geometry, xy: np.ndarray) -> bool:
    """Whether more than half of the camera positions xy (M, 2) lie in `region`. The robot
    stood at its cameras, so a reading of the slice that puts most of them inside walls is
    wrong: a rough Poisson mesh's blobs cross the camera plane where the robot drove
    (apartment 3: 67 % of the cameras in the "closed" reading's walls; a 0.35 m seal kept a
    0.08 m2 pocket around one camera, and the mission stopped with no reachable goal)."""
    return 2 * int(shapely.contains_xy(region, xy[:, 0], xy[:, 1]).sum()) > len(xy)


def _holding(geom: shapely.Geometry, xy: np.ndarray) -> shapely.Geometry | None:
    """Union of the polygons of `geom` that contain at least one of the points xy (M, 2)."""
    parts = [g for g in getattr(geom, "geoms", [geom])
             if shapely.contains_xy(g, xy[:, 0], xy[:, 1]).any()]
    return shapely.union_all(parts) if parts else None


def free_space_from_mesh(mesh: trimesh.Trimesh, plane_z: float, inside_xy: np.ndarray,
                         config: FreeSpaceConfig = FreeSpaceConfig()) -> shapely.Geometry:
    """The robot's space as the paper finds it: slice `mesh` at the camera height plane_z
    (metres) and keep the region(s) around the camera positions inside_xy (M, 2); its
    boundary is the walls and furniture seen at that height. Copes with a leaky Poisson
    mesh by sealing gaps, else closes its open sides by its convex hull (see
    `free_space_from_slice` for which and when).

    (explore.floorplan.floor_plan_from_mesh is not reused: it makes every *closed* outline an
    obstacle footprint, which for a room, whose walls are one closed outline around the
    cameras, would make the room itself the obstacle.)"""
    geom, _ = free_space_from_slice(slice_segments(mesh, plane_z), inside_xy, config)
    try:
        return as_free_space(geom, f"mesh slice at z = {plane_z:g} m")
    except FloorPlanError as e:
        raise InputError(str(e)) from None


def sample_candidates(free: shapely.Geometry, n: int, rng: np.random.Generator,
                      clearance_m: float = 0.25) -> np.ndarray:
    """(n, 3) SE(2) poses (x, y, theta) uniform in `free` eroded by clearance_m (metres),
    headings uniform in [-pi, pi). Rejection sampling in the bounding box, vectorised."""
    region = free.buffer(-clearance_m)
    if region.is_empty or region.area <= 0:
        raise InputError(f"free space has no room left after a {clearance_m} m clearance")
    shapely.prepare(region)
    lo, hi = np.asarray(region.bounds[:2]), np.asarray(region.bounds[2:])
    frac = region.area / max(np.prod(hi - lo), 1e-12)
    out = np.zeros((0, 2))
    while len(out) < n:
        m = int(1.2 * (n - len(out)) / frac) + 8
        xy = rng.uniform(lo, hi, (m, 2))
        out = np.r_[out, xy[shapely.contains_xy(region, xy[:, 0], xy[:, 1])]]
    return np.c_[out[:n], rng.uniform(-np.pi, np.pi, n)]


def select_goals(poses: np.ndarray, scores: np.ndarray, k: int, min_separation_m: float = 0.5) -> np.ndarray:
    """Indices of up to k goals, best (highest score) first, greedily skipping any candidate
    within min_separation_m (metres, xy) of one already chosen ("we select the views with
    the best scores, and send the robot to gather more photos at these locations").
    poses (N, 3) SE(2), scores (N,); non-finite scores are never chosen."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    scores = np.asarray(scores, dtype=np.float64)
    if scores.shape != (len(poses),):
        raise InputError(f"select_goals: {len(poses)} poses but scores of shape {scores.shape}")
    chosen: list[int] = []
    for i in np.argsort(-scores, kind="stable"):
        if len(chosen) >= k or not np.isfinite(scores[i]):
            break
        if all(np.hypot(*(poses[i, :2] - poses[j, :2])) >= min_separation_m for j in chosen):
            chosen.append(int(i))
    return np.array(chosen, dtype=int)
