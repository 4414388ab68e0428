"""Voronoi roadmap, shortest paths and the TSP tour of the Phase I viewpoints."""

import numpy as np
import pytest
import shapely
from scipy.sparse.csgraph import connected_components

from explore.floorplan import FloorPlan
from explore.vueplan.roadmap import build_roadmap, path_is_free, shortest_paths
from explore.vueplan.tour import plan_tour, solve_tsp
from explore.vueplan.phase1 import Phase1Config, plan_phase1
from ibr.synthetic import make_world


@pytest.fixture(scope="module")
def courtyard():
    plan = FloorPlan(make_world("courtyard").free_space)
    return plan, build_roadmap(plan, 0.5)


def test_roadmap_lies_in_free_space_and_is_connected(courtyard):
    plan, rm = courtyard
    assert shapely.contains_xy(plan.free_space, rm.nodes[:, 0], rm.nodes[:, 1]).all()
    lines = shapely.linestrings(rm.nodes[rm.edges])
    assert shapely.covers(plan.free_space, lines).all()
    assert connected_components(rm.graph)[0] == 1
    # the generalised Voronoi diagram keeps its distance from the obstacles: every node is
    # at least as far from the boundary as the sampling allows (no node on a wall)
    d = shapely.distance(plan.free_space.boundary, shapely.points(rm.nodes))
    assert d.min() > 0.2


def test_tsp_on_square_corners_is_the_perimeter():
    pts = np.array([[0, 0], [1, 1], [1, 0], [0, 1], [0.5, 0]], float)
    lengths = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    order = solve_tsp(lengths)
    assert sorted(order) == list(range(5)) and order[0] == 0
    total = sum(lengths[a, b] for a, b in zip(order, order[1:] + order[:1]))
    assert total == pytest.approx(4.0)


def test_tour_visits_every_phase1_view_on_free_paths(courtyard):
    plan, rm = courtyard
    p1 = plan_phase1(plan, Phase1Config(n_candidates=300), np.random.default_rng(2))
    views = p1.views
    tour = plan_tour(rm, views)
    assert sorted(tour.order) == list(range(len(views)))
    assert path_is_free(plan.free_space, tour.path)
    for v in views:  # the path passes through every viewpoint
        assert np.min(np.linalg.norm(tour.path - v, axis=1)) < 1e-9
    lengths, paths = shortest_paths(rm, views)
    # every leg is view -> roadmap nodes (Dijkstra path) -> view, as in the paper
    node_set = {tuple(p) for p in rm.nodes}
    for a, b in zip(tour.order, tour.order[1:] + tour.order[:1]):
        leg = paths[a][b]
        assert len(leg) >= 3 and all(tuple(p) in node_set for p in leg[1:-1])
        assert path_is_free(plan.free_space, leg)
    assert tour.length_m == pytest.approx(np.linalg.norm(np.diff(tour.path, axis=0), axis=1).sum())
    # no leg is shorter than the straight line between its ends
    euclid = np.linalg.norm(views[:, None] - views[None], axis=2)
    assert (lengths >= euclid - 1e-9).all()


def test_path_around_a_building_uses_the_roadmap(courtyard):
    plan, rm = courtyard
    a, b = np.array([-8.0, -9.0]), np.array([-8.0, 9.0])  # opposite sides of the low building
    lengths, paths = shortest_paths(rm, np.stack([a, b]))
    assert len(paths[0][1]) > 2 and path_is_free(plan.free_space, paths[0][1])
    assert lengths[0, 1] > 18.0  # must go round the 12 m long building
    assert not path_is_free(plan.free_space, np.stack([a, b]))
