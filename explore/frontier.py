"""Frontier goals from the robot's ultrasonic (Yamauchi, "A frontier-based approach for
autonomous exploration", CIRA 1997): an occupancy grid of the range readings, and goals
where known free space meets space no reading has reached.

Why the capture mission needs it: Foster, Wang & Grupen's stage 2 draws its candidates
where the photos saw free space in front of the map's mesh (`ViewQuality.seen_free`), so
exploration ends wherever the mesh does. Through a doorway into a room SfM has no points of
the mesh has a hole, no candidate is drawn beyond it, and the room is never photographed
(apartments 0-9, 261 photos: 8 of 10 missions left a room unvisited). The ultrasonic, read
with every photo, sees a plain wall as well as a textured one, and reads far through a
doorway; so the readings tell open space from walls where the photos cannot.

Sensor model: a reading r < `SonarConfig.max_range_m` is the nearest surface in the cone
(`SimRobot.ultrasonic`, the NXT's sensor): the cone is free up to a cell short of r and the
whole arc at r is occupied (the classic sonar model: which ray hit is unknown); a reading
at the maximum is free up to the maximum. Each cell holds counts of free and occupied
hits; it is free when its free hits outnumber its occupied ones, unknown when it has none.

Frames: world metres, SE(2) poses (x, y, theta); grid cells (i, j) = (row along y,
column along x) as `explore.nav_grid.NavGrid`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy import ndimage


@dataclass(frozen=True)
class SonarConfig:
    """The ultrasonic's geometry: properties of the sensor, not of a scene."""

    max_range_m: float = 2.55
    """Largest range the sensor reports (the NXT's 255 cm); a reading within `max_tol_m` of
    it saw nothing."""
    max_tol_m: float = 0.05
    """Readings this close to the maximum (m) count as "nothing in range" (5 noise sigmas)."""
    half_cone_rad: float = np.radians(10.0)
    """Half-angle of the sensor's beam (rad)."""


