"""Navigation grid of Foster, Wang & Grupen ("A Mobile Robot for Autonomous Scene Capture
and Rendering", Sec. IV-B, "Path-Planning"): a grid of about 100 cells on the long side,
centred on the bounding box of the explored area. Each cell c gets a score s(c), the
number of above-ground map points in it, and a cost, Eq. (1):

    K(c) = 1/|N| sum_{c_i in N} w(c, c_i) s(c_i),   w Gaussian,

computed as a separable convolution (scipy.ndimage.convolve1d along each axis).

"Above ground": the paper thresholds at z = 0 with all cameras in the z = 0 plane. Our
world frame has the floor at z = 0 and, in the synthetic office, a ceiling at 2.6 m that
the robot passes under, so points count when z_floor_margin < z <= z_max (defaults
0.05 and 1.5 m): the floor (and its SfM noise) and the ceiling are not obstacles.

Cells: (i, j) = (row along y, column along x); cell (i, j) covers
x in [origin_x + j cell_m, origin_x + (j + 1) cell_m), y likewise with i.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ibr.errors import InputError


@dataclass(frozen=True)
class NavGridConfig:
    cells_long_side: int = 100
    """Cells along the long side of the bounding box (the paper: about 100)."""
    sigma_cells: float = 1.5
    """Standard deviation of the Gaussian weights w(c, c_i), in cells."""
    radius_cells: int = 4
    """Half-width of the neighbourhood N (|N| = (2 r + 1)^2 cells)."""
    z_floor_margin: float = 0.05
    """Points at or below this height (metres) are floor, not obstacles."""
    z_max: float = 1.5
    """Points above this height (metres) pass over the robot (ceiling, shelves' tops)."""
    normalize: bool = True
    """Divide K by its maximum so the cost is in [0, 1] whatever the point density (the
    paper reads K as the probability that a cell holds an obstacle)."""


@dataclass(frozen=True)
class NavGrid:
    """origin (2,) world xy (metres) of the corner of cell (0, 0); cell_m cell size
    (metres); score (H, W) point counts s(c); cost (H, W) K(c) >= 0."""

    origin: np.ndarray
    cell_m: float
    score: np.ndarray
    cost: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return self.cost.shape

    def world_to_cell(self, xy: np.ndarray) -> np.ndarray:
        """World xy (..., 2) metres -> integer cells (..., 2) (i, j); may be out of bounds."""
        ji = np.floor((np.asarray(xy, dtype=np.float64) - self.origin) / self.cell_m).astype(int)
        return ji[..., ::-1]

    def cell_to_world(self, ij: np.ndarray) -> np.ndarray:
        """Cells (..., 2) (i, j) -> world xy (..., 2) of the cell centres, metres."""
        ij = np.asarray(ij, dtype=np.float64)
        return self.origin + (ij[..., ::-1] + 0.5) * self.cell_m

    def centres(self) -> np.ndarray:
        """World xy (H * W, 2) metres of every cell's centre, row by row (reshape a per-cell
        result to `shape`)."""
        H, W = self.shape
        return self.cell_to_world(np.indices((H, W)).reshape(2, -1).T)

    def cost_at(self, xy: np.ndarray) -> np.ndarray:
        """K at world points (..., 2) metres, inf outside the grid (e.g. to drop candidate
        goals that stand on furniture below the camera plane: cost_at(xy) <= max_cost)."""
        ij = self.world_to_cell(xy)
        ok = self.in_bounds(ij)
        out = np.full(ok.shape, np.inf)
        out[ok] = self.cost[ij[ok][..., 0], ij[ok][..., 1]]
        return out

    def in_bounds(self, ij: np.ndarray) -> np.ndarray:
        """Bool (...,) true for cells (..., 2) inside the grid."""
        ij = np.asarray(ij)
        H, W = self.shape
        return (ij[..., 0] >= 0) & (ij[..., 0] < H) & (ij[..., 1] >= 0) & (ij[..., 1] < W)


def gaussian_weights(sigma: float, radius: int) -> np.ndarray:
    """1-D weights exp(-d^2 / (2 sigma^2)), d = -radius..radius (1 at d = 0)."""
    d = np.arange(-radius, radius + 1, dtype=np.float64)
    return np.exp(-0.5 * (d / sigma) ** 2)


def kde_cost(score: np.ndarray, sigma: float, radius: int) -> np.ndarray:
    """Eq. (1): K = (1/|N|) sum w s over the (2r+1)^2 neighbourhood, w(c, c_i) the product
    of 1-D Gaussians (a separable convolution; zero outside the grid)."""
    w = gaussian_weights(sigma, radius)
    k = ndimage.convolve1d(score.astype(np.float64), w, axis=0, mode="constant")
    k = ndimage.convolve1d(k, w, axis=1, mode="constant")
    return k / (2 * radius + 1) ** 2


def nav_grid_from_points(points: np.ndarray, bounds_xy, config: NavGridConfig = NavGridConfig()) -> NavGrid:
    """The navigation grid over bounds_xy (xmin, ymin, xmax, ymax) metres (e.g. the explored
    area's bounding box), centred on it, `cells_long_side` cells on its long side, from the
    map points (N, 3) world metres."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    xmin, ymin, xmax, ymax = (float(v) for v in bounds_xy)
    if not (np.isfinite([xmin, ymin, xmax, ymax]).all() and xmax > xmin and ymax > ymin):
        raise InputError(f"nav grid: bounds_xy {bounds_xy} is not (xmin, ymin, xmax, ymax)")
    cell = max(xmax - xmin, ymax - ymin) / config.cells_long_side
    W = max(1, int(np.ceil((xmax - xmin) / cell - 1e-9)))
    H = max(1, int(np.ceil((ymax - ymin) / cell - 1e-9)))
    centre = np.array([xmin + xmax, ymin + ymax]) / 2
    origin = centre - 0.5 * cell * np.array([W, H])
    z = points[:, 2]
    above = points[np.isfinite(points).all(1) & (z > config.z_floor_margin) & (z <= config.z_max)]
    ji = np.floor((above[:, :2] - origin) / cell).astype(int)
    ok = (ji[:, 0] >= 0) & (ji[:, 0] < W) & (ji[:, 1] >= 0) & (ji[:, 1] < H)
    score = np.zeros((H, W))
    np.add.at(score, (ji[ok, 1], ji[ok, 0]), 1.0)
    cost = kde_cost(score, config.sigma_cells, config.radius_cells)
    if config.normalize and cost.max() > 0:
        cost = cost / cost.max()
    return NavGrid(origin, cell, score, cost)


def reachable_mask(grid: NavGrid, start_xy, max_cost: float, clearance_m: float = 0.0) -> np.ndarray:
    """(H, W) bool: the cells a robot at start_xy (metres) can reach on the grid as A* moves,
    through cells whose cost K <= max_cost and that lie at least clearance_m (metres, e.g.
    the robot's radius) from every blocked cell. A* steps to 8 neighbours but never cuts
    the corner of a blocked cell (`explore.astar`), so a diagonal step joins two cells
    already joined through both their shared neighbours: its components are the
    4-connected ones (labelled 8-connected, cells touching only at a corner counted as
    joined, and the mission drew goals A* then found no path to: apartment 0, traced, 2 of
    its 10 goals given up for "no path"). When the robot's own cell fails the test (it
    stands near furniture), the component of the nearest passing cell is taken. Cells
    outside the grid are blocked."""
    passable = np.asarray(grid.cost) <= max_cost
    if clearance_m > 0:
        r = clearance_m / grid.cell_m
        passable &= ndimage.distance_transform_edt(passable) > r
    labels, n = ndimage.label(passable)  # 4-connected
    if n == 0:
        return np.zeros(grid.shape, bool)
    H, W = grid.shape
    i, j = np.clip(grid.world_to_cell(np.asarray(start_xy, dtype=np.float64)), 0, [H - 1, W - 1])
    if labels[i, j] == 0:
        _, (ii, jj) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
        i, j = ii[i, j], jj[i, j]
    return labels == labels[i, j]


def reachable_at(grid: NavGrid, mask: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(N,) bool: the world points xy (N, 2) metres lie in a cell of `mask` (H, W)."""
    ij = grid.world_to_cell(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
    ok = grid.in_bounds(ij)
    out = np.zeros(len(ij), bool)
    out[ok] = mask[ij[ok, 0], ij[ok, 1]]
    return out


def near_segments(grid: NavGrid, segments: np.ndarray, radius_m: float) -> np.ndarray:
    """(H, W) bool: the cells whose centre lies within radius_m (metres) of a cell that one
    of the straight segments (S, 2, 2) (world xy endpoints, metres) passes through. Each
    segment is sampled every half cell, so no cell it crosses is skipped; the parts outside
    the grid are ignored."""
    H, W = grid.shape
    hit = np.zeros((H, W), bool)
    segs = np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2)
    if len(segs) == 0:
        return hit
    n = np.ceil(np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1) / (grid.cell_m / 2)).astype(int) + 1
    t = np.concatenate([np.linspace(0.0, 1.0, k) for k in n])
    a = np.repeat(segs[:, 0], n, axis=0)
    b = np.repeat(segs[:, 1], n, axis=0)
    ij = grid.world_to_cell(a + t[:, None] * (b - a))
    ok = grid.in_bounds(ij)
    hit[ij[ok, 0], ij[ok, 1]] = True
    if not hit.any():
        return hit
    return ndimage.distance_transform_edt(~hit) * grid.cell_m <= radius_m
