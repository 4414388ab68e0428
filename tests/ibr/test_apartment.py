"""`synthetic:apartment`: over many seeds the floor plan is connected and traversable, the
doorways are clear, the textures and furniture meet the world's brief; the generated
routes stay clear in every world. Geometry tests build the apartments with coarse
textures (the layout does not depend on them); one test renders a full one."""

import itertools

import cv2
import numpy as np
import pytest
import shapely
import trimesh

from ibr.scene import load_scene
from ibr.synthetic import loop_route, make_world
from ibr.synthetic.apartment import DOOR_CLEARANCE_M, DOOR_SIDE_M, make_apartment
from ibr.synthetic.routes import tour_route

SEEDS = range(50)
ROBOT_RADIUS_M = 0.25


@pytest.fixture(scope="module")
def apartments():
    return [make_apartment(s, texels_per_m=4) for s in SEEDS]


def test_free_space_is_one_polygon_through_every_doorway(apartments):
    for w in apartments:
        assert w.free_space.geom_type == "Polygon", w.seed
        floors = shapely.union_all([r.polygon for r in w.rooms])
        assert w.free_space.area < floors.area + sum(d.width * d.thickness for d in w.doorways) + 1e-6
        for d in w.doorways:
            assert w.free_space.contains(shapely.Point(d.centre)), (w.seed, d)


def test_every_room_is_reachable_by_the_robot(apartments):
    for w in apartments:
        reach = w.free_space.buffer(-ROBOT_RADIUS_M)
        assert reach.geom_type == "Polygon", w.seed  # one piece: every part reaches every other
        for r in w.rooms:
            assert reach.intersection(r.polygon).area > 0.5, (w.seed, r.name)


def test_rooms_and_corridor(apartments):
    for w in apartments:
        kinds = [r.kind for r in w.rooms]
        assert kinds.count("corridor") == 1 and 2 <= kinds.count("room") <= 4, w.seed
        area = np.sort([r.polygon.area for r in w.rooms if r.kind == "room"])
        assert np.all(area[1:] > 1.1 * area[:-1]), w.seed  # different sizes
        assert len({r.name for r in w.rooms}) == len(w.rooms)
        for r in w.rooms:  # every room opens onto the corridor
            if r.kind == "room":
                assert any(set(d.rooms) == {r.name, "corridor"} for d in w.doorways), (w.seed, r.name)


def test_doorways_are_wide_enough_and_clear_of_furniture(apartments):
    assert DOOR_CLEARANCE_M >= 2 * ROBOT_RADIUS_M + 0.2
    for w in apartments:
        names = {r.name for r in w.rooms}
        for d in w.doorways:
            assert 0.8 <= d.width <= 1.2 and 0.05 < d.thickness < 0.3, (w.seed, d)
            assert set(d.rooms) <= names and d.rooms[0] != d.rooms[1]
            zone = d.zone(DOOR_CLEARANCE_M, DOOR_SIDE_M)
            assert zone.difference(w.free_space).area < 1e-9, (w.seed, d)  # no furniture, no wall
            n = np.asarray(d.normal)  # rooms[0] behind, rooms[1] in front
            before = np.asarray(d.centre) - (d.thickness / 2 + 0.3) * n
            after = np.asarray(d.centre) + (d.thickness / 2 + 0.3) * n
            assert (w.room_at(before), w.room_at(after)) == d.rooms, (w.seed, d)
            assert w.room_at(d.centre) is None  # the threshold is in the wall


def test_walls_have_thickness_at_the_doorways():
    w = make_apartment(3, texels_per_m=4)
    for d in w.doorways:  # from the middle of the opening sideways: the jamb, at half the width
        n = np.asarray(d.normal)
        along = np.r_[-n[1], n[0], 0.0]
        origin = np.r_[d.centre, 1.0]
        hits, _, _ = w.mesh.ray.intersects_location([origin, origin], [along, -along])
        dist = np.linalg.norm(hits - origin, axis=1)
        np.testing.assert_allclose(np.sort(dist)[:2], d.width / 2, atol=1e-6)


def test_seeds_give_different_layouts(apartments):
    for a, b in itertools.combinations(apartments, 2):
        assert a.free_space.symmetric_difference(b.free_space).area > 1.0, (a.seed, b.seed)
    assert len({len(w.rooms) for w in apartments}) == 3  # 2, 3 and 4 rooms all occur


