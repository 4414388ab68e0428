import cv2
import numpy as np
import pytest
import shapely

from ibr.synthetic import loop_route, make_world


@pytest.mark.parametrize("name", ["office", "courtyard"])
def test_worlds_are_seeded_and_photographable(name, gl_ctx):
    world = make_world(name, 0)
    cam = world.default_cameras(4, 320, 240)[1]
    img = world.photograph(cam, gl_ctx)
    again = make_world(name, 0).photograph(cam, gl_ctx)
    other = make_world(name, 1).photograph(cam, gl_ctx)
    np.testing.assert_array_equal(img, again)
    assert np.abs(img.astype(int) - other).mean() > 5
    # rich enough for SIFT
    assert len(cv2.SIFT_create().detect(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY))) > 50


def test_office_dimensions_and_floor_plan(office):
    lo, hi = office.bounds
    np.testing.assert_allclose(hi - lo, [6, 8, 2.6], atol=1e-6)
    assert 30 < office.free_space.area < 48  # furniture takes some of the 48 m2
    assert (office.mesh.vertex_attributes["specular"] > 0.9).any()  # the shiny cabinet


def test_office_loop_is_clear_of_furniture(office):
    loop = shapely.LineString(loop_route(office))
    assert office.free_space.buffer(-0.3).contains(loop)


def test_courtyard_has_two_buildings_of_different_heights():
    world = make_world("courtyard", 0)
    assert len(world.free_space.interiors) == 2
    roofs = np.unique(np.round(world.mesh.vertices[:, 2], 3))
    assert {6.0, 12.0} <= set(roofs.tolist())


def test_default_cameras_stand_in_free_space():
    for name in ("office", "courtyard"):
        world = make_world(name, 0)
        for cam in world.default_cameras(12):
            assert world.free_space.contains(shapely.Point(cam.center[:2]))
