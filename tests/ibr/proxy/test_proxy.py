"""Geometry from photos: triangulation with known poses, normals, Poisson mesh, hole filling,
the cached proxy of a synthetic scene against its true mesh."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

from ibr.camera import Camera, intrinsics_from_fov
from ibr.render.depth_maps import render_depth_maps
from ibr.render.hole_filling import push_pull
from ibr.proxy.normals import estimate_normals, merge_repeats, remove_outliers
from ibr.proxy.poisson import MeshingError, PoissonConfig, poisson_mesh
from ibr.proxy.proxy_geometry import ProxyConfig, build_proxy, cache_dir, triangulated_points
from ibr.scene import load_scene
from ibr.proxy.triangulation import (fundamental_matrix, neighbour_pairs, sampson_distance,
                               triangulate_pair, TriangulationConfig)


def _cams():
    K = intrinsics_from_fov(60, 320, 240)
    return [Camera.look_at((x, 0, 1), (0, 6, 1), K, 320, 240) for x in (-1.0, -0.5, 0.0, 0.5, 3.0)]


def test_epipolar_geometry_and_triangulation_of_known_poses():
    rng = np.random.default_rng(0)
    a, b = _cams()[1:3]
    X = rng.uniform([-1, 4, 0], [1, 7, 2], (50, 3))
    xa, xb = a.project(X)[0], b.project(X)[0]
    F = fundamental_matrix(a, b)
    assert sampson_distance(F, xa, xb).max() < 1e-6
    assert sampson_distance(F, xa, xb + [0, 5.0]).min() > 1.0   # off the epipolar line
    P, idx = triangulate_pair(a, b, xa + rng.normal(0, 0.2, xa.shape), xb, TriangulationConfig())
    assert len(idx) > 45
    assert np.median(np.linalg.norm(P - X[idx], axis=1)) < 0.05


def test_neighbour_pairs_join_close_cameras():
    pairs = {tuple(p) for p in neighbour_pairs(_cams(), 1)}
    assert (0, 1) in pairs and (3, 4) in pairs and (0, 4) not in pairs


def test_normals_face_the_cameras_and_outliers_go():
    rng = np.random.default_rng(1)
    pts = np.c_[rng.uniform(-1, 1, (400, 2)), rng.normal(0, 0.002, 400)]
    pts = np.r_[pts, [[0, 0, 5.0]]]
    keep = remove_outliers(pts)
    assert not keep[-1] and keep[:-1].mean() > 0.95
    n = estimate_normals(pts[:-1], np.tile([0.3, 0, 2.0], (400, 1)))
    assert np.median(n[:, 2]) > 0.99


def test_repeats_of_a_feature_merge_to_one_point():
    """Three places, one seen from 4 pairs (4 points a millimetre apart), one from 1, and a
    thin wall's two faces in one cell (their normals cancel): one point each, at the mean."""
    rng = np.random.default_rng(0)
    a = np.array([0.525, 0.525, 0.525]) + rng.normal(0, 0.001, (4, 3))  # mid-cell: cells are cut at fixed planes
    points = np.vstack([a, [[2.0, 0.0, 1.0]], [[1.0, 1.025, 1.0], [1.001, 1.025, 1.0]]])
    normals = np.array([[1.0, 0, 0]] * 4 + [[0, 0, 1.0]] + [[1.0, 0, 0], [-1.0, 0, 0]])
    colors = np.array([[10, 20, 30]] * 4 + [[200, 200, 200]] + [[0, 0, 0], [100, 100, 100]], np.uint8)
    p, n, c = merge_repeats(points, normals, colors, cell_m=0.05)
    assert len(p) == 3
    k = int(np.argmin(np.linalg.norm(p - a.mean(0), axis=1)))
    assert np.allclose(p[k], a.mean(0)) and np.allclose(n[k], [1, 0, 0]) and c[k].tolist() == [10, 20, 30]
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)  # the wall's cell keeps one of its normals
    assert len(merge_repeats(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3), np.uint8), 0.05)[0]) == 0


def test_poisson_mesh_of_a_sphere_and_a_cap():
    rng = np.random.default_rng(2)
    d = rng.normal(size=(1500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    colors = np.full((len(d), 3), 200, np.uint8)
    sphere = poisson_mesh(2.0 * d, d, colors, PoissonConfig(depth=6))
    assert len(sphere.faces) > 500
    assert np.percentile(np.abs(np.linalg.norm(sphere.vertices, axis=1) - 2.0), 95) < 0.05
    up = d[:, 2] > 0                                       # the upper half only
    cap = poisson_mesh(2.0 * d[up], d[up], colors[up], PoissonConfig(depth=6, max_gap_spacing=3.0))
    assert cap.vertices[:, 2].min() > -1.0                 # Poisson's closing lid was cut off
    with pytest.raises(MeshingError):
        poisson_mesh(d[:10], d[:10], colors[:10])


def test_push_pull_keeps_known_and_fills_holes():
    ramp = np.fromfunction(lambda i, j: i + 2.0 * j, (40, 50))
    known = np.random.default_rng(3).random((40, 50)) > 0.6
    filled = push_pull(ramp, known)
    np.testing.assert_array_equal(filled[known], ramp[known])
    assert ramp.min() <= filled.min() and filled.max() <= ramp.max()
    assert np.abs(filled - ramp)[~known].mean() < 4.0


@pytest.fixture(scope="module")
def small_office():
    return load_scene("synthetic:office?views=24&width=320&height=240")


def test_proxy_from_photos_lies_on_the_true_surface(gl_ctx, small_office, tmp_path):
    small_office = dataclasses.replace(small_office, root=tmp_path)  # a fresh cache
    cfg = ProxyConfig(poisson=PoissonConfig(depth=7))
    pts, _, normals = triangulated_points(small_office, cfg)
    assert len(pts) > 1000
    _, dist, _ = trimesh.proximity.closest_point(small_office.mesh, pts[::10])
    assert np.median(dist) < 0.01                          # metres
    proxy = build_proxy(small_office, cfg)
    again = build_proxy(small_office, cfg)                 # from the cache
    assert len(list((tmp_path / ".ibrnav_cache").glob("proxy_*.ply"))) == 1
    assert cache_dir(small_office) == tmp_path / ".ibrnav_cache"
    assert len(again.mesh.faces) == len(proxy.mesh.faces)
    # the proxy's depth maps agree with the true depth where both exist
    true = render_depth_maps(small_office.mesh, small_office.cameras[:4], gl_ctx)
    est = render_depth_maps(proxy.mesh, small_office.cameras[:4], gl_ctx)
    both = (true > 0) & (est > 0)
    assert both.mean() > 0.3
    assert np.median(np.abs(est[both] - true[both]) / true[both]) < 0.03


def test_a_scene_too_small_to_triangulate_is_one_error_naming_it():
    """8 photos of 160x120 give SIFT almost nothing to triangulate: the error names the scene
    and says what to change, instead of a numpy reduction error."""
    scene = load_scene("synthetic:office?views=8&width=160&height=120")
    with pytest.raises(MeshingError, match=r"synthetic:office.*points triangulated"):
        build_proxy(scene, use_cache=False)
