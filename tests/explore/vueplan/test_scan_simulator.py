"""The z-buffer scan simulator: returns lie on the mesh, within range, one beam per
direction over the whole sphere."""

import numpy as np
import pytest
import trimesh

from explore.vueplan.scan_simulator import ScanConfig, simulate_scan, window_cameras, window_ownership
from ibr.synthetic import make_world

WINDOW_LIM = np.tan(np.radians(30))


def test_windows_cover_the_sphere_once():
    keep = window_ownership(30)
    cams = window_cameras(np.zeros(3), 30)
    assert len(cams) == 18
    d = np.random.default_rng(0).normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    inside = []
    for c in cams:
        q = d @ c.world_from_cam[:3, :3]
        inside.append((q[:, 2] > 0) & (np.abs(q[:, :2]) <= WINDOW_LIM * q[:, 2:3]).all(axis=1))
    assert np.any(inside, axis=0).all()
    # kept beams: about one per (30 / 60 deg)^2 ... of the sphere: 4 pi sr / pixel solid angle
    assert 0.85 < keep.sum() / (4 * np.pi / np.radians(2.0) ** 2) < 1.25


def test_scan_points_lie_on_the_mesh_within_range(gl_ctx):
    world = make_world("courtyard")
    origin = np.array([0.0, 15.0, 1.6])
    cfg = ScanConfig(resolution_deg=1.0, min_range_m=2.0, max_range_m=25.0)
    scan = simulate_scan(world.renderer(gl_ctx), origin, cfg)
    r = np.linalg.norm(scan.points - origin, axis=1)
    assert len(scan.points) > 10000 and r.min() >= 2.0 and r.max() <= 25.0
    _, dist, _ = trimesh.proximity.closest_point(world.mesh, scan.points[::50])
    assert dist.max() < 1e-3
    # no-return beams: the sky and the ground beyond 25 m
    assert len(scan.no_return) > 0
    np.testing.assert_allclose(np.linalg.norm(scan.no_return, axis=1), 1.0)
    assert (scan.no_return[:, 2] > 0).sum() > 0.4 * len(scan.no_return)


def test_range_noise_from_generator(gl_ctx):
    world = make_world("courtyard")
    origin = np.array([0.0, 15.0, 1.6])
    cfg = ScanConfig(resolution_deg=2.0, max_range_m=25.0, min_range_m=0.0)
    clean = simulate_scan(world.renderer(gl_ctx), origin, cfg)
    noisy = simulate_scan(world.renderer(gl_ctx), origin, ScanConfig(2.0, 0.0, 25.0, range_noise_m=0.05),
                          np.random.default_rng(0))
    assert len(clean.points) == len(noisy.points)
    dr = np.linalg.norm(noisy.points - origin, axis=1) - np.linalg.norm(clean.points - origin, axis=1)
    assert np.std(dr) == pytest.approx(0.05, rel=0.1)
    with pytest.raises(ValueError):
        simulate_scan(world.renderer(gl_ctx), origin, ScanConfig(2.0, range_noise_m=0.05))
