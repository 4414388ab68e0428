"""Routes a robot can drive in any synthetic world, made from the world's floor plan.

`tour_route(world)` is a closed waypoint polyline: in a world of one room (the office, an
outdoor site) a loop around the middle of the room, half way between its centre and its
walls across the short side; in a world of several rooms (the apartment) a tour that drives
that loop in every room, the corridor included, going from room to room through the
doorways in the order that makes the tour shortest.

How: the loop's corners are targets; consecutive targets are joined by the cheapest path on
a grid over the free space, where a step costs its length, more near walls and furniture
(so paths keep `clearance_m` from them where there is room and go through the middle of a
doorway), and cells closer than the robot's radius to an obstacle are closed. Each leg is
then pulled straight: a waypoint is dropped where the straight line comes no closer to the
obstacles than the grid path did (and never closer than the robot's radius).
"""

from __future__ import annotations

import itertools

import numpy as np
import scipy.sparse
import shapely
from scipy.sparse import csgraph

from ibr.synthetic.world import SyntheticWorld

MAX_CELLS = 200_000
"""Largest grid (cells) over the free space: bounds the time of a route on a large site."""
NEAR_COST = 3.0
"""Extra cost of a step right at `robot_radius_m` from an obstacle, relative to one at
`clearance_m` or more (a ratio, not a size): what makes paths keep to the middle."""


def tour_route(world: SyntheticWorld, clearance_m: float = 0.5,
               robot_radius_m: float = 0.25) -> np.ndarray:
    """(N, 2) closed waypoint polyline (first row = last row), metres, that a disc robot
    of radius `robot_radius_m` can drive in `world`.

    clearance_m: the distance the route keeps from walls and furniture where there is room
        (the robot's radius and a margin for following the route); through a doorway or
        a gap it narrows, but never below `robot_radius_m`. Both are sizes of the robot,
        not of the world: the loops' sizes come from the rooms'.
    Raises ValueError when some room has no place a robot of that radius can reach.
    """
    grid = _Grid(world.free_space, robot_radius_m, clearance_m)
    loops = [_room_loop(r.polygon) for r in world.rooms]
    if len(loops) == 1:
        stops = [loops[0]]
    else:  # the room order of the shortest tour, from the first room
        anchor = [grid.snap(loop.mean(axis=0)) for loop in loops]
        dist, _ = grid.paths(anchor)
        cost = dist[:, anchor]
        if not np.isfinite(cost).all():
            raise ValueError(f"{world.name} {world.seed}: some room cannot be reached by a robot "
                             f"of radius {robot_radius_m} m")
        rest = range(1, len(loops))
        best = min(itertools.permutations(rest),
                   key=lambda p: sum(cost[a, b] for a, b in zip((0, *p), (*p, 0))))
        stops = [loops[0]] + [loops[i] for i in best]
    targets = []
    for loop in stops:  # enter each loop at the corner nearest to where the robot is
        if targets:
            k = int(np.argmin(np.linalg.norm(loop - targets[-1], axis=1)))
            loop = np.roll(loop, -k, axis=0)
        targets += [*loop, loop[0]]
    targets.append(targets[0])
    cells = [grid.snap(p) for p in targets]
    sources = sorted(set(cells))
    dist, pred = grid.paths(sources)
    row = {c: i for i, c in enumerate(sources)}
    route = []
    for a, b, ca, cb in zip(targets[:-1], targets[1:], cells[:-1], cells[1:]):
        if ca == cb:
            continue
        if not np.isfinite(dist[row[ca], cb]):
            raise ValueError(f"{world.name} {world.seed}: a robot of radius {robot_radius_m} m "
                             f"cannot drive from {np.round(a, 2)} to {np.round(b, 2)}")
        leg = grid.pull(grid.leg(a, b, ca, cb, pred[row[ca]]))
        route += list(leg if not route else leg[1:])
    return _drop_repeats(np.array(route))


def _room_loop(polygon: shapely.Polygon) -> np.ndarray:
    """(k, 2) counter-clockwise corners of a room's outline shrunk by a quarter of its
    short side (its minimum rotated rectangle's), starting from the lowest x + y."""
    corners = np.array(polygon.minimum_rotated_rectangle.exterior.coords)[:4]
    short = min(np.linalg.norm(corners[1] - corners[0]), np.linalg.norm(corners[2] - corners[1]))
    inner = polygon.buffer(-short / 4, join_style="mitre").simplify(short / 20)
    if inner.geom_type != "Polygon":  # an odd-shaped room: its largest piece
        inner = max(inner.geoms, key=lambda g: g.area)
    ring = shapely.orient_polygons(inner).exterior
    pts = np.array(ring.coords)[:-1]
    return np.roll(pts, -int(np.argmin(pts.sum(axis=1))), axis=0)


def _drop_repeats(route: np.ndarray) -> np.ndarray:
    keep = np.r_[True, np.linalg.norm(np.diff(route, axis=0), axis=1) > 1e-9]
    return route[keep]


