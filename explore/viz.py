"""Rerun logging for exploration: planned paths (`world/plan/path`), floor plans, candidates,
the navigation grid and the ultrasonic's occupancy grid (`world/plan/sonar`)."""

from __future__ import annotations

import numpy as np
import rerun as rr
import shapely

from explore.frontier import frontiers


def log_path(xy: np.ndarray, path: str = "world/plan/path", height_m: float = 0.02,
             static: bool = False) -> None:
    """A 2-D path (M, 2) on the floor as a line strip."""
    xy = np.asarray(xy, dtype=np.float64)
    rr.log(path, rr.LineStrips3D([np.c_[xy, np.full(len(xy), height_m)]], colors=[[255, 200, 0]],
                                 radii=0.02), static=static)


def log_floor_plan(free_space: shapely.Geometry, path: str = "world/map/floor_plan") -> None:
    """Outline of a free-space polygon (with holes) on the floor, static."""
    polys = getattr(free_space, "geoms", [free_space])
    rings = [np.asarray(r.coords) for p in polys for r in (p.exterior, *p.interiors)]
    rr.log(path, rr.LineStrips3D([np.c_[r, np.full(len(r), 0.01)] for r in rings],
                                 colors=[[120, 200, 120]], radii=0.015), static=True)


def score_colors(scores: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 colours from blue (lowest score) through yellow to red (highest)."""
    s = np.asarray(scores, dtype=np.float64)
    finite = np.isfinite(s)
    lo, hi = (s[finite].min(), s[finite].max()) if finite.any() else (0.0, 1.0)
    t = np.clip((np.where(finite, s, lo) - lo) / max(hi - lo, 1e-12), 0, 1)[:, None]
    blue, yellow, red = np.array([40, 80, 220]), np.array([250, 220, 40]), np.array([220, 30, 30])
    rgb = np.where(t < 0.5, blue + (yellow - blue) * 2 * t, yellow + (red - yellow) * (2 * t - 1))
    return rgb.astype(np.uint8)


def log_candidates(poses: np.ndarray, scores: np.ndarray, path: str = "world/nbv/candidates",
                   height_m: float = 0.05, arrow_m: float = 0.3) -> None:
    """Candidate SE(2) poses (N, 3) as arrows on the floor along their headings, coloured by
    their heuristic scores (N,) (red = highest = most to gain)."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    origins = np.c_[poses[:, :2], np.full(len(poses), height_m)]
    vectors = arrow_m * np.c_[np.cos(poses[:, 2]), np.sin(poses[:, 2]), np.zeros(len(poses))]
    labels = [f"{s:.3f}" for s in np.asarray(scores, dtype=np.float64)]
    rr.log(path, rr.Arrows3D(origins=origins, vectors=vectors, colors=score_colors(scores),
                             radii=0.01, labels=labels, show_labels=False))


def log_nav_grid(grid, path: str = "world/plan/grid", min_cost: float = 0.02,
                 height_m: float = 0.005, static: bool = False) -> None:
    """A `explore.nav_grid.NavGrid` as points at the centres of the cells whose cost
    exceeds min_cost, dark grey (low) to black/red (high); blocked cells red."""
    cost = np.asarray(grid.cost, dtype=np.float64)
    ij = np.argwhere(~(cost <= min_cost))
    c = cost[ij[:, 0], ij[:, 1]]
    finite = np.isfinite(c)
    top = c[finite].max() if finite.any() else 1.0
    level = np.where(finite, c / max(top, 1e-12), 1.0)[:, None]
    colors = ((1 - level) * np.array([200, 200, 200]) + level * np.array([30, 30, 30])).astype(np.uint8)
    colors[~finite] = [220, 30, 30]
    xy = grid.cell_to_world(ij)
    rr.log(path, rr.Points3D(np.c_[xy, np.full(len(xy), height_m)], colors=colors,
                             radii=0.5 * grid.cell_m), static=static)


def log_sonar_grid(grid, path: str = "world/plan/sonar", height_m: float = 0.003) -> None:
    """An ultrasonic occupancy grid (`explore.frontier.SonarGrid`) as points at cell centres:
    free cells pale blue, occupied ones dark grey, frontier cells (free next to unknown,
    `explore.frontier.frontiers` of any width) orange."""
    free, occupied = grid.free_mask, (grid.occupied > 0) & ~grid.free_mask
    ij = np.argwhere(free | occupied)
    colors = np.where(free[ij[:, 0], ij[:, 1]][:, None], [[170, 200, 235]], [[60, 60, 60]]).astype(np.uint8)
    xy = grid.centres(ij[:, 0], ij[:, 1])
    front = np.vstack(frontiers(grid, 0.0) or [np.zeros((0, 2))])
    xy, colors = np.r_[xy, front], np.r_[colors, np.tile(np.array([[255, 140, 0]], np.uint8), (len(front), 1))]
    rr.log(path, rr.Points3D(np.c_[xy, np.full(len(xy), height_m)], colors=colors, radii=0.5 * grid.cell_m))
