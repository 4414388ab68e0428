"""Visibility polygon of a point inside a polygon with holes, by an angular ray sweep (the
sweep Blaer & Allen 2009, Sec. 3.1 use for VuePlan's 2-D visibility).

Between two consecutive polygon vertices, as seen from the viewpoint q, no vertex lies in
the open angular interval, so one polygon edge is nearest to q over the whole interval: the
one the interval's middle ray hits first. The visible boundary in that interval is that
edge's piece between the interval's two bounding rays. The polygon is these pieces in angular
order; consecutive pieces on different edges are joined by a radial "shadow" edge through
the free space. Vertices are intersections of edges with rays through vertices, so they are
the polygon's own vertices where the ray ends on one (to rounding) and exact points on the
edges behind a corner otherwise. Cost: O(n * E) for n vertices and E edges, vectorised.

Frame: world xy, metres.
"""

from __future__ import annotations

import numpy as np
import shapely

__all__ = ["VisibilityPolygons", "polygon_edges", "visibility_polygon"]


def polygon_edges(polygon: shapely.Polygon) -> np.ndarray:
    """Every edge (E, 2, 2) of the polygon's exterior and holes."""
    rings = [polygon.exterior, *polygon.interiors]
    return np.concatenate([np.stack([c[:-1], c[1:]], axis=1) for c in
                           (np.asarray(r.coords)[:, :2] for r in rings)])


def _ray_hits(q: np.ndarray, directions: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ray parameters t (R, E) where rays q + t d (d: directions (R, 2)) meet each edge (inf
    where they miss it or run parallel to it) and the edge parameters s (R, E) in [0, 1]."""
    a, e = edges[:, 0] - q, edges[:, 1] - edges[:, 0]  # (E, 2)
    d = directions[:, None, :]  # (R, 1, 2)
    den = d[..., 0] * e[None, :, 1] - d[..., 1] * e[None, :, 0]  # cross(d, e)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (a[None, :, 0] * e[None, :, 1] - a[None, :, 1] * e[None, :, 0]) / den  # cross(a, e) / cross(d, e)
        s = (a[None, :, 0] * d[..., 1] - a[None, :, 1] * d[..., 0]) / den  # cross(a, d) / cross(d, e)
    ok = (np.abs(den) > 1e-15) & (t > 0) & (s >= -1e-12) & (s <= 1 + 1e-12)
    return np.where(ok, t, np.inf), s


def _on_line(q: np.ndarray, angle: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Points (R, 2) where rays from q at angles (R,) meet the lines of edges (R, 2, 2)."""
    d = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    a, e = edges[:, 0] - q, edges[:, 1] - edges[:, 0]
    t = (a[:, 0] * e[:, 1] - a[:, 1] * e[:, 0]) / (d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0])
    return q + t[:, None] * d


def visibility_polygon(polygon: shapely.Polygon, xy: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Vertices (K, 2) of the part of `polygon` (with holes) visible from the interior point
    xy, counter-clockwise; empty when xy is not inside the polygon. tol: points closer than
    this (relative to the polygon's size) are merged."""
    q = np.asarray(xy, dtype=np.float64)[:2]
    if not polygon.contains(shapely.Point(q)):
        return np.empty((0, 2))
    edges = polygon_edges(polygon)
    ang = np.unique(np.arctan2(edges[:, 0, 1] - q[1], edges[:, 0, 0] - q[0]))
    ang = ang[np.r_[True, np.diff(ang) > 1e-14]]
    lo, hi = ang, np.r_[ang[1:], ang[0] + 2 * np.pi]
    mid = (lo + hi) / 2
    t, _ = _ray_hits(q, np.stack([np.cos(mid), np.sin(mid)], axis=1), edges)
    nearest = edges[t.argmin(axis=1)]  # the edge seen over each open interval
    pts = np.stack([_on_line(q, lo, nearest), _on_line(q, hi, nearest)], axis=1).reshape(-1, 2)
    scale = tol * max(1.0, float(np.abs(edges).max()))
    keep = np.r_[True, np.linalg.norm(np.diff(pts, axis=0), axis=1) > scale]
    pts = pts[keep]
    if len(pts) > 1 and np.linalg.norm(pts[-1] - pts[0]) <= scale:
        pts = pts[:-1]
    return pts


class VisibilityPolygons:
    """Visibility polygons in a free space of one or several polygons (with holes):
    `vis(xy)` gives the vertices (K, 2) of the polygon seen from xy (metres), or an empty
    array when xy is in none of them."""

    def __init__(self, free_space: shapely.Geometry):
        self.polygons = list(getattr(free_space, "geoms", [free_space]))
        for p in self.polygons:
            shapely.prepare(p)

    def __call__(self, xy: np.ndarray) -> np.ndarray:
        for poly in self.polygons:
            if poly.contains(shapely.Point(xy)):
                return visibility_polygon(poly, xy)
        return np.empty((0, 2))
