"""SMC cost space (Mendez et al. Sec. 3.2.1): particles from empty voxels only, w = 1 - C,
resampling into I_p (best kept), I_g (weighted + noise), I_u (fresh uniform) in the
configured proportions."""

import numpy as np
import pytest
import shapely

from explore.scenic.cost import NBVConfig
from explore.scenic.map import EMPTY, OCCUPIED, MapConfig, ScenicMap
from explore.scenic.pose import CameraModel
from explore.scenic.smc import CostSpace, SMCConfig, resample, sample_uniform, weights
from explore.scenic.workspace import Workspace

WS = Workspace(shapely.box(-2, -2, 2, 2), 0.5, 1.5)


def half_empty_map() -> ScenicMap:
    """Only the x < 0 half of the room has been seen empty; a wall of points at x = 1.9."""
    m = ScenicMap.covering([-2, -2, 0], [2, 2, 2], MapConfig(voxel_m=0.1))
    m.state[:20] = EMPTY
    m.state[39] = OCCUPIED
    return m


def test_uniform_particles_come_from_empty_voxels_only():
    m = half_empty_map()
    q = sample_uniform(m, WS, 2000, np.random.default_rng(0))
    assert q.shape == (2000, 4)
    assert np.all(m.state_at(q[:, :3]) == EMPTY)
    assert np.all(WS.contains(q[:, :3]))
    assert q[:, 3].min() >= -np.pi and q[:, 3].max() < np.pi
    assert np.std(q[:, 3]) == pytest.approx(np.pi / np.sqrt(3), rel=0.1)  # uniform yaw


@pytest.mark.parametrize("frac_best,frac_uniform", [(0.1, 0.2), (0.25, 0.05), (0.0, 0.5)])
def test_resample_keeps_the_configured_proportions(frac_best, frac_uniform):
    m = half_empty_map()
    rng = np.random.default_rng(1)
    cfg = SMCConfig(n_particles=200, frac_best=frac_best, frac_uniform=frac_uniform)
    q = sample_uniform(m, WS, 200, rng)
    w = rng.uniform(0, 1, 200)
    new, labels = resample(q, w, m, WS, cfg, rng)
    n_p, n_g, n_u = cfg.counts()
    assert len(new) == 200 and n_p + n_g + n_u == 200
    assert np.bincount(labels, minlength=3).tolist() == [n_p, n_g, n_u]
    assert n_p == round(frac_best * 200) and n_u == round(frac_uniform * 200)
    # I_p: exactly the best particles, unchanged
    np.testing.assert_array_equal(new[labels == 0], q[np.argsort(-w)[:n_p]])
    # I_u: fresh draws from Ve; I_g: inside the workspace
    assert np.all(m.state_at(new[labels == 2][:, :3]) == EMPTY)
    assert np.all(WS.contains(new[labels == 1][:, :3]))


def test_weighted_resample_follows_the_weights():
    """All weight on one particle: every I_g particle is a noisy copy of it."""
    m = half_empty_map()
    rng = np.random.default_rng(2)
    cfg = SMCConfig(n_particles=100, sigma_pos_m=0.05, sigma_yaw_rad=0.05)
    q = sample_uniform(m, WS, 100, rng)
    w = np.zeros(100)
    w[7] = 1.0
    new, labels = resample(q, w, m, WS, cfg, rng)
    g = new[labels == 1]
    assert np.all(np.linalg.norm(g[:, :3] - q[7, :3], axis=1) < 0.3)
    assert np.std(g[:, 0]) == pytest.approx(0.05, rel=0.4)


def test_weights_are_one_minus_view_cost():
    m = half_empty_map()
    rng = np.random.default_rng(3)
    model, nbv = CameraModel(32, 24), NBVConfig(gamma=0.25, ray_cols=4, ray_rows=3)
    space = CostSpace(m, WS, model, nbv, SMCConfig(n_particles=50), rng)
    np.testing.assert_allclose(space.w, 1 - 0.25)  # no points yet: every ray costs γ
    np.testing.assert_allclose(weights(m, space.particles, model, nbv), space.w)
    space.update(m)
    assert space.particles.shape == (50, 4)
