"""Phase II (Blaer & Allen Algorithm 2): voxel carving and visibility counts on tiny grids
with known answers, and the NBV loop on the synthetic courtyard."""

from dataclasses import replace

import numpy as np
import pytest
import shapely
import trimesh

from explore.floorplan import FloorPlan
from explore.vueplan.voxel_grid import (EMPTY, OCCUPIED, UNSEEN, VoxelGrid, boundary_unseen, insert_scan,
                                ray_voxels, segments_clear, blocker_distance)
from explore.vueplan.voxel_occlusion import VoxelOccluder, blocker_faces
from explore.vueplan.phase1 import Phase1Config, plan_phase1
from explore.vueplan.phase2 import (Phase2Config, SurfaceCoverage, count_visible, count_visible_per_ray, reachable_views,
                                    ground_candidates, plan_phase2)
from explore.vueplan.scan_simulator import ScanConfig, simulate_scan
from ibr.synthetic import make_world


def test_ray_voxels_walks_every_crossed_voxel():
    _, idx = ray_voxels((5, 5, 1), np.array([[0.5, 0.5, 0.5]]), np.array([[4.5, 2.5, 0.5]]))
    assert idx.tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [2, 1, 0], [3, 1, 0], [3, 2, 0], [4, 2, 0]]


def test_carving_marks_points_and_passes_through_occupied():
    grid = VoxelGrid.covering([0, 0, 0], [10, 3, 3], 1.0)
    scanner = np.array([0.5, 1.5, 1.5])
    insert_scan(grid, scanner, np.array([[4.5, 1.5, 1.5]]))
    line = grid.state[:, 1, 1]
    assert line.tolist() == [EMPTY] * 4 + [OCCUPIED] + [UNSEEN] * 5
    insert_scan(grid, scanner, np.array([[7.5, 1.5, 1.5]]))
    assert grid.state[:, 1, 1].tolist() == [EMPTY] * 4 + [OCCUPIED] + [EMPTY] * 2 + [OCCUPIED] + [UNSEEN] * 2
    # a point in an empty voxel turns it occupied; nothing off the line changed
    insert_scan(grid, scanner, np.array([[2.5, 1.5, 1.5]]))
    assert grid.state[2, 1, 1] == OCCUPIED
    assert (grid.state[:, [0, 2], :] == UNSEEN).all() and (grid.state[:, :, [0, 2]] == UNSEEN).all()
    # no-return beams carve out to the maximum range
    insert_scan(grid, scanner, np.empty((0, 3)), np.array([[0.0, 0.0, 1.0]]), max_range_m=1.0)
    assert grid.state[0, 1, 2] == EMPTY


def _wall_grid():
    """6 x 5 x 1 grid of 1 m voxels, all seen-empty, except an unseen column at x = 5 and one
    occupied voxel at (3, 2)."""
    grid = VoxelGrid.covering([0, 0, 0], [6, 5, 1], 1.0)
    grid.state[:] = EMPTY
    grid.state[5] = UNSEEN
    grid.state[3, 2, 0] = OCCUPIED
    return grid


def test_boundary_unseen_and_exposed_faces():
    idx, faces = boundary_unseen(_wall_grid())
    assert idx.tolist() == [[5, j, 0] for j in range(5)]
    assert faces.tolist() == [[True, False, False, False, False, False]] * 5  # the -x face


@pytest.mark.parametrize("grazing_deg,max_range,expected", [(70, 60, 3), (20, 60, 2), (70, 5.1, 1)])
def test_visibility_count_known_answer(grazing_deg, max_range, expected):
    # from (0.5, 2.7): the rays to the unseen voxels (5, 1) and (5, 2) cross the occupied
    # voxel (3, 2); (5, 0), (5, 3), (5, 4) are clear, at 23.7, 9.1 and 19.8 deg from the
    # face normal and 5.46, 5.06 and 5.31 m away
    grid = _wall_grid()
    cfg = Phase2Config(max_grazing_rad=np.radians(grazing_deg), max_range_m=max_range, min_range_m=0.0)
    views = np.array([[0.5, 2.7, 0.5], [5.5, 2.5, 0.5]])  # the second stands in unseen space
    counts = count_visible(grid, views, cfg)
    assert counts.tolist() == [expected, 0]
    assert count_visible_per_ray(grid, views, cfg).tolist() == [expected, 0]


