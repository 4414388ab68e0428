"""Phase I (Blaer & Allen Algorithm 1): clipping against hand-made geometry with known
answers, the greedy cover, and coverage of the synthetic courtyard."""

import numpy as np
import pytest
import shapely

from explore.floorplan import FloorPlan
from explore.vueplan.phase1 import (Phase1Config, VisibilityPolygons, clip_to_field_of_view,
                                    clip_to_grazing_angle, clip_to_range, greedy_cover,
                                    obstacle_edges, plan_phase1)
from ibr.synthetic import make_world

O = np.zeros((1, 2))


def seg(*pts):
    return np.array(pts, float).reshape(1, 2, 2)


def test_range_case1_both_inside_kept_whole():
    s, i = clip_to_range(seg((-1, 1), (1, 1)), O, 0.0, 5.0)
    np.testing.assert_allclose(s, seg((-1, 1), (1, 1)))
    assert i.tolist() == [0]


def test_range_case2_one_inside_cut_at_circle():
    s, _ = clip_to_range(seg((0, 1), (10, 1)), O, 0.0, 5.0)
    np.testing.assert_allclose(s, seg((0, 1), (np.sqrt(24), 1)))


def test_range_case3_both_outside_chord_or_dropped():
    s, _ = clip_to_range(seg((-10, 3), (10, 3)), O, 0.0, 5.0)
    np.testing.assert_allclose(s, seg((-4, 3), (4, 3)))
    s, i = clip_to_range(seg((-10, 6), (10, 6)), O, 0.0, 5.0)
    assert len(s) == 0 and len(i) == 0


def test_min_range_splits_segment():
    s, i = clip_to_range(seg((-4, 1), (4, 1)), O, 2.0, 5.0)
    r3 = np.sqrt(3)
    np.testing.assert_allclose(s, np.array([[(-4, 1), (-r3, 1)], [(r3, 1), (4, 1)]]))
    assert i.tolist() == [0, 0]


@pytest.mark.parametrize("deg,half", [(70, 2 * np.tan(np.radians(70))), (45, 2.0)])
def test_grazing_angle_keeps_known_subsegment(deg, half):
    s, _ = clip_to_grazing_angle(seg((-10, 2), (10, 2)), O, np.radians(deg))
    np.testing.assert_allclose(s, seg((-half, 2), (half, 2)))


def test_field_of_view_clips_to_wedge():
    wall = seg((-10, 2), (10, 2))
    s, _ = clip_to_field_of_view(wall, O, np.array([np.pi / 2]), np.radians(90))
    np.testing.assert_allclose(s, seg((-2, 2), (2, 2)), atol=1e-12)
    s, _ = clip_to_field_of_view(wall, O, np.array([0.0]), np.radians(90))
    np.testing.assert_allclose(s, seg((2, 2), (10, 2)), atol=1e-12)
    s, _ = clip_to_field_of_view(wall, O, np.array([-np.pi / 2]), np.radians(90))
    assert len(s) == 0
    s, _ = clip_to_field_of_view(wall, O, np.array([0.0]), 2 * np.pi)
    np.testing.assert_allclose(s, wall)


def test_visibility_polygon_keeps_only_obstacle_edges():
    free = shapely.box(0, 0, 10, 10).difference(shapely.box(4, 4, 6, 6))
    plan = FloorPlan(free, exterior_is_wall=True)
    boundary, _ = plan.boundary_segments()
    edges, owner = obstacle_edges(VisibilityPolygons(free)(np.array([2.0, 5.0])), boundary)
    hole = np.isin(owner, np.arange(4, 8))  # the hole ring comes after the exterior ring
    L = np.linalg.norm(edges[:, 1] - edges[:, 0], axis=1)
    assert L[hole].sum() == pytest.approx(2.0)  # only the hole's face at x = 4
    np.testing.assert_allclose(edges[hole][:, :, 0], 4.0)
    # every kept edge lies on the boundary: total < perimeter, and the left wall is whole
    left = (np.abs(edges[:, :, 0]) < 1e-9).all(axis=1)
    assert L[left].sum() == pytest.approx(10.0)


