"""Free space from the map mesh sliced at camera height, and candidate goals inside it
(Foster, Wang & Grupen, Sec. IV-B, "Choosing a goal")."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
import trimesh

from explore.candidates import (free_space_from_mesh, free_space_from_slice, sample_candidates, select_goals,
                                slice_segments)
from ibr.errors import InputError


def _iou(a, b) -> float:
    return a.intersection(b).area / a.union(b).area


@pytest.fixture(scope="module")
def camera_xy(office):
    return np.array([c.center[:2] for c in office.default_cameras(30)])


def test_free_space_of_office_matches_truth(office, camera_xy):
    free = free_space_from_mesh(office.mesh, office.view_height_m, camera_xy)
    assert _iou(free, office.free_space) > 0.8
    assert shapely.contains_xy(free, camera_xy[:, 0], camera_xy[:, 1]).all()
    # at camera height the cabinet and the shelf are walls: their footprints are not free
    assert not free.contains(shapely.Point(2.75, -0.2)) and not free.contains(shapely.Point(0.0, 3.8))


def test_leaky_mesh_is_sealed(office, camera_xy):
    v, f = trimesh.remesh.subdivide_to_size(office.mesh.vertices, office.mesh.faces, 0.25)
    mesh = trimesh.Trimesh(v, f, process=False)
    mesh.update_faces(np.random.default_rng(0).random(len(f)) > 0.05)  # 5% holes
    _, how = free_space_from_slice(slice_segments(mesh, 1.2), camera_xy)
    assert how.startswith("sealed")
    assert _iou(free_space_from_mesh(mesh, 1.2, camera_xy), office.free_space) > 0.8


def test_open_mesh_is_closed_by_its_convex_hull(office, camera_xy):
    segs = slice_segments(office.mesh, 1.2)
    open_side = segs[~np.all(np.isclose(segs[:, :, 1], 4.0), axis=1)]  # drop the y = 4 wall
    free, how = free_space_from_slice(open_side, camera_xy)
    assert how == "closed" and len(open_side) < len(segs)
    assert shapely.contains_xy(free, camera_xy[:, 0], camera_xy[:, 1]).all()
    # the walls still seen bound it and the hull closes the open side: the room, not the cameras' hull
    assert _iou(free, free_space_from_slice(segs, camera_xy)[0]) > 0.95
    assert free.within(shapely.MultiPoint(open_side.reshape(-1, 2)).convex_hull.buffer(1e-6))


def test_open_mesh_reaches_past_the_cameras(office, camera_xy):
    """All photos in the south of the room and the slice open in the north (the demo's first
    map): the free space still reaches the north wall, so goals can be chosen there."""
    segs = slice_segments(office.mesh, 1.2)
    open_side = segs[~np.all(np.isclose(segs[:, :, 1], 4.0), axis=1)]
    south = camera_xy[camera_xy[:, 1] < -1.5]
    free, how = free_space_from_slice(open_side, south)
    assert how == "closed" and free.contains(shapely.Point(0.0, 3.0))
    assert free.within(shapely.box(-3.0, -4.0, 3.0, 4.0))


def test_empty_slice_falls_back_to_camera_hull(camera_xy):
    free, how = free_space_from_slice(np.zeros((0, 2, 2)), camera_xy)
    assert how == "hull" and shapely.contains_xy(free, camera_xy[:, 0], camera_xy[:, 1]).all()
    assert free.within(shapely.MultiPoint(camera_xy).convex_hull.buffer(0.76))


def _square(lo: float, hi: float) -> list:
    c = [(lo, lo), (hi, lo), (hi, hi), (lo, hi)]
    return [[c[k], c[(k + 1) % 4]] for k in range(4)]


def test_a_reading_that_puts_most_cameras_in_walls_falls_back_to_their_hull():
    """A room 6 m square; one camera in a 0.2 m closed pocket, four on short blobs of a
    rough mesh crossing the camera plane. Sealing (and closing) would keep only the pocket,
    0.01 m2 around one camera of five: neither reading holds most cameras, so the free
    space is the cameras' grown hull, which holds them all."""
    cams = np.array([[1.0, 1.0], [3.0, 3.0], [4.0, 3.0], [3.0, 4.0], [4.0, 4.0]])
    blobs = [[(x - 0.1, y), (x + 0.1, y)] for x, y in cams[1:]]
    segs = np.array(_square(0.0, 6.0) + _square(0.9, 1.1) + blobs)
    free, how = free_space_from_slice(segs, cams)
    assert how == "hull" and free.area > 5.0
    assert shapely.contains_xy(free, cams[:, 0], cams[:, 1]).all()
    # with the blobs gone, the room is sealed as before and holds the four cameras
    free, how = free_space_from_slice(np.array(_square(0.0, 6.0) + _square(0.9, 1.1)), cams)
    assert how.startswith("sealed") and shapely.contains_xy(free, cams[1:, 0], cams[1:, 1]).all()


def test_candidates_inside_eroded_free_space(office, camera_xy):
    free = free_space_from_mesh(office.mesh, 1.2, camera_xy)
    poses = sample_candidates(free, 300, np.random.default_rng(5), clearance_m=0.3)
    assert poses.shape == (300, 3)
    assert shapely.contains_xy(free.buffer(-0.299), poses[:, 0], poses[:, 1]).all()
    assert np.all((poses[:, 2] >= -np.pi) & (poses[:, 2] < np.pi)) and np.std(poses[:, 2]) > 1.0
    np.testing.assert_array_equal(poses, sample_candidates(free, 300, np.random.default_rng(5), 0.3))
    spread = np.ptp(poses[:, :2], axis=0)
    assert spread[0] > 4.0 and spread[1] > 6.0  # uniform over the room, not a corner
    with pytest.raises(InputError, match="clearance"):
        sample_candidates(free, 5, np.random.default_rng(0), clearance_m=10.0)
    with pytest.raises(InputError, match="inside_xy"):
        free_space_from_mesh(office.mesh, 1.2, np.zeros((0, 2)))


def test_select_goals_best_first_and_spread():
    poses = np.array([[0, 0, 0], [0.1, 0, 1], [2, 0, 0], [4, 0, 0], [4.2, 0.1, 0]], dtype=float)
    scores = np.array([1.0, 3.0, 0.5, 2.0, np.nan])
    np.testing.assert_array_equal(select_goals(poses, scores, 10, 0.5), [1, 3, 2])
    np.testing.assert_array_equal(select_goals(poses, scores, 2, 0.0), [1, 3])
    np.testing.assert_array_equal(select_goals(poses, scores, 10, 0.0), [1, 3, 0, 2])
    with pytest.raises(InputError, match="scores"):
        select_goals(poses, scores[:3], 2)
