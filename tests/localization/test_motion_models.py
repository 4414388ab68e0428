import numpy as np

from localization.motion_models import (apply_odometry, odometry_decomposition,
                                        sample_motion_model_odometry, wrap_angle)


def test_decomposition_recomposes():
    rng = np.random.default_rng(0)
    for _ in range(100):
        a = rng.uniform(-3, 3, 3)
        b = rng.uniform(-3, 3, 3)
        back = apply_odometry(a, odometry_decomposition(a, b))[0]
        np.testing.assert_allclose(back[:2], b[:2], atol=1e-9)
        assert abs(wrap_angle(back[2] - b[2])) < 1e-9


def test_backward_move_is_a_negative_translation():
    u = odometry_decomposition(np.array([0, 0, 0.0]), np.array([-1, 0, 0.0]))
    np.testing.assert_allclose(u, [0, -1, 0], atol=1e-12)


def test_sampled_spread_follows_alphas():
    rng = np.random.default_rng(1)
    start = np.zeros((20000, 3))
    moved = sample_motion_model_odometry(start, np.zeros(3), np.array([1.0, 0, 0]), (0, 0, 0.04, 0), rng)
    # pure translation of 1 m: trans variance = alpha3 * 1^2, no rotation noise (alpha1,2 = 0)
    np.testing.assert_allclose(np.std(moved[:, 0]), 0.2, rtol=0.03)
    np.testing.assert_allclose(moved[:, 1:], 0, atol=1e-12)
    np.testing.assert_allclose(moved[:, 0].mean(), 1.0, atol=0.01)


def test_random_walk_spread_and_wrap():
    from localization.motion_models import sample_motion_model_random_walk

    rng = np.random.default_rng(2)
    start = np.tile([1.0, -2.0, np.pi - 0.01], (20000, 1))
    moved = sample_motion_model_random_walk(start, [0.1, 0.3, 0.05], rng)
    np.testing.assert_allclose(moved[:, :2].mean(axis=0), [1.0, -2.0], atol=0.01)
    np.testing.assert_allclose(moved[:, :2].std(axis=0), [0.1, 0.3], rtol=0.03)
    assert moved[:, 2].min() >= -np.pi and moved[:, 2].max() < np.pi  # wrapped
    np.testing.assert_allclose(np.std(wrap_angle(moved[:, 2] - start[:, 2])), 0.05, rtol=0.03)
