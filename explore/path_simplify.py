"""Path simplification and the grid planner (Foster, Wang & Grupen, "A Mobile Robot for
Autonomous Scene Capture and Rendering", Sec. IV-B, "Path-Planning": "To avoid a long
sequence of short moves, we simplify the path when the search completes. First, we merge
sequences of moves at the same angle into single longer moves. Then we recursively remove
path nodes that can be skipped over without increasing the path cost by more than a
constant multiple of the total cost of the original move sequence.").

Cost of a straight segment between two cell centres: its line integral over the grid,

    C(a, b) = sum over the cells it crosses of length_in_cell * (1 + cost_weight * K(cell)),

in cell units, exact (the crossings with the grid lines are computed). A segment through a
blocked (non-finite) cell, or through a grid corner beside a blocked cell (the corner cut
A* forbids), costs inf. Merging collinear moves leaves this cost unchanged; each node
dropped keeps C(a, b) <= factor * (cost of the original sequence a..b), so the simplified
path costs at most factor times the original and never crosses a blocked cell.
"""

from __future__ import annotations

import numpy as np

from explore.astar import GridError, astar, check_cost
from explore.nav_grid import NavGrid


def merge_collinear(cells: np.ndarray) -> np.ndarray:
    """Drop the nodes (K, 2) where the path goes on at the same angle; first and last kept."""
    cells = np.asarray(cells)
    if len(cells) < 3:
        return cells.copy()
    d = np.diff(cells, axis=0).astype(np.float64)
    cross = d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]
    dot = np.einsum("ij,ij->i", d[:-1], d[1:])
    turn = (np.abs(cross) > 1e-12) | (dot <= 0)
    return cells[np.r_[True, turn, True]]


def segment_cost(cost: np.ndarray, a, b, cost_weight: float = 10.0) -> float:
    """Line integral C(a, b) of (1 + cost_weight K) along the straight segment between the
    centres of cells a and b (i, j), cell units; inf across blocked cells or their corners."""
    a = np.asarray(a, dtype=np.float64) + 0.5
    b = np.asarray(b, dtype=np.float64) + 0.5
    d = b - a
    L = float(np.hypot(*d))
    if L == 0:
        return 0.0
    ts = [np.array([0.0, 1.0])]
    for k in range(2):
        if d[k] != 0:
            lines = np.arange(np.ceil(min(a[k], b[k])), np.floor(max(a[k], b[k])) + 1)
            ts.append((lines - a[k]) / d[k])
    t = np.unique(np.clip(np.concatenate(ts), 0.0, 1.0))
    mid = a + np.outer((t[:-1] + t[1:]) / 2, d)
    cells = np.floor(mid).astype(int)
    H, W = cost.shape
    if ((cells < 0) | (cells >= [H, W])).any():
        return float("inf")
    K = cost[cells[:, 0], cells[:, 1]]
    total = float(np.sum(np.diff(t) * L * (1.0 + cost_weight * K)))
    if not np.isfinite(total) or not (d[0] and d[1]):
        return total
    p = a + np.outer(t, d)  # points where the segment crosses grid lines
    corner = np.all(np.abs(p - np.round(p)) < 1e-9, axis=1) & (t > 0) & (t < 1)
    for ci, cj in np.round(p[corner]).astype(int):  # the two cells beside a corner passed
        si, sj = int(np.sign(d[0])), int(np.sign(d[1]))
        side = [(ci - (si > 0), cj - (sj < 0)), (ci - (si < 0), cj - (sj > 0))]
        if any(not np.isfinite(cost[i, j]) for i, j in side if 0 <= i < H and 0 <= j < W):
            return float("inf")
    return total


def simplify_path(cells: np.ndarray, cost: np.ndarray, factor: float = 1.2,
                  cost_weight: float = 10.0) -> np.ndarray:
    """Merge collinear moves, then recursively skip nodes: the whole run a..b is replaced by
    the straight segment a -> b when C(a, b) <= factor * (cost of the run); otherwise the run
    is split at its middle node and each half is tried. Returns the kept nodes (M, 2).
    A blocked start cell (A* lets the robot leave the cell it stands in) counts with the
    grid's highest finite cost."""
    if factor < 1:
        raise GridError(f"simplify_path: factor must be >= 1, got {factor}")
    cost = check_cost(cost)
    nodes = merge_collinear(np.asarray(cells, dtype=int))
    if len(nodes) and not np.isfinite(cost[tuple(nodes[0])]):
        cost = cost.copy()
        finite = cost[np.isfinite(cost)]
        cost[tuple(nodes[0])] = finite.max() if finite.size else 0.0
    if len(nodes) < 3:
        return nodes
    seg = np.array([segment_cost(cost, p, q, cost_weight) for p, q in zip(nodes[:-1], nodes[1:])])
    prefix = np.r_[0.0, np.cumsum(seg)]
    keep = {0, len(nodes) - 1}

    def run(a: int, b: int) -> None:
        if b - a < 2:
            return
        if segment_cost(cost, nodes[a], nodes[b], cost_weight) <= factor * (prefix[b] - prefix[a]):
            return
        m = (a + b) // 2
        keep.add(m)
        run(a, m)
        run(m, b)

    run(0, len(nodes) - 1)
    return nodes[sorted(keep)]


def polyline_cost(cost: np.ndarray, nodes: np.ndarray, cost_weight: float = 10.0) -> float:
    """Sum of segment_cost over consecutive nodes (M, 2)."""
    return float(sum(segment_cost(cost, p, q, cost_weight) for p, q in zip(nodes[:-1], nodes[1:])))


def plan_path(grid: NavGrid, start_xy, goal_xy, cost_weight: float = 10.0, factor: float = 1.2,
              max_cost: float | None = None) -> np.ndarray | None:
    """World waypoints (M, 2) metres from start_xy to goal_xy: A* on the grid, then
    simplification. Cells with cost > max_cost (when given) are blocked. The start is
    clamped into the grid (a robot may stand just outside the explored box); a goal
    outside the grid raises GridError. The first waypoint is start_xy, the last goal_xy,
    those between are cell centres. None when the goal cannot be reached."""
    cost = np.array(grid.cost, dtype=np.float64)
    if max_cost is not None:
        cost[cost > max_cost] = np.inf
    H, W = grid.shape
    goal = grid.world_to_cell(np.asarray(goal_xy, dtype=np.float64))
    if not grid.in_bounds(goal):
        raise GridError(f"goal {tuple(np.round(goal_xy, 3))} m lies outside the navigation grid")
    start = np.clip(grid.world_to_cell(np.asarray(start_xy, dtype=np.float64)), 0, [H - 1, W - 1])
    cells = astar(cost, start, goal, cost_weight)
    if cells is None:
        return None
    nodes = simplify_path(cells, cost, factor, cost_weight)
    xy = grid.cell_to_world(nodes)
    xy[0], xy[-1] = start_xy, goal_xy
    return xy
