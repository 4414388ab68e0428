"""Stereo-pair costs (Mendez et al. eq. 5-9): zero for the ideal pair d_LI = d_RI = α d_B
looking at known geometry at I, growing as the pair moves away from it."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from explore.scenic.stereo import StereoCostConfig, ray_intersection, stereo_cost, stereo_terms

ALPHA = 3.0
CFG = StereoCostConfig(alpha=ALPHA)


def ideal_pair(d_b=0.5):
    """L, R on the x axis, both principal rays verging on I with d_LI = d_RI = α d_B."""
    L, R = np.array([-d_b / 2, 0, 1.0]), np.array([d_b / 2, 0, 1.0])
    I = np.array([0.0, np.sqrt((ALPHA * d_b) ** 2 - (d_b / 2) ** 2), 1.0])
    unit = lambda v: v / np.linalg.norm(v)
    return L, R, unit(I - L), unit(I - R), I


def terms(L, R, rl, rr, occ):
    return {k: float(v[0]) for k, v in stereo_terms(L, R, rl, rr, cKDTree(occ), CFG).items()}


def test_intersection_of_verging_rays_is_I():
    L, R, rl, rr, I = ideal_pair()
    np.testing.assert_allclose(ray_intersection(L[None], R[None], rl[None], rr[None])[0], I, atol=1e-9)


def test_ideal_configuration_costs_zero():
    L, R, rl, rr, I = ideal_pair()
    t = terms(L, R, rl, rr, I[None])
    for name, value in t.items():
        assert value == pytest.approx(0.0, abs=1e-6), name


@pytest.mark.parametrize("scale", [0.3, 0.6, 1.5, 2.5])
def test_baseline_cost_grows_away_from_alpha(scale):
    """Same I, baseline scaled: C_B and C_β grow, more the farther from the ideal."""
    L, R, rl, rr, I = ideal_pair()
    c = (L + R) / 2
    L2, R2 = c + scale * (L - c), c + scale * (R - c)
    unit = lambda v: v / np.linalg.norm(v)
    t = terms(L2, R2, unit(I - L2), unit(I - R2), I[None])
    assert t["C_B"] > 0.1 and t["C_beta"] > 0.01
    closer = 1 + 0.5 * (scale - 1)
    L3, R3 = c + closer * (L - c), c + closer * (R - c)
    t3 = terms(L3, R3, unit(I - L3), unit(I - R3), I[None])
    assert t3["C_B"] < t["C_B"]


def test_turning_a_camera_raises_cost():
    """Rotating R's principal ray away from I moves the intersection: total cost grows
    monotonically with the rotation angle."""
    L, R, rl, rr, I = ideal_pair()
    costs = []
    for ang in np.radians([0, 2, 5, 10]):
        c, s = np.cos(ang), np.sin(ang)
        r2 = np.array([c * rr[0] - s * rr[1], s * rr[0] + c * rr[1], 0.0])
        costs.append(stereo_cost(L[None], R[None], rl[None], r2[None], cKDTree(I[None]), CFG)[0])
    assert costs[0] == pytest.approx(0.0, abs=1e-6)
    assert np.all(np.diff(costs) > 0)


def test_geometry_off_the_vergence_point_raises_C_G():
    """Known geometry G to the side of I costs the angle between the rays to I and to G."""
    L, R, rl, rr, I = ideal_pair()
    near = terms(L, R, rl, rr, (I + [0.1, 0, 0])[None])["C_G"]
    far = terms(L, R, rl, rr, (I + [0.5, 0, 0])[None])["C_G"]
    assert 0 < near < far
    G = I + [0.5, 0, 0]
    expected = sum(np.arccos(np.dot(I - X, G - X) / np.linalg.norm(I - X) / np.linalg.norm(G - X))
                   for X in (L, R))
    assert far == pytest.approx(expected, rel=1e-9)


def test_principal_rays_that_miss_each_other_pay_C_T():
    """Parallel rays: I is put far along them, the rays to I leave the principal rays."""
    L, R, _, _, I = ideal_pair()
    fwd = np.array([0.0, 1.0, 0.0])
    t = terms(L, R, fwd, fwd, I[None])
    assert t["C_B"] > 10 and t["C_beta"] > 0.2