def test_half_space_behind_the_exposed_face_is_pruned_before_walking():
    # unseen column x = 4 whose +x neighbour is occupied: only its -x face is exposed.
    # Views at x = 7.5 stand behind that face: they count 0 and their rays are never walked.
    grid = VoxelGrid.covering([0, 0, 0], [9, 5, 1], 1.0)
    grid.state[:] = EMPTY
    grid.state[4] = UNSEEN
    grid.state[5] = OCCUPIED
    front = np.array([[0.5, 2.5, 0.5], [1.5, 2.5, 0.5]])
    behind = np.array([[7.5, 2.5, 0.5], [8.5, 0.5, 0.5]])
    cfg = Phase2Config(min_range_m=0.0, max_range_m=60.0, max_grazing_rad=np.radians(70))
    stats = {}
    counts = count_visible(grid, np.vstack([front, behind]), cfg, stats=stats)
    # grazing: from (0.5, 2.5) the voxels at y = 0.5..4.5 are at atan(2/3.5) = 29.7 deg at
    # most; from (1.5, 2.5) at atan(2/2.5) = 38.7 deg: all 5 seen from both
    assert counts.tolist() == [5, 5, 0, 0]
    assert stats["pairs"] == 5 * 4 and stats["rays"] == 5 * 2


def test_ground_candidates_lie_in_free_space_at_sensor_height():
    grid = VoxelGrid.covering([0, 0, 0], [10, 10, 3], 1.0)
    free = shapely.box(0, 0, 10, 10).difference(shapely.box(4, 4, 6, 6))
    cfg = Phase2Config(sensor_height_m=1.6, candidate_clearance_m=0.3)
    views = ground_candidates(grid, free, cfg)
    assert len(views) == 100 - 4 and np.all(views[:, 2] == 1.6)  # the 4 centres in the hole go
    np.testing.assert_allclose(np.mod(views[:, :2], 1.0), 0.5)
    stride = ground_candidates(grid, free, Phase2Config(candidate_stride=2))
    assert len(stride) == 25 - 1  # centres 0.5, 2.5, ..., 8.5; (4.5, 4.5) is in the hole
    # 0.6 m clearance: the outer ring of centres goes (8 x 8 left) and so do the 4 x 4
    # centres 3.5..6.5 around the hole, except its 4 corners (0.71 m from the hole's corners)
    assert len(ground_candidates(grid, free, Phase2Config(candidate_clearance_m=0.6))) == 64 - (16 - 4)


def test_vectorised_walk_matches_scalar_reference():
    rng = np.random.default_rng(3)
    grid = VoxelGrid.covering([0, 0, 0], [20, 20, 8], 1.0)
    grid.state[:] = rng.choice([UNSEEN, EMPTY, OCCUPIED], grid.shape, p=[0.05, 0.9, 0.05])
    views = np.c_[rng.uniform(0, 20, (12, 2)), np.full(12, 1.37)]  # off the voxel lattice: no ties
    reference = count_visible_per_ray(grid, views, Phase2Config(max_range_m=15.0, min_range_m=1.0))
    assert reference.sum() > 0
    for backend in ("gl", "embree", "walk"):
        cfg = Phase2Config(max_range_m=15.0, min_range_m=1.0, ray_backend=backend)
        np.testing.assert_array_equal(count_visible(grid, views, cfg), reference)
    blocked = grid.state != EMPTY
    a, b = rng.uniform(0, [20, 20, 8], (3000, 3)), rng.uniform(0, [20, 20, 8], (3000, 3))
    walk = segments_clear(blocked, a, b)
    assert 0 < walk.sum() < len(walk)
    np.testing.assert_array_equal(walk, segments_clear(blocked, a, b, blocker_distance(blocked)))
    np.testing.assert_array_equal(walk, VoxelOccluder(blocked).clear(a, b))


def test_blocker_faces_and_occluder_on_two_voxels():
    blocked = np.zeros((4, 3, 3), bool)
    blocked[1, 1, 1] = blocked[2, 1, 1] = True    # two voxels side by side: 10 outer faces
    vertices, triangles = blocker_faces(blocked)
    assert len(triangles) == 20 and len(vertices) == 40
    assert vertices.min() == 1 and vertices.max() == 3  # the box [1, 3] x [1, 2] x [1, 2]
    occ = VoxelOccluder(blocked)
    a = np.array([[0.5, 1.5, 1.5], [0.5, 0.5, 1.5], [1.5, 1.5, 1.5], [1.5, 1.5, 1.5], [3.5, 1.4, 1.6]])
    b = np.array([[3.5, 1.5, 1.5], [3.5, 0.5, 1.5], [0.5, 1.5, 1.5], [2.5, 1.5, 1.5], [0.5, 1.6, 1.4]])
    # through both, beside them, out of its own blocked voxel, into the blocked neighbour
    # (no face between the two: found by the next-voxel lookup), through from the far side
    assert occ.clear(a, b).tolist() == [False, True, True, False, False]


