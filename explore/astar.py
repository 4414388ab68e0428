"""A* on the navigation grid (Foster, Wang & Grupen, "A Mobile Robot for Autonomous Scene
Capture and Rendering", Sec. IV-B, "Path-Planning": "We find a path to our goal location
with an A* search on the grid, using the cell costs as weights. We allow the robot to move
to any of the 8 neighbors of its current cell.").

Edge weight of the move from cell u to its neighbour v (in cell units):

    w(u, v) = |v - u| * (1 + cost_weight * K(v)),   |v - u| = 1 or sqrt(2),

i.e. the step length scaled by the cost of the cell entered. Cells with a non-finite cost
are impassable, and a diagonal move may not cut the corner of an impassable cell (both
orthogonal neighbours it passes between must be passable). Since K >= 0, every weight is
at least the step length, so the Euclidean distance to the goal is an admissible and
consistent heuristic and A* returns a least-cost path. `grid_graph` builds the same
weighted graph as a scipy.sparse matrix (the test checks A*'s cost against
scipy.sparse.csgraph.dijkstra's).
"""

from __future__ import annotations

import heapq
import math

import numpy as np
import scipy.sparse

from ibr.errors import InputError

SQRT2 = math.sqrt(2.0)
MOVES = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
"""The 8 neighbour offsets (di, dj)."""


class GridError(InputError):
    """A cost grid or a start/goal cell that cannot be searched."""


def check_cost(cost: np.ndarray) -> np.ndarray:
    """The cost grid as float64 (H, W); raises GridError for NaN or negative values
    (+inf is allowed: impassable)."""
    cost = np.asarray(cost, dtype=np.float64)
    if cost.ndim != 2 or cost.size == 0:
        raise GridError(f"cost grid must be a non-empty (H, W) array, got shape {cost.shape}")
    if np.isnan(cost).any() or (cost < 0).any():
        raise GridError("cost grid has NaN or negative cells (costs must be >= 0, inf = blocked)")
    return cost


def _cell(ij, shape, what: str) -> tuple[int, int]:
    i, j = (int(v) for v in np.asarray(ij).reshape(2))
    if not (0 <= i < shape[0] and 0 <= j < shape[1]):
        raise GridError(f"{what} cell {(i, j)} is outside the {shape[0]}x{shape[1]} grid")
    return i, j


def astar(cost: np.ndarray, start, goal, cost_weight: float = 10.0) -> np.ndarray | None:
    """Least-cost 8-connected path from cell `start` (i, j) to `goal` (i, j) on the cost
    grid (H, W) (K >= 0, inf = blocked; the start cell itself may be blocked: the robot is
    there). Returns the cells (K, 2) int, start and goal included, or None when the goal
    cannot be reached."""
    cost = check_cost(cost)
    H, W = cost.shape
    si, sj = _cell(start, cost.shape, "start")
    gi, gj = _cell(goal, cost.shape, "goal")
    # pad with a ring of blocked cells: no bounds checks; node = (i + 1) * P + (j + 1)
    P = W + 2
    padded = np.full((H + 2, P), np.inf)
    padded[1:-1, 1:-1] = 1.0 + cost_weight * cost
    mult = padded.ravel().tolist()
    I, J = np.divmod(np.arange(padded.size), P)
    h = np.hypot(I - (gi + 1), J - (gj + 1)).tolist()  # Euclidean heuristic, cells
    s, g = (si + 1) * P + sj + 1, (gi + 1) * P + gj + 1
    if not math.isfinite(mult[g]):
        return None
    # (offset, step length, offsets of the two cells a diagonal passes between)
    moves = [(di * P + dj, math.hypot(di, dj), di * P, dj) for di, dj in MOVES]
    best = [math.inf] * len(mult)
    parent = [-1] * len(mult)
    closed = bytearray(len(mult))
    best[s] = 0.0
    heap = [(h[s], 0.0, s)]
    inf, push, pop = math.inf, heapq.heappush, heapq.heappop
    while heap:
        _, d, u = pop(heap)
        if closed[u]:
            continue
        if u == g:
            break
        closed[u] = 1
        for off, step, side_i, side_j in moves:
            v = u + off
            m = mult[v]
            if m == inf or closed[v]:
                continue
            if side_i and side_j and (mult[u + side_i] == inf or mult[u + side_j] == inf):
                continue  # diagonal: no cutting the corner of a blocked cell
            nd = d + step * m
            if nd < best[v]:
                best[v] = nd
                parent[v] = u
                push(heap, (nd + h[v], nd, v))
    if best[g] == inf:
        return None
    path = [g]
    while path[-1] != s:
        path.append(parent[path[-1]])
    return np.array([divmod(v, P) for v in reversed(path)], dtype=int) - 1


def path_cost(cost: np.ndarray, cells: np.ndarray, cost_weight: float = 10.0) -> float:
    """Sum of the A* edge weights along a path of neighbouring cells (K, 2)."""
    cells = np.asarray(cells, dtype=int)
    step = np.linalg.norm(np.diff(cells, axis=0), axis=1)
    entered = np.asarray(cost, dtype=np.float64)[cells[1:, 0], cells[1:, 1]]
    return float(np.sum(step * (1.0 + cost_weight * entered)))


def grid_graph(cost: np.ndarray, cost_weight: float = 10.0) -> scipy.sparse.csr_matrix:
    """The directed graph A* searches, as a sparse (H*W, H*W) matrix: node i*W + j, an edge
    u -> v for every allowed move with weight |v - u| (1 + cost_weight K(v))."""
    cost = check_cost(cost)
    H, W = cost.shape
    free = np.isfinite(cost)
    idx = np.arange(H * W).reshape(H, W)
    rows, cols, vals = [], [], []
    for di, dj in MOVES:
        i0, i1, j0, j1 = max(0, -di), H - max(0, di), max(0, -dj), W - max(0, dj)

        def at(a: np.ndarray, oi: int, oj: int) -> np.ndarray:  # a at u + (oi, oj), u in the block
            return a[i0 + oi:i1 + oi, j0 + oj:j1 + oj]

        allowed = at(free, di, dj).copy()
        if di and dj:  # the two cells the diagonal passes between
            allowed &= at(free, di, 0) & at(free, 0, dj)
        rows.append(at(idx, 0, 0)[allowed])
        cols.append(at(idx, di, dj)[allowed])
        vals.append(math.hypot(di, dj) * (1.0 + cost_weight * at(cost, di, dj)[allowed]))
    return scipy.sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                   shape=(H * W, H * W))
