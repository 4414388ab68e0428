import numpy as np
import pytest
import shapely
from filterpy.monte_carlo import systematic_resample

from localization.particle_filter import (ParticleFilter, ParticleFilterConfig, numpy_random_from,
                                          effective_sample_size,
                                          kld_sample_count, sample_free_poses, weighted_estimate)

FREE = shapely.box(0, 0, 4, 2).difference(shapely.box(1, 0.5, 2, 1.5))


def test_kld_count_matches_fox():
    # k = 10 bins, epsilon 0.05, z_0.99 = 2.326: 9 / 0.1 * (1 - 2/81 + sqrt(2/81) z)^3 = 216.9
    assert kld_sample_count(10, 0.05, 0.99) == 217
    assert kld_sample_count(1, 0.05, 0.99) == 1


def test_uniform_poses_stay_in_free_space():
    p = sample_free_poses(FREE, 5000, np.random.default_rng(0))
    assert shapely.contains_xy(FREE, p[:, 0], p[:, 1]).all()
    assert abs(p[:, 2].mean()) < 0.1 and p[:, 2].min() >= -np.pi
    # uniform: the share in the left column matches its share of the area
    left = (p[:, 0] < 1).mean()
    assert left == pytest.approx(2 / FREE.area, abs=0.02)


def test_estimate_uses_circular_mean():
    particles = np.array([[0, 0, np.pi - 0.1], [2, 0, -np.pi + 0.1]])
    mean, cov, best = weighted_estimate(particles, np.log([0.5, 0.5]))
    assert mean[0] == pytest.approx(1)
    assert abs(abs(mean[2]) - np.pi) < 1e-9
    assert cov[2, 2] == pytest.approx(0.01)


def test_filterpy_resampling_is_reproducible_from_the_generator():
    w = np.random.default_rng(0).random(100)
    w /= w.sum()
    state = np.random.get_state()[1].copy()
    with numpy_random_from(np.random.default_rng(5)):
        a = systematic_resample(w)
    with numpy_random_from(np.random.default_rng(5)):
        b = systematic_resample(w)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(np.random.get_state()[1], state)  # global state untouched


def test_filter_concentrates_on_a_synthetic_likelihood():
    """A likelihood peaked at a known pose pulls a uniform filter there, and KLD shrinks it."""
    truth = np.array([3.0, 1.0, 0.5])
    config = ParticleFilterConfig(n_particles=2000, roughening=(0.01, 0.01, 0.01))
    pf = ParticleFilter(FREE, config, np.random.default_rng(0))
    pf.init_uniform()
    for _ in range(8):
        d = pf.particles - truth
        d[:, 2] = (d[:, 2] + np.pi) % (2 * np.pi) - np.pi
        pf.update(-0.5 * np.sum((d / [0.2, 0.2, 0.2]) ** 2, axis=1))
        pf.resample_if_needed()
    mean, cov, _ = pf.estimate()
    assert np.hypot(*(mean[:2] - truth[:2])) < 0.1  # posterior sd ~ 0.2 / sqrt(8)
    assert len(pf.particles) < 1000


def test_kidnapping_injects_random_particles():
    config = ParticleFilterConfig(n_particles=500)
    pf = ParticleFilter(FREE, config, np.random.default_rng(1))
    pf.init_gaussian([3.0, 1.0, 0.0], [0.05, 0.05, 0.05])
    for _ in range(5):  # good fit: likelihood averages settle
        pf.update(np.zeros(len(pf.particles)))
        pf.log_w += np.random.default_rng(0).normal(0, 1, len(pf.log_w))  # force resampling
        pf.resample_if_needed()
    injected_before = pf.n_injected
    pf.update(np.full(len(pf.particles), -30.0))  # the world stopped matching
    pf.log_w += np.random.default_rng(1).normal(0, 1, len(pf.log_w))
    assert pf.resample_if_needed()
    # w_fast falls by alpha_fast, w_slow by alpha_slow: p = 1 - (1 - 0.5) / (1 - 0.05)
    assert injected_before == 0
    assert pf.n_injected / len(pf.particles) == pytest.approx(1 - 0.5 / 0.95, abs=0.1)


def _tracking_filter(seed: int) -> ParticleFilter:
    """A filter tracking well at (3, 1, 0): five steps of a perfect fit."""
    pf = ParticleFilter(FREE, ParticleFilterConfig(n_particles=500), np.random.default_rng(seed))
    pf.init_gaussian([3.0, 1.0, 0.0], [0.05, 0.05, 0.05])
    for _ in range(5):
        pf.update(np.zeros(len(pf.particles)))
        pf.resample_if_needed()
    return pf


def test_due_injection_forces_resampling_while_the_weights_are_even():
    """A tight cluster that fits equally badly everywhere keeps its effective sample size;
    the injection must still happen (it lives in the resampling step)."""
    pf = _tracking_filter(2)
    pf.update(np.full(len(pf.particles), -30.0))  # even weights, ESS = N
    assert pf.injection_probability() == pytest.approx(1 - 0.5 / 0.95)
    assert pf.resample_if_needed() and pf.n_injected > 0 and not pf.reinitialised