def test_phase2_raises_coverage_each_iteration_and_stops_when_exhausted(gl_ctx):
    world = make_world("courtyard")
    rng = np.random.default_rng(0)
    p1 = plan_phase1(FloorPlan(world.free_space), Phase1Config(n_candidates=300), rng)
    scfg = ScanConfig(resolution_deg=2.0, max_range_m=60.0)
    grid = VoxelGrid.covering([-20, -20, 0], [20, 20, 13], 1.0)
    cov = SurfaceCoverage(world.mesh, 4000, rng, tol_m=0.5)
    renderer = world.renderer(gl_ctx)
    # start from the first Phase I scan only, so Phase II has occlusions to resolve
    scan = simulate_scan(renderer, np.r_[p1.views[0], 1.6], scfg)
    insert_scan(grid, scan.origin, scan.points, scan.no_return, scan.max_range_m)
    cov.add(scan.points)

    def acquire(view):
        s = simulate_scan(renderer, view, scfg)
        cov.add(s.points)
        return s

    cfg = Phase2Config(stop_fraction=0.1, max_views=8, candidate_stride=2)
    rows = plan_phase2(grid, ground_candidates(grid, world.free_space, cfg), acquire, cfg,
                       lambda: cov.fraction)
    assert len(rows) >= 3
    covs = [r.surface_coverage for r in rows]
    assert all(b > a for a, b in zip(covs, covs[1:])), covs
    assert rows[-1].stop == "exhausted"                 # stopped by the fraction, not the guard
    assert rows[-1].visible_to_nbv < cfg.stop_fraction * rows[-1].boundary_unseen
    assert all(r.visible_to_nbv >= cfg.stop_fraction * r.boundary_unseen for r in rows[:-1])
    occ = [r.seen_occupied for r in rows]
    assert occ == sorted(occ)


def test_gl_counts_agree_with_embree_and_choose_the_same_view(gl_ctx):
    """On the courtyard after one scan (1 m voxels, views on the voxel lattice, so ties at
    voxel edges are common): the GL pass's next best view is Embree's, or scores within 2 %
    of it under Embree's counts (measured 0.995; the numpy walk's: 0.973), and the counts
    agree within a few per cent in total."""
    world = make_world("courtyard")
    grid = VoxelGrid.covering([-20, -20, 0], [20, 20, 13], 1.0)
    scan = simulate_scan(world.renderer(gl_ctx), np.array([12.0, 12.0, 1.6]), ScanConfig(resolution_deg=2.0))
    insert_scan(grid, scan.origin, scan.points, scan.no_return, scan.max_range_m)
    cfg = Phase2Config(candidate_stride=2)
    views = ground_candidates(grid, world.free_space, cfg)
    exact = count_visible(grid, views, replace(cfg, ray_backend="embree"))
    gl = count_visible(grid, views, cfg)
    assert exact.max() > 100
    assert exact[np.argmax(gl)] >= 0.98 * exact.max()
    assert np.abs(gl - exact).sum() <= 0.04 * exact.sum()  # measured 0.029 (the numpy walk: 0.015)
    # the two-pass mode of large grids (rank on every 4th voxel, re-count the best 8 views)
    ranked = count_visible(grid, views, replace(cfg, gl_exact_pairs=1, gl_estimate_stride=4, gl_refine_views=8))
    best = np.argmax(ranked)
    assert ranked[best] == gl[best]                    # the NBV's count is exact
    assert exact[best] >= 0.98 * exact.max()


def test_in_sight_of_views_on_a_box():
    """Samples on a 2 m cube seen from (5, 0, 0): only the +x face (1/6 of the area) is in
    sight; from both sides 1/3; out of range none."""
    box = trimesh.creation.box((2, 2, 2))
    cov = SurfaceCoverage(box, 6000, np.random.default_rng(0), tol_m=0.01)
    one = cov.in_sight(box, np.array([[5.0, 0, 0]]), 0.5, 60.0)
    assert abs(one.mean() - 1 / 6) < 0.02
    assert np.all(cov.samples[one, 0] > 1 - 5 * cov.tol_m)  # within tol of the face counts as on it
    both = cov.in_sight(box, np.array([[5.0, 0, 0], [-5.0, 0, 0]]), 0.5, 60.0)
    assert abs(both.mean() - 1 / 3) < 0.03
    assert not cov.in_sight(box, np.array([[5.0, 0, 0]]), 0.5, 3.5).any()


def test_reachable_views_keep_the_start_component():
    free = shapely.box(0, 0, 4, 4).union(shapely.box(6, 0, 10, 4))  # two rooms, no door
    views = np.array([[1.0, 1, 1.6], [3, 3, 1.6], [8, 2, 1.6]])
    np.testing.assert_array_equal(reachable_views(views, free, np.array([[2.0, 2]]), 0.3), [True, True, False])
    np.testing.assert_array_equal(reachable_views(views, free, np.array([[2.0, 2], [7, 1]]), 0.3), [True] * 3)
