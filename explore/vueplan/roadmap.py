"""Voronoi roadmap for moving between scan positions (Blaer & Allen 2009, Sec. 5.2.1, after
Blaer & Allen 2003): the generalised Voronoi diagram of the obstacle polygons is
approximated by the Voronoi diagram of points sampled densely along the obstacle edges
(`scipy.spatial.Voronoi`); Voronoi edges with an end point inside an obstacle (outside
the free space), or that leave the free space, are removed. As in the paper, a path goes
from the start straight onto a visible roadmap node, along the shortest roadmap path
(Dijkstra, `scipy.sparse.csgraph`) to the node nearest the goal that sees it, then straight
to the goal; it never cuts across open space off the roadmap, so it keeps the Voronoi
diagram's clearance from the obstacles.

Frame: world xy, metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import Voronoi, cKDTree

from explore.floorplan import FloorPlan
from ibr.errors import InputError


class RoadmapError(InputError):
    """Points that the roadmap cannot join: off the roadmap or in unconnected parts."""


@dataclass
class Roadmap:
    """nodes (V, 2) metres; edges (E, 2) node index pairs; graph: sparse (V, V) symmetric
    edge lengths (metres); free_space: the polygon paths must stay in."""

    nodes: np.ndarray
    edges: np.ndarray
    graph: object
    free_space: shapely.Geometry

    def connect(self, xy: np.ndarray, k: int = 16) -> int:
        """Index of the nearest roadmap node reachable from xy (2,) in a straight
        collision-free line (among its k nearest); -1 if none."""
        tree = cKDTree(self.nodes)
        _, near = tree.query(xy, k=min(k, len(self.nodes)))
        near = np.atleast_1d(near)
        lines = shapely.linestrings([[xy, self.nodes[j]] for j in near])
        ok = shapely.covers(self.free_space, lines)
        return int(near[np.argmax(ok)]) if ok.any() else -1


def sample_boundary(plan: FloorPlan, spacing_m: float) -> np.ndarray:
    """Points (N, 2) every ~spacing_m along every boundary edge of the free space."""
    segs, _ = plan.boundary_segments()
    L = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
    n = np.maximum(1, np.ceil(L / spacing_m).astype(int))
    seg = np.repeat(np.arange(len(segs)), n)
    t = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / n[seg]
    return segs[seg, 0] + t[:, None] * (segs[seg, 1] - segs[seg, 0])


def build_roadmap(plan: FloorPlan, spacing_m: float = 0.5) -> Roadmap:
    """The approximate generalised Voronoi diagram of the free space's boundary."""
    pts = sample_boundary(plan, spacing_m)
    vor = Voronoi(pts)
    ridges = np.array([r for r in vor.ridge_vertices if -1 not in r], dtype=int).reshape(-1, 2)
    v = vor.vertices
    inside = shapely.contains_xy(plan.free_space, v[:, 0], v[:, 1])
    ridges = ridges[inside[ridges].all(axis=1)]
    lines = shapely.linestrings(np.stack([v[ridges[:, 0]], v[ridges[:, 1]]], axis=1))
    ridges = ridges[shapely.covers(plan.free_space, lines)]
    used, inverse = np.unique(ridges, return_inverse=True)
    edges = inverse.reshape(-1, 2)
    nodes = v[used]
    w = np.linalg.norm(nodes[edges[:, 0]] - nodes[edges[:, 1]], axis=1)
    n = len(nodes)
    g = coo_matrix((np.r_[w, w], (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])),
                   shape=(n, n)).tocsr()
    return Roadmap(nodes, edges, g, plan.free_space)


def shortest_paths(roadmap: Roadmap, points: np.ndarray) -> tuple[np.ndarray, list[list[np.ndarray]]]:
    """Path lengths (n, n) metres between points (n, 2) over the roadmap, and the paths:
    paths[i][j] is a (K, 2) polyline from point i to point j (inf / empty if unreachable):
    point i, its attachment node, the Dijkstra path, point j's attachment node, point j."""
    n = len(points)
    attach = np.array([roadmap.connect(p) for p in points])
    if (attach < 0).any():
        bad = points[attach < 0]
        raise RoadmapError(f"points {np.round(bad, 2).tolist()} see no roadmap node in a straight line")
    dist, pred = dijkstra(roadmap.graph, directed=False, indices=attach, return_predecessors=True)
    lengths = np.full((n, n), np.inf)
    paths: list[list[np.ndarray]] = [[np.empty((0, 2))] * n for _ in range(n)]
    for i in range(n):
        for j in range(n):
            if i == j:
                lengths[i, j], paths[i][j] = 0.0, points[[i]]
                continue
            if not np.isfinite(dist[i, attach[j]]):
                continue
            chain = [attach[j]]
            while chain[-1] != attach[i]:
                chain.append(pred[i, chain[-1]])
            poly = np.vstack([points[i], roadmap.nodes[chain[::-1]], points[j]])
            paths[i][j] = poly
            lengths[i, j] = np.linalg.norm(np.diff(poly, axis=0), axis=1).sum()
    return lengths, paths


def path_is_free(free_space: shapely.Geometry, path: np.ndarray) -> bool:
    """True when the polyline (K, 2) stays inside the free space."""
    if len(path) < 2:
        return bool(shapely.covers(free_space, shapely.Point(path[0])))
    return bool(shapely.covers(free_space, shapely.LineString(path)))
