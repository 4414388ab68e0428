"""Rerun logging for VuePlan: the site mesh, Phase I candidates / views / visible walls,
the Voronoi roadmap and tour, scans, the voxel space and Phase II candidate scores.
Entity paths follow docs/ARCHITECTURE.md: world/map/mesh, world/map/points/<scan>, world/plan/...
(phase1 candidates and views, roadmap, tour = world/plan/path, scan positions),
world/voxels/{occupied,boundary_unseen}, world/nbv/{candidates,best}, plots/vueplan/...;
timeline `step` = scan / Phase II iteration."""

from __future__ import annotations

import numpy as np
import rerun as rr

from explore.vueplan.voxel_grid import OCCUPIED, VoxelGrid, boundary_unseen


def _z(xy: np.ndarray, z: float) -> np.ndarray:
    xy = np.asarray(xy, float).reshape(-1, 2)
    return np.c_[xy, np.full(len(xy), z)]


def log_phase1(positions: np.ndarray, chosen: list[int], walls: np.ndarray) -> None:
    """Candidates (grey), planned views (red) and the walls to cover, static."""
    rr.log("world/plan/phase1/candidates", rr.Points3D(_z(positions, 0.05), colors=[[150, 150, 150]],
                                                       radii=0.08), static=True)
    rr.log("world/plan/phase1/views", rr.Points3D(_z(positions[chosen], 0.1), colors=[[230, 40, 40]],
                                                  radii=0.35,
                                                  labels=[f"view {k}" for k in range(len(chosen))]),
           static=True)
    rr.log("world/plan/phase1/walls", rr.LineStrips3D([_z(w, 0.05) for w in walls], colors=[[255, 120, 0]],
                                                      radii=0.05), static=True)


def log_roadmap(nodes: np.ndarray, edges: np.ndarray) -> None:
    rr.log("world/plan/roadmap", rr.LineStrips3D([_z(nodes[e], 0.03) for e in edges],
                                                 colors=[[90, 90, 220]], radii=0.02), static=True)


def log_tour(path: np.ndarray) -> None:
    rr.log("world/plan/path", rr.LineStrips3D([_z(path, 0.06)], colors=[[255, 200, 0]], radii=0.08),
           static=True)


def log_scan(step: int, name: str, origin: np.ndarray, points: np.ndarray, max_points: int = 50_000) -> None:
    """One scan's points (subsampled) under the map's point cloud, world/map/points/<name>,
    and its scanner position at world/plan/scans/<name>, at timeline step."""
    rr.set_time("step", sequence=step)
    pts = points[:: max(1, len(points) // max_points)]
    rr.log(f"world/map/points/{name}", rr.Points3D(pts, colors=[[60, 180, 255]], radii=0.03))
    rr.log(f"world/plan/scans/{name}", rr.Points3D([origin], colors=[[255, 0, 0]], radii=0.3,
                                                   labels=[name]))


def log_voxels(step: int, grid: VoxelGrid, max_boxes: int = 60_000) -> None:
    """Seen-occupied voxels (grey) and boundary-unseen voxels (magenta) as boxes."""
    rr.set_time("step", sequence=step)
    half = [grid.voxel_m / 2] * 3
    occ = np.argwhere(grid.state == OCCUPIED)[:max_boxes]
    rr.log("world/voxels/occupied", rr.Boxes3D(centers=grid.centers(occ), half_sizes=half,
                                               colors=[[170, 170, 170]]))
    bu, _ = boundary_unseen(grid)
    rr.log("world/voxels/boundary_unseen", rr.Boxes3D(centers=grid.centers(bu[:max_boxes]), half_sizes=half,
                                                      colors=[[230, 0, 230]]))


def log_nbv_candidates(step: int, views: np.ndarray, counts: np.ndarray, nbv: np.ndarray | None) -> None:
    """Potential views coloured by how many boundary-unseen voxels they see (blue: none,
    red: the most), and the chosen next-best view (cleared when none is acquired)."""
    rr.set_time("step", sequence=step)
    s = counts / max(1, counts.max())
    colors = np.c_[255 * s, 80 + 0 * s, 255 * (1 - s)].astype(np.uint8)
    rr.log("world/nbv/candidates", rr.Points3D(views, colors=colors, radii=0.1))
    if nbv is None:
        rr.log("world/nbv/best", rr.Clear(recursive=False))
    else:
        rr.log("world/nbv/best", rr.Points3D([nbv], colors=[[255, 255, 0]], radii=0.4,
                                             labels=[f"NBV sees {int(counts.max())}"]))


def log_phase2_row(step: int, row) -> None:
    rr.set_time("step", sequence=step)
    for key in ("seen_occupied", "unseen", "boundary_unseen", "visible_to_nbv", "surface_coverage"):
        rr.log(f"plots/vueplan/{key}", rr.Scalars(float(getattr(row, key))))