def test_greedy_cover_enforces_overlap():
    cover = np.array([[1, 1, 1, 1, 1, 0, 0, 0, 0, 0],
                      [0, 0, 0, 0, 0, 1, 1, 1, 1, 0],   # much new, but no overlap at first
                      [0, 0, 0, 0, 1, 1, 1, 0, 0, 0],
                      [0, 0, 0, 0, 0, 0, 0, 0, 1, 1]], bool)
    length = np.ones(10)
    chosen, cov = greedy_cover(cover, length, min_overlap=0.2, min_gain=0.0, coverage_target=1.0)
    assert chosen == [0, 2, 1, 3]
    assert cov == pytest.approx([0.5, 0.7, 0.9, 1.0])
    chosen, _ = greedy_cover(cover, length, min_overlap=0.0, min_gain=0.0, coverage_target=1.0)
    assert chosen == [0, 1, 3]
    chosen, _ = greedy_cover(cover, length, min_overlap=0.0, min_gain=0.35, coverage_target=1.0)
    assert chosen == [0, 1]  # the third view would add only 1/10 < 35%
    chosen, _ = greedy_cover(cover, length, min_overlap=0.0, min_gain=0.0, coverage_target=0.85)
    assert chosen == [0, 1]


def test_courtyard_phase1_covers_95_percent():
    plan = FloorPlan(make_world("courtyard").free_space)
    res = plan_phase1(plan, Phase1Config(n_candidates=500), np.random.default_rng(0))
    assert res.boundary_coverage >= 0.95
    assert 2 <= len(res.chosen) <= 10
    assert np.all(np.diff(res.coverage) > 0)
    assert shapely.contains_xy(plan.free_space, res.views[:, 0], res.views[:, 1]).all()


def test_limited_field_of_view_needs_headings():
    plan = FloorPlan(make_world("courtyard").free_space)
    cfg = Phase1Config(n_candidates=1500, field_of_view_rad=np.radians(90))
    res = plan_phase1(plan, cfg, np.random.default_rng(1))
    assert np.ptp(res.headings) > 0
    full = plan_phase1(plan, Phase1Config(n_candidates=1500), np.random.default_rng(1),
                       positions=res.positions)
    # the same positions see at most as much with a 90 deg field of view
    assert (res.cover <= full.cover).all()
    assert res.boundary_coverage >= 0.9


@pytest.mark.parametrize("max_range,heading_deg,fov_deg,covered_m", [
    (30.0, 0.0, 360.0, 2.0),    # the hole's whole x = 4 face; its other faces are hidden
    (2.2, 0.0, 360.0, 1.8),     # range circle: |y - 5| <= sqrt(2.2^2 - 2^2) = 0.92 m
    (30.0, 0.0, 30.0, 1.0),     # 30 deg wedge: |y - 5| <= 2 tan 15 deg = 0.54 m
    (30.0, 180.0, 90.0, 0.0)])  # facing away from the hole
def test_phase1_cover_of_one_view_in_a_hand_made_room(max_range, heading_deg, fov_deg, covered_m):
    # 10 x 10 m yard, a 2 x 2 m obstacle at (4..6, 4..6), one view at (2, 5); the wall
    # elements are 0.1 m, counted when their midpoint lies on a clipped visible edge
    plan = FloorPlan(shapely.box(0, 0, 10, 10).difference(shapely.box(4, 4, 6, 6)))
    cfg = Phase1Config(max_range_m=max_range, field_of_view_rad=np.radians(fov_deg), min_gain=0.0)
    res = plan_phase1(plan, cfg, np.random.default_rng(0), positions=np.array([[2.0, 5.0]]),
                      headings=np.radians([heading_deg]))
    assert res.element_length.sum() == pytest.approx(8.0)
    assert res.cover[0] @ res.element_length == pytest.approx(covered_m)
    assert res.boundary_coverage == pytest.approx(covered_m / 8.0)
