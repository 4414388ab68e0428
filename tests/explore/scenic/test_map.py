"""Map and reconstruction (Mendez et al. Sec. 3.1): voxel states, data association by
lookup with information-form fusion, free-space carving, triangulation covariances."""

import numpy as np
import pytest

from explore.scenic.map import EMPTY, OCCUPIED, UNOBSERVED, MapConfig, ScenicMap
from explore.scenic.pose import CameraModel, camera_at
from explore.scenic.reconstruction import (StereoConfig, reconstruct_pair, triangulate,
                                           triangulation_covariance)


def empty_map():
    return ScenicMap.covering([0, 0, 0], [4, 2, 2], MapConfig(voxel_m=0.1, assoc_m=0.05))


def test_association_fuses_repeated_observations():
    m = empty_map()
    cov = np.diag([0.04, 0.01, 0.01])
    cam = np.array([[0.05, 1.0, 1.0]])
    m.insert(cam, np.array([[3.01, 1.01, 1.01]]), cov[None])
    assert len(m) == 1
    matched = m.insert(cam, np.array([[3.02, 1.02, 1.0]]), cov[None])
    assert matched == 1 and len(m) == 1 and m.n_obs[0] == 2
    np.testing.assert_allclose(m.covariances[0], cov / 2, rtol=1e-6)   # two equal Gaussians
    np.testing.assert_allclose(m.means[0], [3.015, 1.015, 1.005], atol=1e-6)
    m.insert(cam, np.array([[3.3, 1.0, 1.0]]), cov[None])                # another cell: new point
    assert len(m) == 2


def test_insert_marks_occupied_and_carves_empty_up_to_the_point():
    m = empty_map()
    cam = np.array([[0.05, 1.05, 1.05]])
    m.insert(cam, np.array([[3.05, 1.05, 1.05]]), 1e-4 * np.eye(3)[None])
    row = m.state[:, 10, 10]
    assert row[30] == OCCUPIED
    assert np.all(row[:28] == EMPTY)               # carved along the ray
    assert np.all(row[31:] == UNOBSERVED)          # nothing behind the point
    assert m.state[5, 15, 10] == UNOBSERVED        # nothing beside the ray
    order, start, count = m.points_by_voxel()
    flat = np.ravel_multi_index((30, 10, 10), m.state.shape)
    assert count[flat] == 1 and order[start[flat]] == 0


def test_triangulation_covariance_matches_monte_carlo():
    """σ² J Jᵀ against the scatter of triangulations of noisy pixels."""
    model = CameraModel(320, 240, 60.0, pitch_rad=0.0)
    L, R = camera_at(np.array([0, 0, 1.0, 0.1]), model), camera_at(np.array([0, -0.6, 1.0, 0.2]), model)
    X = np.array([[4.0, -0.2, 1.3]])
    uv_l, uv_r = L.project(X)[0], R.project(X)[0]
    sigma = 0.5
    cov = triangulation_covariance(L, R, uv_l, uv_r, sigma)[0]
    rng = np.random.default_rng(0)
    n = 4000
    samples = triangulate(L, R, uv_l + rng.normal(0, sigma, (n, 2)), uv_r + rng.normal(0, sigma, (n, 2)))
    emp = np.cov(samples.T)
    np.testing.assert_allclose(np.linalg.eigvalsh(cov), np.linalg.eigvalsh(emp), rtol=0.15)
    w_c, v_c = np.linalg.eigh(cov)
    w_e, v_e = np.linalg.eigh(emp)
    assert abs(np.dot(v_c[:, -1], v_e[:, -1])) > 0.99  # the same main axis (the depth)


@pytest.mark.parametrize("matcher,qb,at_least,inliers", [
    ("sift", [0.5, -2.0, 1.2, np.pi / 2], 100, 0.8),
    ("dense", [0.5, -2.0, 1.2, np.pi / 2], 1500, 0.8),
    ("dense", [0.0, -1.5, 1.2, np.pi / 2 + 0.4], 100, 0.65),  # forward motion and a 23° turn
])
def test_reconstructed_pair_lies_on_the_true_surface(office, matcher, qb, at_least, inliers):
    """Triangulated matches of two office photos (sparse SIFT, or dense bidirectional flow
    after rotation compensation): most within 5 cm of the mesh, and the predicted
    uncertainty is larger for the farther points."""
    import trimesh

    model = CameraModel(320, 240, 60.0)
    qa = np.array([0, -2.0, 1.2, np.pi / 2])
    A, B = camera_at(qa, model), camera_at(np.array(qb), model)
    X, cov = reconstruct_pair(A, B, office.photograph(A), office.photograph(B),
                              StereoConfig(matcher=matcher))
    assert len(X) > at_least
    _, dist, _ = trimesh.proximity.closest_point(office.mesh, X)
    assert np.mean(dist < 0.05) > inliers
    sd = np.sqrt(np.linalg.eigvalsh(cov)[:, -1])
    depth = np.linalg.norm(X - A.center, axis=1)
    assert np.corrcoef(depth, sd)[0, 1] > 0.5
