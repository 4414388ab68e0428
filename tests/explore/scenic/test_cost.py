"""NBV cost (Mendez et al. eq. 2-4): φ lowest for rays perpendicular to the point's main
uncertainty axis, γ for rays that meet nothing observed, C_view the ray mean."""

import numpy as np
import pytest

from explore.scenic.cost import NBVConfig, first_occupied, point_cost, pose_rays, too_near, view_costs
from explore.scenic.map import EMPTY, MapConfig, ScenicMap
from explore.scenic.pose import CameraModel

MODEL = CameraModel(64, 48, 60.0, pitch_rad=0.0)


def test_phi_is_lowest_for_rays_perpendicular_to_e():
    e = np.array([[1.0, 0, 0]])
    angles = np.radians(np.arange(0, 181, 15))
    r = np.stack([np.cos(angles), np.sin(angles), 0 * angles], -1)
    phi = point_cost(np.full(len(r), 2.0), np.repeat(e, len(r), 0), r)
    assert np.argmin(phi) == 6  # 90 degrees
    np.testing.assert_allclose(phi, np.exp(-2.0 * np.abs(np.sin(angles))), atol=1e-12)
    assert phi[0] == pytest.approx(1.0) and phi[6] == pytest.approx(np.exp(-2.0))


def wall_map(axis: np.ndarray, lam: float = 0.01) -> ScenicMap:
    """Empty room 4 x 4 x 2 m with a wall of points at y = 1.5, each with covariance
    elongated along `axis` (largest eigenvalue lam m^2)."""
    m = ScenicMap.covering([-2, -2, 0], [2, 2, 2], MapConfig(voxel_m=0.1))
    m.state[:] = EMPTY
    xs, zs = np.meshgrid(np.linspace(-1.95, 1.95, 40), np.linspace(0.05, 1.95, 20))
    P = np.c_[xs.ravel(), np.full(xs.size, 1.55), zs.ravel()]
    a = axis / np.linalg.norm(axis)
    cov = 1e-6 * np.eye(3) + (lam - 1e-6) * np.outer(a, a)
    m.insert(P - [0, 1.0, 0], P, np.repeat(cov[None], len(P), 0))
    return m


def test_view_cost_prefers_rays_across_the_uncertainty():
    """The same head-on view of a wall costs more when the points are uncertain along the
    viewing direction (rays ∥ e_p) than across it (rays ⟂ e_p)."""
    cfg = NBVConfig(gamma=1.0, eigen_scale=400.0, ray_cols=8, ray_rows=6, min_range_m=0.0)
    q = np.array([[0.0, 0.3, 1.0, np.pi / 2]])
    along = view_costs(wall_map(np.array([0.0, 1.0, 0.0])), q, MODEL, cfg)[0]
    across = view_costs(wall_map(np.array([1.0, 0.0, 0.0])), q, MODEL, cfg)[0]
    assert across < 0.05 and along > 5 * across


def test_rays_meeting_nothing_cost_gamma():
    m = ScenicMap.covering([-2, -2, 0], [2, 2, 2], MapConfig(voxel_m=0.1))
    m.state[:] = EMPTY
    for gamma in (0.0, 0.3, 1.0):
        c = view_costs(m, np.array([[0.0, 0.0, 1.0, 0.0], [0.5, 0.5, 1.0, 2.0]]), MODEL,
                       NBVConfig(gamma=gamma))
        np.testing.assert_allclose(c, gamma)


def test_view_cost_is_mean_of_psi_and_gamma():
    """Half the rays meet the wall (ψ known by hand), the other half see unobserved space."""
    m = wall_map(np.array([0.0, 0.0, 1.0]), lam=0.005)  # e_p vertical: every ray ⟂ in yaw only
    m.state[:, :, 10:] = 0  # upper half unobserved
    cfg = NBVConfig(gamma=0.4, eigen_scale=100.0, ray_cols=4, ray_rows=4, min_range_m=0.5)
    q = np.array([[0.0, 0.0, 1.0, np.pi / 2]])
    rays = pose_rays(q, MODEL, cfg)[0]
    hit = first_occupied(m, q[:, :3], rays[None], cfg.max_range_m)[0]
    e = np.array([0, 0, 1.0])
    phi = np.exp(-100 * 0.005 * np.linalg.norm(np.cross(e, rays), axis=1))
    expected = np.where(hit >= 0, phi, 0.4).mean()
    assert (hit >= 0).any() and (hit < 0).any()
    assert view_costs(m, q, MODEL, cfg)[0] == pytest.approx(expected, rel=1e-6)


def test_first_occupied_stops_at_unobserved():
    m = ScenicMap.covering([0, 0, 0], [3, 1, 1], MapConfig(voxel_m=0.1))
    m.state[:] = EMPTY
    m.state[20, 5, 5] = 2
    o = np.array([[0.05, 0.55, 0.55]])
    d = np.array([[[1.0, 0, 0]]])
    assert first_occupied(m, o, d, 5.0)[0, 0] == np.ravel_multi_index((20, 5, 5), m.state.shape)
    m.state[10, 5, 5] = 0  # an unobserved voxel in front hides it
    assert first_occupied(m, o, d, 5.0)[0, 0] == -1


def test_geometry_inside_the_near_limit_costs_one():
    """The wall at y = 1.55 seen from 1.25 m away costs ψ (< 1); from 0.45 m away, inside
    the 1 m near limit, every ray costs 1; without the limit the close view costs ψ too."""
    m = wall_map(np.array([1.0, 0.0, 0.0]), lam=0.01)
    cfg = NBVConfig(gamma=0.5, ray_cols=8, ray_rows=6, min_range_m=1.0)
    far, close = np.array([0.0, 0.3, 1.0, np.pi / 2]), np.array([0.0, 1.1, 1.0, np.pi / 2])
    c = view_costs(m, np.array([far, close]), MODEL, cfg)
    assert c[0] < 0.5 and c[1] == pytest.approx(1.0)
    assert view_costs(m, close[None], MODEL, NBVConfig(gamma=0.5, ray_cols=8, ray_rows=6,
                                                      min_range_m=0.0))[0] < 0.5
    rays = pose_rays(np.array([far, close]), MODEL, cfg)
    hit = first_occupied(m, np.array([far, close])[:, :3], rays, cfg.max_range_m)
    near = too_near(m, np.array([far, close])[:, :3], hit, cfg.min_range_m)
    assert not near[0].any() and near[1][hit[1] >= 0].all()