@dataclass(frozen=True)
class SonarGrid:
    """Occupancy counts on a grid: `origin` (2,) world xy of cell (0, 0)'s corner (m),
    `cell_m` the cell size (m), `free` and `occupied` (H, W) hit counts."""

    origin: np.ndarray
    cell_m: float
    free: np.ndarray
    occupied: np.ndarray

    @property
    def free_mask(self) -> np.ndarray:
        """(H, W) bool: more free hits than occupied ones."""
        return self.free > self.occupied

    @property
    def unknown_mask(self) -> np.ndarray:
        """(H, W) bool: no reading reached the cell."""
        return (self.free == 0) & (self.occupied == 0)

    @property
    def occupied_mask(self) -> np.ndarray:
        """(H, W) bool: more occupied hits than free ones (a surface the beam met)."""
        return self.occupied > self.free

    def blocks(self, a: np.ndarray, b: np.ndarray, chunk: int = 4096) -> np.ndarray:
        """(K,) bool: the straight line from each world point a (K, 2) to b (K, 2) (m)
        crosses an occupied cell (`occupied_mask`), b's own cell included: a camera at a
        did not see empty space at b through the surface the ultrasonic met. The line is
        sampled every half cell; a's own cell is skipped (the robot stood there)."""
        a, b = np.asarray(a, float).reshape(-1, 2), np.asarray(b, float).reshape(-1, 2)
        out = np.zeros(len(a), bool)
        occupied = self.occupied_mask
        H, W = occupied.shape
        for k in range(0, len(a), chunk):
            aa, bb = a[k:k + chunk], b[k:k + chunk]
            length = np.linalg.norm(bb - aa, axis=1)
            n = int(np.ceil(length.max(initial=0.0) / (self.cell_m / 2))) + 1
            t = np.linspace(0.0, 1.0, n)
            xy = aa[:, None] + t[None, :, None] * (bb - aa)[:, None]  # (k, n, 2)
            i, j = self.cells(xy.reshape(-1, 2))
            ai, aj = self.cells(aa)
            own = (i == np.repeat(ai, n)) & (j == np.repeat(aj, n))
            ok = (i >= 0) & (i < H) & (j >= 0) & (j < W) & ~own
            hit = np.zeros(len(i), bool)
            hit[ok] = occupied[i[ok], j[ok]]
            out[k:k + chunk] = hit.reshape(len(aa), n).any(axis=1)
        return out

    def cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(i, j) integer cells of world points (N, 2) (may be out of bounds)."""
        ji = np.floor((np.asarray(xy, float) - self.origin) / self.cell_m).astype(int)
        return ji[:, 1], ji[:, 0]

    def centres(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """(K, 2) world xy (m) of the centres of the cells (i, j) (K,) each."""
        return self.origin + (np.c_[j, i] + 0.5) * self.cell_m

    def is_free(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: the cells of world points (N, 2) are free (False outside the grid)."""
        i, j = self.cells(xy)
        H, W = self.free.shape
        ok = (i >= 0) & (i < H) & (j >= 0) & (j < W)
        out = np.zeros(len(i), bool)
        out[ok] = self.free_mask[i[ok], j[ok]]
        return out

    def surface_distance(self, xy: np.ndarray) -> np.ndarray:
        """(N,) distance (m) from world points xy (N, 2) to the centre of the nearest
        occupied cell (`occupied_mask`: a surface the beam met); inf when none is occupied.
        A point off the grid reads its nearest edge cell (the grid reaches a reading's
        range of unknown space beyond every reading, so no surface lies off it)."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        dist = self._surface_distances
        if dist is None:
            return np.full(len(xy), np.inf)
        i, j = self.cells(xy)
        H, W = dist.shape
        return dist[np.clip(i, 0, H - 1), np.clip(j, 0, W - 1)]

    @cached_property
    def _surface_distances(self) -> np.ndarray | None:
        """(H, W) distance (m) from each cell's centre to the nearest occupied cell's, once
        per grid (a goal choice asks for it per frontier); None when none is occupied."""
        occupied = self.occupied_mask
        return ndimage.distance_transform_edt(~occupied) * self.cell_m if occupied.any() else None

    def free_bounds(self) -> np.ndarray | None:
        """(2, 2) [lo, hi] world xy of the free cells' extent (m); None when none is free."""
        i, j = np.nonzero(self.free_mask)
        if len(i) == 0:
            return None
        lo = self.origin + np.array([j.min(), i.min()]) * self.cell_m
        hi = self.origin + np.array([j.max() + 1, i.max() + 1]) * self.cell_m
        return np.array([lo, hi])


def sonar_grid(poses: np.ndarray, ranges: np.ndarray, cell_m: float,
               config: SonarConfig = SonarConfig()) -> SonarGrid:
    """The occupancy counts of range readings `ranges` (N,) (m) taken at robot poses (N, 3)
    (the sensor at the robot's centre, looking along its heading), on cells of `cell_m`
    metres over the readings' reach and as far again (unknown space all round, so which
    way the unknown lies is not skewed by the grid's edge). Non-finite poses or ranges
    are skipped."""
    poses = np.asarray(poses, float).reshape(-1, 3)
    ranges = np.asarray(ranges, float).reshape(-1)
    ok = np.isfinite(poses).all(axis=1) & np.isfinite(ranges) & (ranges > 0)
    poses, ranges = poses[ok], np.minimum(ranges[ok], config.max_range_m)
    reach = 2 * config.max_range_m  # the readings' reach, and as much unknown space beyond it
    lo = (poses[:, :2].min(0) if len(poses) else np.zeros(2)) - reach
    hi = (poses[:, :2].max(0) if len(poses) else np.zeros(2)) + reach
    H, W = (np.ceil((hi - lo) / cell_m).astype(int) + 1)[::-1]
    grid = SonarGrid(lo, cell_m, np.zeros((H, W), np.int32), np.zeros((H, W), np.int32))
    if len(poses) == 0:
        return grid
    for pose, r in zip(poses, ranges):
        free, arc = _reading(pose, r, cell_m, config)
        _count(grid, grid.free, free)
        if arc is not None:
            _count(grid, grid.occupied, arc)
    return grid


