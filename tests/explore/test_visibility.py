"""The ray-sweep visibility polygon against answers worked out by hand."""

import numpy as np
import pytest
import shapely
from shapely.geometry import Polygon, box

from explore.visibility import VisibilityPolygons, visibility_polygon


def area(xy):
    return shapely.Polygon(xy).area


def test_a_convex_room_is_seen_whole_from_anywhere_inside():
    room = box(0, 0, 7, 4)
    for q in ([1, 1], [6.5, 3.9], [3.5, 2]):
        vis = visibility_polygon(room, np.array(q, float))
        assert area(vis) == pytest.approx(28.0, rel=1e-12)
        assert shapely.LinearRing(vis).is_ccw


def test_an_l_shaped_room_hides_what_is_round_the_corner():
    # arms [0,2]x[0,10] and [0,10]x[0,2]; from (1, 9) the line through the inner corner (2, 2)
    # meets the floor y = 0 at x = 1 + 9/7: seen are the vertical arm (20 m^2) and the triangle
    # (2, 2), (2, 0), (1 + 9/7, 0)
    room = shapely.union(box(0, 0, 2, 10), box(0, 0, 10, 2))
    vis = visibility_polygon(room, np.array([1.0, 9.0]))
    assert area(vis) == pytest.approx(20 + 0.5 * 2 * (9 / 7 - 1), rel=1e-12)
    assert any(np.allclose(v, [1 + 9 / 7, 0]) for v in vis)


def test_a_pillar_casts_its_shadow():
    # a 10x10 room, a pillar [4,6]x[4,6], the viewer at (5, 1): the rays through the pillar's
    # front corners (4, 4) and (6, 4) bound the shadow, |x - 5| < (y - 1) / 3 above y = 4:
    # 16/3 m^2 from y = 4 to 6 (4 of them the pillar) and 56/3 m^2 from y = 6 to 10
    room = Polygon(box(0, 0, 10, 10).exterior.coords, [box(4, 4, 6, 6).exterior.coords[::-1]])
    vis = visibility_polygon(room, np.array([5.0, 1.0]))
    assert area(vis) == pytest.approx(100 - 16 / 3 - 56 / 3, rel=1e-12)
    assert any(np.allclose(v, [2, 10]) for v in vis) and any(np.allclose(v, [8, 10]) for v in vis)


def test_a_point_outside_the_free_space_sees_nothing():
    vis = VisibilityPolygons(shapely.MultiPolygon([box(0, 0, 1, 1), box(5, 5, 6, 6)]))
    assert vis(np.array([3.0, 3.0])).shape == (0, 2)
    assert area(vis(np.array([5.5, 5.5]))) == pytest.approx(1.0)