class _Grid:
    """Square cells over the free space: each cell's distance to the nearest wall or piece
    of furniture, the 8-connected graph of the cells a robot centre may use (the largest
    connected piece), and paths on it."""

    def __init__(self, free: shapely.Geometry, radius: float, clearance: float):
        self.free, self.radius = free, radius
        self.clearance = max(clearance, radius)
        x0, y0, x1, y1 = free.bounds
        # fine enough to thread a doorway, coarse enough to stay under MAX_CELLS
        self.cell = c = max(radius / 5, np.sqrt((x1 - x0) * (y1 - y0) / MAX_CELLS))
        self.origin = np.array([x0, y0])
        self.shape = ny, nx = int(np.ceil((y1 - y0) / c)) + 1, int(np.ceil((x1 - x0) / c)) + 1
        gx, gy = np.meshgrid(x0 + c * np.arange(nx), y0 + c * np.arange(ny))
        centres = np.c_[gx.ravel(), gy.ravel()]
        inside = shapely.contains_xy(free, centres[:, 0], centres[:, 1])
        d = np.zeros(len(centres))
        d[inside] = shapely.distance(free.boundary, shapely.points(centres[inside]))
        self.d = d
        # a cell is open when the robot at any point within half a diagonal of it is clear
        self.hard = radius + c
        open_ = d >= self.hard
        idx = np.arange(ny * nx).reshape(ny, nx)
        rows, cols, cost = [], [], []
        for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
            a = idx[max(0, -dy) : ny - max(0, dy), max(0, -dx) : nx - max(0, dx)]
            b = idx[max(0, dy) : ny + min(0, dy) or None, max(0, dx) : nx + min(0, dx) or None]
            a, b = a.ravel(), b.ravel()
            ok = open_[a] & open_[b]
            a, b = a[ok], b[ok]
            near = np.clip((self.clearance - np.minimum(d[a], d[b])) / self.clearance, 0, 1)
            w = c * np.hypot(dx, dy) * (1 + NEAR_COST * near)
            rows += [a, b]
            cols += [b, a]
            cost += [w, w]
        n = ny * nx
        graph = scipy.sparse.csr_matrix((np.concatenate(cost), (np.concatenate(rows),
                                         np.concatenate(cols))), shape=(n, n))
        _, label = csgraph.connected_components(graph, directed=False)
        sizes = np.bincount(label[open_], minlength=label.max() + 1)
        self.usable = open_ & (label == np.argmax(sizes))
        self.graph = graph
        self.centres = centres

    def snap(self, p) -> int:
        """The usable cell nearest to the point p (x, y)."""
        usable = np.flatnonzero(self.usable)
        return int(usable[np.argmin(np.linalg.norm(self.centres[usable] - p, axis=1))])

    def paths(self, sources: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Cheapest-path costs and predecessors (len(sources), cells) from each source."""
        return csgraph.dijkstra(self.graph, indices=sources, return_predecessors=True)

    def leg(self, a, b, ca: int, cb: int, pred: np.ndarray) -> np.ndarray:
        """(m, 2) polyline from point a to point b along the cheapest cell path ca -> cb;
        an end point that is not itself clear is replaced by its cell's centre."""
        cells = [cb]
        while cells[-1] != ca:
            cells.append(int(pred[cells[-1]]))
        pts = self.centres[cells[::-1]].copy()
        for i, p in ((0, a), (-1, b)):
            if self._clear(np.asarray(p, float)[None], self.hard)[0] and \
                    self._segment_ok(np.asarray(p, float), pts[i], self.hard):
                pts[i] = p
        return pts

    def pull(self, pts: np.ndarray) -> np.ndarray:
        """The polyline with waypoints dropped where a straight line can skip them without
        coming closer to the obstacles than the polyline does there (nor than the radius).
        From each kept waypoint, the farthest skip found by doubling then bisecting."""
        d = self._distance(pts)

        def ok(i, j):
            floor = min(self.clearance, d[i : j + 1].min()) - self.cell
            return self._segment_ok(pts[i], pts[j], max(self.hard, floor))

        out, i, last = [pts[0]], 0, len(pts) - 1
        while i < last:
            good, step = i + 1, 1
            while good + step <= last and ok(i, good + step):
                good += step
                step *= 2
            bad = min(good + step, last + 1)
            while bad - good > 1:
                mid = (good + bad) // 2
                good, bad = (mid, bad) if ok(i, mid) else (good, mid)
            out.append(pts[good])
            i = good
        return np.array(out)

    def _segment_ok(self, p: np.ndarray, q: np.ndarray, least: float) -> bool:
        n = max(2, int(np.ceil(np.linalg.norm(q - p) / (self.cell / 2))) + 1)
        s = np.linspace(0, 1, n)[:, None]
        return bool(self._clear(p + s * (q - p), least).all())

    def _clear(self, pts: np.ndarray, least: float) -> np.ndarray:
        return self._distance(pts) >= least

    def _distance(self, pts: np.ndarray) -> np.ndarray:
        """The distance of the grid cell nearest to each point (0 off the grid): within
        half a cell's diagonal of the point's own."""
        ij = np.rint((pts - self.origin) / self.cell).astype(int)
        ny, nx = self.shape
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)
        out = np.zeros(len(pts))
        out[ok] = self.d[ij[ok, 1] * nx + ij[ok, 0]]
        return out