def test_textures_vary_with_a_textureless_wall_and_a_shiny_surface(apartments):
    walls, floors = {"painted_wall", "wallpaper"}, {"wood_floor", "floor_tiles", "carpet"}
    for w in apartments:
        kinds = w.mesh.metadata["quad_textures"]
        assert "plain_wall" in kinds, w.seed
        assert len(walls & set(kinds)) == 2 and len(floors & set(kinds)) >= 2, w.seed
        assert w.mesh.vertex_attributes["specular"].max() >= 1.0, w.seed
        assert len(w.mesh.faces) < 600, w.seed  # lean: a few hundred triangles


def test_start_poses_are_in_rooms_and_clear(apartments):
    rng = np.random.default_rng(0)
    reach = {}
    for w in apartments:
        x, y, theta = w.start_pose(rng)
        assert w.free_space.buffer(-ROBOT_RADIUS_M).contains(shapely.Point(x, y)), w.seed
        room = w.room_at((x, y))
        assert room is not None and w.room(room).kind == "room"
        assert -np.pi <= theta <= np.pi
        reach[room] = reach.get(room, 0) + 1
    assert len(reach) >= 3  # the start room is drawn, not always the same


def test_default_cameras_are_spread_over_the_rooms(apartments):
    for w in apartments[:10]:
        cams = w.default_cameras(24)
        assert len(cams) == 24
        for cam in cams:
            assert w.free_space.contains(shapely.Point(cam.center[:2])), w.seed
        assert {w.room_at(c.center[:2]) for c in cams} == {r.name for r in w.rooms}


def test_tour_visits_every_room_and_stays_clear(apartments):
    for w in apartments[::2]:
        route = tour_route(w)
        np.testing.assert_array_equal(route[0], route[-1])
        line = shapely.LineString(route)
        assert w.free_space.buffer(-ROBOT_RADIUS_M).covers(line), w.seed
        for r in w.rooms:
            assert line.intersection(r.polygon).length > 1.0, (w.seed, r.name)


@pytest.mark.parametrize("name", ["office", "courtyard"])
def test_single_room_worlds_have_one_room_and_a_loop_around_the_middle(name):
    w = make_world(name, 2)
    assert len(w.rooms) == 1 and not w.doorways
    route = tour_route(w)
    line = shapely.LineString(route)
    assert w.free_space.buffer(-ROBOT_RADIUS_M).covers(line)
    room = w.rooms[0].polygon
    assert shapely.Polygon(route).contains(room.centroid)  # around the middle
    assert 0.2 < shapely.Polygon(route).area / room.area < 0.6
    if name == "office":  # half way to the walls: the hand-made demo loop
        np.testing.assert_allclose(route, loop_route(w))


def test_rendered_apartment_rooms_look_different(gl_ctx):
    world = make_world("apartment", 0)
    atlas = np.asarray(world.mesh.visual.material.image)
    assert atlas.shape[1] == 4096 and atlas.shape[0] <= 4096
    cams = world.default_cameras(12, 320, 240)
    imgs = [world.photograph(c, gl_ctx) for c in cams]
    sift = cv2.SIFT_create()
    features = [len(sift.detect(cv2.cvtColor(i, cv2.COLOR_RGB2GRAY))) for i in imgs]
    assert all(i.std() > 10 for i in imgs)  # not blank
    assert np.median(features) > 50  # rich enough for SIFT (a plain wall may fill one view)
    rooms = [world.room_at(c.center[:2]) for c in cams]
    assert len(set(rooms)) == len(world.rooms)

    def colours(img):  # hue-saturation histogram
        hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV)
        h = cv2.calcHist([hsv], [0, 1], None, [18, 8], [0, 180, 0, 256])
        return cv2.normalize(h, h).ravel()

    hists = [colours(i) for i in imgs]
    same, other = [], []
    for a, b in itertools.combinations(range(len(imgs)), 2):
        corr = cv2.compareHist(hists[a], hists[b], cv2.HISTCMP_CORREL)
        (same if rooms[a] == rooms[b] else other).append(corr)
    assert np.mean(other) < 0.5 < np.mean(same)  # each room has its own paint and floor


def test_apartment_loads_as_a_scene(gl_ctx):
    scene = load_scene("synthetic:apartment?seed=1&views=4&width=96&height=72")
    assert len(scene) == 4 and scene.world.name == "apartment" and scene.meta["seed"] == 1
    assert isinstance(scene.mesh, trimesh.Trimesh)
