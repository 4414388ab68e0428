"""Navigation grid (KDE of above-ground points), A* against scipy's Dijkstra on the same
graph, and path simplification (Foster, Wang & Grupen, Sec. IV-B, Path-Planning)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
import trimesh
from scipy.sparse.csgraph import dijkstra

from explore.astar import GridError, astar, grid_graph, path_cost
from explore.nav_grid import (NavGrid, NavGridConfig, kde_cost, nav_grid_from_points, near_segments, reachable_at,
                              reachable_mask)
from explore.path_simplify import merge_collinear, plan_path, polyline_cost, segment_cost, simplify_path


def _random_grid(rng, H, W, blocked=0.2):
    cost = rng.random((H, W)) ** 3
    cost[rng.random((H, W)) < blocked] = np.inf
    return cost


@pytest.mark.parametrize("seed", range(6))
def test_astar_cost_equals_scipy_dijkstra(seed):
    rng = np.random.default_rng(seed)
    H, W = rng.integers(8, 40, 2)
    cost = _random_grid(rng, H, W)
    weight = float(rng.uniform(0.5, 20))
    G = grid_graph(cost, weight)
    for _ in range(5):
        s = (int(rng.integers(H)), int(rng.integers(W)))
        g = (int(rng.integers(H)), int(rng.integers(W)))
        d = dijkstra(G, indices=s[0] * W + s[1])[g[0] * W + g[1]]
        path = astar(cost, s, g, weight)
        if path is None:
            assert np.isinf(d)
            continue
        assert tuple(path[0]) == s and tuple(path[-1]) == g
        steps = np.abs(np.diff(path, axis=0))
        assert steps.max() <= 1 and steps.sum(1).min() >= 1  # 8-connected moves
        assert np.isfinite(cost[path[1:, 0], path[1:, 1]]).all()
        assert path_cost(cost, path, weight) == pytest.approx(d, abs=1e-9)


def test_astar_no_corner_cutting_and_unreachable():
    cost = np.zeros((3, 3))
    cost[0, 1] = cost[1, 0] = np.inf
    assert astar(cost, (0, 0), (2, 2)) is None  # (0,0) is walled in diagonally
    cost[1, 0] = 0.0
    path = astar(cost, (0, 0), (1, 1))
    assert path.tolist() == [[0, 0], [1, 0], [1, 1]]
    cost[2, 2] = np.inf
    assert astar(cost, (0, 0), (2, 2)) is None  # blocked goal
    with pytest.raises(GridError, match="goal"):
        astar(cost, (0, 0), (3, 0))
    with pytest.raises(GridError, match="NaN"):
        astar(np.full((2, 2), np.nan), (0, 0), (1, 1))


def test_merge_collinear_and_segment_cost_known_answers():
    cells = np.array([[0, 0], [0, 1], [0, 2], [1, 3], [2, 4], [3, 4]])
    assert merge_collinear(cells).tolist() == [[0, 0], [0, 2], [2, 4], [3, 4]]
    cost = np.zeros((4, 5))
    assert segment_cost(cost, (0, 0), (3, 4), 10.0) == pytest.approx(5.0)
    cost[0, 2] = 1.0  # a horizontal run from (0,0) to (0,4) spends 1 cell length in (0, 2)
    assert segment_cost(cost, (0, 0), (0, 4), 3.0) == pytest.approx(4.0 + 3.0)
    cost[0, 2] = np.inf
    assert segment_cost(cost, (0, 0), (0, 4)) == np.inf
    corner = np.zeros((2, 2))
    corner[0, 1] = np.inf  # the diagonal (0,0)->(1,1) passes the corner of a blocked cell
    assert segment_cost(corner, (0, 0), (1, 1)) == np.inf


def _dense_cells(nodes: np.ndarray) -> np.ndarray:
    """Cells under the polyline through cell centres, sampled every 0.01 cell."""
    pts = []
    for a, b in zip(nodes[:-1] + 0.5, nodes[1:] + 0.5):
        n = int(np.ceil(np.linalg.norm(b - a) / 0.01)) + 1
        pts.append(a + np.linspace(0, 1, n)[:, None] * (b - a))
    return np.floor(np.concatenate(pts)).astype(int)


@pytest.mark.parametrize("factor", [1.0, 1.2, 2.0])
def test_simplified_path_cost_bounded_and_collision_free(factor):
    rng = np.random.default_rng(3)
    cost = 0.2 * rng.random((40, 60))
    cost[5:40, 30] = np.inf  # a wall with a gap at the top
    cost[0:20, 45] = np.inf
    path = astar(cost, (35, 5), (35, 55), 5.0)
    simple = simplify_path(path, cost, factor, 5.0)
    assert len(simple) < len(merge_collinear(path)) <= len(path)
    assert tuple(simple[0]) == (35, 5) and tuple(simple[-1]) == (35, 55)
    original = polyline_cost(cost, path, 5.0)
    assert polyline_cost(cost, simple, 5.0) <= factor * original + 1e-9
    under = _dense_cells(simple)
    assert np.isfinite(cost[under[:, 0], under[:, 1]]).all()


def test_nav_grid_cost_peaks_at_point_cluster():
    rng = np.random.default_rng(0)
    cluster = rng.normal([1.0, -0.5, 0.6], [0.05, 0.05, 0.2], (400, 3))
    floor = np.c_[rng.uniform(-3, 3, (3000, 2)), rng.normal(0, 0.01, 3000)]
    ceiling = np.c_[rng.uniform(-3, 3, (3000, 2)), np.full(3000, 2.6)]
    grid = nav_grid_from_points(np.r_[cluster, floor, ceiling], (-3, -4, 3, 4), NavGridConfig())
    assert grid.shape == (100, 75) and grid.cell_m == pytest.approx(0.08)
    peak = np.unravel_index(np.argmax(grid.cost), grid.shape)
    assert np.linalg.norm(grid.cell_to_world(peak) - [1.0, -0.5]) < 0.1
    assert grid.cost.max() == pytest.approx(1.0)
    assert grid.score.sum() == pytest.approx(np.sum((cluster[:, 2] > 0.05) & (cluster[:, 2] <= 1.5)))
    far = grid.world_to_cell(np.array([-2.0, 3.0]))
    assert grid.cost[tuple(far)] == 0.0  # floor and ceiling points are not obstacles
    xy = np.array([[0.31, -1.7], [-2.99, 3.99]])
    assert np.all(np.abs(grid.cell_to_world(grid.world_to_cell(xy)) - xy) <= grid.cell_m / 2 + 1e-12)
    assert grid.in_bounds(grid.world_to_cell(np.array([[0, 0], [3.5, 0]]))).tolist() == [True, False]
    at = grid.cost_at(np.array([[1.0, -0.5], [-2.0, 3.0], [9.0, 0.0]]))
    assert at[0] > 0.8 and at[1] == 0.0 and at[2] == np.inf


def test_cell_centres_lie_in_their_own_cells_row_by_row():
    grid = NavGrid(np.array([-1.0, 2.0]), 0.5, np.zeros((3, 4)), np.zeros((3, 4)))
    xy = grid.centres()
    assert xy.shape == (12, 2) and xy[0].tolist() == [-0.75, 2.25] and xy[1].tolist() == [-0.25, 2.25]
    assert (grid.world_to_cell(xy) == np.indices((3, 4)).reshape(2, -1).T).all()


def test_kde_is_separable_gaussian_eq1():
    score = np.zeros((21, 21))
    score[10, 10] = 9.0
    K = kde_cost(score, sigma=2.0, radius=3)
    d2 = (np.arange(21)[:, None] - 10) ** 2 + (np.arange(21)[None] - 10) ** 2
    expect = np.where((np.abs(np.arange(21)[:, None] - 10) <= 3) & (np.abs(np.arange(21) - 10) <= 3),
                      9.0 * np.exp(-d2 / 8.0) / 49, 0.0)
    np.testing.assert_allclose(K, expect, atol=1e-12)


def test_plan_path_in_office_avoids_furniture(office):
    pts, _ = trimesh.sample.sample_surface(office.mesh, 40000, seed=0)
    grid = nav_grid_from_points(pts, (-3, -4, 3, 4), NavGridConfig(cells_long_side=80))
    xy = plan_path(grid, (-1.5, -2.5), (1.5, 2.5), cost_weight=20.0, max_cost=0.2)
    assert xy is not None and np.allclose(xy[0], [-1.5, -2.5]) and np.allclose(xy[-1], [1.5, 2.5])
    line = shapely.LineString(xy)
    assert office.free_space.buffer(-0.05).contains(line)
    with pytest.raises(GridError, match="goal"):
        plan_path(grid, (0, 0), (10.0, 0.0))


def test_reachable_mask_is_what_astar_can_reach():
    """A wall of points splits the grid in two: the robot's side is reachable, the other is
    not, and A* agrees cell by cell (reachable <=> a path exists)."""
    wall = np.array([[2.0, y, 0.5] for y in np.linspace(0, 4, 200)] * 3)
    grid = nav_grid_from_points(wall, (0.0, 0.0, 4.0, 4.0), NavGridConfig(cells_long_side=40))
    mask = reachable_mask(grid, (0.5, 2.0), max_cost=0.35)
    xy = np.array([[0.5, 0.5], [1.2, 3.5], [3.0, 2.0], [3.6, 0.4]])
    assert reachable_at(grid, mask, xy).tolist() == [True, True, False, False]
    for p, ok in zip(xy, reachable_at(grid, mask, xy)):
        assert (plan_path(grid, (0.5, 2.0), p, max_cost=0.35) is not None) == ok
    # from the other side, the other half
    other = reachable_mask(grid, (3.5, 2.0), max_cost=0.35)
    assert reachable_at(grid, other, xy).tolist() == [False, False, True, True]
    assert not (mask & other).any()


@pytest.mark.parametrize("seed", range(5))
def test_reachable_mask_agrees_with_astar_on_every_cell(seed):
    """On random grids, a cell is in the reachable mask exactly when A* finds a path to it:
    cells that touch only at a corner are not joined (A* does not cut a blocked corner)."""
    rng = np.random.default_rng(seed)
    cost = _random_grid(rng, 14, 14, blocked=0.4)
    cost[7, 7] = 0.0
    grid = NavGrid(np.zeros(2), 1.0, np.zeros_like(cost), cost)
    mask = reachable_mask(grid, (7.5, 7.5), max_cost=0.5)
    for i, j in np.ndindex(cost.shape):
        found = plan_path(grid, (7.5, 7.5), (j + 0.5, i + 0.5), max_cost=0.5) is not None
        assert mask[i, j] == found, (i, j)


def test_cells_touching_at_a_corner_are_not_reachable():
    """A blocked staircase leaves the two sides touching only at corners: no path, and
    the mask does not cross it either."""
    cost = np.zeros((6, 6))
    for k in range(6):
        cost[k, 5 - k] = np.inf
    grid = NavGrid(np.zeros(2), 1.0, np.zeros_like(cost), cost)
    mask = reachable_mask(grid, (0.5, 0.5), max_cost=0.35)
    assert not mask[5, 5] and plan_path(grid, (0.5, 0.5), (5.5, 5.5), max_cost=0.35) is None


def test_cells_near_a_segment_are_a_band_along_it():
    """A segment across a 0.1 m grid marks the cells it crosses and those within the radius
    of them (a band 3 cells wide for 0.1 m), nothing beyond its ends or off the grid."""
    grid = NavGrid(np.zeros(2), 0.1, np.zeros((10, 20)), np.zeros((10, 20)))
    near = near_segments(grid, np.array([[[0.25, 0.55], [1.45, 0.55]], [[5.0, 5.0], [6.0, 5.0]]]), 0.1)
    rows, cols = np.nonzero(near)
    assert set(rows) == {4, 5, 6} and near[5, 2:15].all() and near[4, 2:15].all() and near[6, 2:15].all()
    assert not near[5, :1].any() and not near[5, 16:].any() and near.sum() == 3 * 13 + 2
    assert not near_segments(grid, np.zeros((0, 2, 2)), 0.1).any()
