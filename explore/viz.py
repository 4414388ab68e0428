"""Rerun logging for exploration: planned paths (`world/plan/path`) and floor plans."""

from __future__ import annotations

import numpy as np
import rerun as rr
import shapely


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