def _reading(pose: np.ndarray, r: float, cell_m: float, config: SonarConfig) -> tuple[np.ndarray, np.ndarray | None]:
    """What one reading r (m, at most `max_range_m`) taken at the robot pose (3,) marks, on
    rays half a cell apart at the longest range (the beam leaves no cell between rays): the
    world points (K, 2) it makes free, every half cell along each ray short of the surface
    by a cell (to the maximum when nothing is in range), and the arc (R, 2) at r it makes
    occupied (None: nothing in range)."""
    n_rays = int(np.ceil(2 * config.half_cone_rad * config.max_range_m / (cell_m / 2))) + 1
    a = pose[2] + np.linspace(-config.half_cone_rad, config.half_cone_rad, n_rays)
    dirs = np.c_[np.cos(a), np.sin(a)]
    hit = r < config.max_range_m - config.max_tol_m
    t = np.arange(0.0, max(r - (cell_m if hit else 0.0), 0.0), cell_m / 2)
    free = (pose[:2] + t[:, None, None] * dirs[None]).reshape(-1, 2)
    return free, (pose[:2] + r * dirs if hit else None)


def revealed(grid: SonarGrid, pose: np.ndarray, range_m: float, config: SonarConfig = SonarConfig()) -> int:
    """How many of `grid`'s unknown cells one reading `range_m` (m) taken at the robot pose
    (3,) would make free, as `sonar_grid` marks them (its cone free up to a cell short of a
    surface, or to the maximum): what that reading taught the grid."""
    free, _ = _reading(np.asarray(pose, float), min(float(range_m), config.max_range_m), grid.cell_m, config)
    return int(grid.unknown_mask.reshape(-1)[_distinct_cells(grid, free)].sum())


def _count(grid: SonarGrid, counts: np.ndarray, xy: np.ndarray) -> None:
    """Add one hit to each distinct cell of the world points xy (N, 2)."""
    counts.reshape(-1)[_distinct_cells(grid, xy)] += 1


def _distinct_cells(grid: SonarGrid, xy: np.ndarray) -> np.ndarray:
    """The flat indices (row-major) of the distinct grid cells of the world points xy (N, 2)
    that lie on the grid."""
    i, j = grid.cells(xy)
    H, W = grid.free.shape
    ok = (i >= 0) & (i < H) & (j >= 0) & (j < W)
    return np.unique(i[ok] * W + j[ok])


def frontiers(grid: SonarGrid, min_width_m: float) -> list[np.ndarray]:
    """Yamauchi's frontiers: free cells 4-adjacent to an unknown cell, grouped into
    8-connected regions, each as the world xy (K, 2) of its cells' centres (m); a region
    narrower than `min_width_m` (its cell count times the cell size; the robot's width: it
    could not pass) is dropped. Largest first."""
    near_unknown = ndimage.binary_dilation(grid.unknown_mask, structure=ndimage.generate_binary_structure(2, 1))
    labels, n = ndimage.label(grid.free_mask & near_unknown, structure=np.ones((3, 3), bool))
    out = []
    for k in range(1, n + 1):
        i, j = np.nonzero(labels == k)
        if len(i) * grid.cell_m >= min_width_m:
            out.append(grid.centres(i, j))
    return sorted(out, key=lambda cells: -len(cells))


def toward_unknown(grid: SonarGrid, xy: np.ndarray, radius_m: float) -> float | None:
    """Heading (rad) from the world point xy (2,) to the mean of the unknown cells within
    `radius_m` of it: the way a photo from there shows what no reading has reached. None
    when there is no unknown cell that near."""
    c = grid.centres(*np.nonzero(grid.unknown_mask))
    near = c[np.linalg.norm(c - xy, axis=1) < radius_m]
    if len(near) == 0:
        return None
    d = near.mean(0) - xy
    return float(np.arctan2(d[1], d[0]))