def test_collapsed_likelihood_reinitialises_globally():
    pf = _tracking_filter(3)
    for k in range(3):  # w_fast / w_slow: 0.5 / 0.95, 0.25 / 0.9025, 0.125 / 0.857 < reinit_ratio
        pf.update(np.full(len(pf.particles), -30.0))
        pf.resample_if_needed()
        assert pf.reinitialised == (k == 2)
    assert len(pf.particles) == pf.config.n_particles
    p = pf.particles
    assert (p[:, 0] < 1).mean() == pytest.approx(2 / FREE.area, abs=0.06)  # uniform again
    assert pf.w_slow == pf.w_fast == 0.0  # the averages restart (nav2_amcl)


def test_averages_use_the_fit_likelihood_not_the_tempered_one():
    pf = _tracking_filter(4)
    w_slow, w_fast = pf.w_slow, pf.w_fast
    # a flat tempered likelihood but a collapsed fit: the averages see the fit
    pf.update(np.zeros(len(pf.particles)), fit_loglik=np.full(len(pf.particles), -30.0))
    assert pf.w_fast == pytest.approx(w_fast * 0.5) and pf.w_slow == pytest.approx(w_slow * 0.95)
    np.testing.assert_allclose(pf.weights, 1 / len(pf.particles))  # weights from the tempered one


@pytest.mark.parametrize("resampler", ["systematic", "stratified"])
def test_resampling_is_triggered_by_effective_sample_size(resampler):
    pf = ParticleFilter(FREE, ParticleFilterConfig(n_particles=400, resampler=resampler),
                        np.random.default_rng(6))
    pf.init_gaussian([3.0, 1.0, 0.0], [0.1, 0.1, 0.1])
    pf.update(np.random.default_rng(0).normal(0, 0.1, 400))  # ESS ~ 0.99 N: keep
    assert effective_sample_size(pf.log_w) > 0.9 * 400 and not pf.resample_if_needed()
    heavy = np.where(np.arange(400) < 40, 0.0, -50.0)  # 40 particles carry the weight
    pf.update(heavy, fit_loglik=np.zeros(400))  # the fit as before: no injection due
    survivors = pf.particles[:40].copy()
    assert effective_sample_size(pf.log_w) == pytest.approx(40, rel=0.02)  # earlier weights ~even
    assert pf.resample_if_needed()
    # every new particle is a roughened copy of one of the 40
    d = np.abs(pf.particles[:, None, :2] - survivors[None, :, :2]).max(axis=2).min(axis=1)
    assert d.max() < 6 * pf.config.roughening[0]
    np.testing.assert_allclose(pf.weights, 1 / len(pf.particles))


def test_estimate_covariance_and_best_particle():
    rng = np.random.default_rng(7)
    particles = np.c_[rng.normal(1.0, 0.2, 5000), rng.normal(-1.0, 0.1, 5000), rng.normal(0.3, 0.05, 5000)]
    log_w = np.zeros(5000)
    log_w[123] = 5.0
    mean, cov, best = weighted_estimate(particles, log_w)
    np.testing.assert_allclose(best, particles[123])
    w = np.exp(log_w) / np.exp(log_w).sum()
    np.testing.assert_allclose(mean[:2], w @ particles[:, :2])
    np.testing.assert_allclose(np.sqrt(np.diag(cov)), [0.2, 0.1, 0.05], rtol=0.05)
    assert abs(cov[0, 1]) < 0.002


def test_random_walk_prediction_moves_particles():
    pf = ParticleFilter(FREE, ParticleFilterConfig(n_particles=3000), np.random.default_rng(8))
    pf.init_gaussian([3.0, 1.0, 0.0], [0.0, 0.0, 0.0])
    pf.predict_random_walk(np.array([0.05, 0.05, 0.02]))
    np.testing.assert_allclose(pf.particles.std(axis=0), [0.05, 0.05, 0.02], rtol=0.06)


def test_injected_particles_come_from_the_injection_source():
    """Mixture MCL: with a source (e.g. the poses the photo fits best), augmented MCL's
    injected particles are drawn from it, not uniformly."""
    pf = ParticleFilter(shapely.box(0, 0, 10, 10), ParticleFilterConfig(n_particles=500, n_min=500,
                                                                       roughening=(0, 0, 0)),
                        np.random.default_rng(0))
    pf.init_gaussian([2.0, 2.0, 0.0], [0.05, 0.05, 0.01])
    pf.injection_source = lambda n: np.tile([8.0, 8.0, 1.0], (n, 1))
    pf.w_slow, pf.w_fast = 1.0, 0.5  # injection due (p = 0.5), not collapsed
    assert pf.resample_if_needed() and pf.n_injected > 100
    at_source = (np.abs(pf.particles - [8.0, 8.0, 1.0]) < 1e-9).all(axis=1)
    assert at_source.sum() == pf.n_injected
