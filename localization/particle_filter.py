"""Particle filter (Monte Carlo localisation) for SE(2) robot poses (x, y, theta).

Heigl et al., "A light-field model for visual navigation": Condensation — particles
initialised uniformly over the map, moved by the odometry (the action), weighted by the
rendered-view likelihood, resampled. With the standard additions of ROS nav2_amcl and
Thrun et al. (Probabilistic Robotics, ch. 8):
- resampling only when the effective sample size drops (filterpy's systematic or
  stratified resampling; not its residual_resample, filterpy issue #290);
- KLD-sampling (Fox 2003): the particle count adapts to the number of occupied
  (x, y, theta) histogram bins;
- augmented MCL: short- and long-term averages of the likelihood (alpha_fast,
  alpha_slow) trigger random injection of particles when the filter is lost (kidnapping).
  The averages are taken of a likelihood that is comparable from step to step (the
  caller's untempered `fit_loglik`, not the tempered weights), a due injection forces a
  resampling step even while the effective sample size is high (otherwise a tight cluster
  that fits equally badly everywhere is never resampled, so never injected into), and
  when the short-term average collapses far below the long-term one the whole set is
  re-initialised uniformly (global re-initialisation, as nav2_amcl's global-localisation
  reset; sensor-resetting localisation, Lenser & Veloso 2000) and the averages restart
  (nav2_amcl resets them after injecting, "to avoid spiralling off into complete
  randomness");
- Loc-NeRF's roughening: a small random perturbation of every particle after resampling.
Frames: world, metres, radians. Weights are kept as log-weights (N,).
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import shapely
from filterpy.monte_carlo import stratified_resample, systematic_resample
from scipy.stats import norm

from localization.motion_models import (sample_motion_model_odometry, sample_motion_model_random_walk,
                                        wrap_angle)


@dataclass(frozen=True)
class ParticleFilterConfig:
    n_particles: int = 1000
    """Initial particle count."""
    n_min: int = 100
    """Fewest particles KLD-sampling may keep."""
    n_max: int = 4000
    """Most particles KLD-sampling may ask for."""
    kld_epsilon: float = 0.05
    """KLD bound between the sample and the true posterior (Fox 2003)."""
    kld_quantile: float = 0.99
    """Probability that the KLD bound holds (1 - delta)."""
    kld_bin: tuple[float, float, float] = (0.25, 0.25, np.radians(15))
    """Histogram bin size (m, m, rad) for counting occupied bins."""
    ess_fraction: float = 0.5
    """Resample when the effective sample size falls below this fraction of N."""
    resampler: str = "systematic"
    """'systematic' or 'stratified' (filterpy)."""
    alphas: tuple[float, float, float, float] = (0.05, 0.005, 0.05, 0.005)
    """Odometry noise alpha1..4 of the prediction (Thrun Table 5.6)."""
    in_place_alpha4: float = 1e-4
    """Trans-from-rot noise of a commanded turn in place (m^2 per rad^2): its centre slips by
    sqrt(1e-4) = 1 cm per radian turned. A differential drive turning on the spot keeps its
    centre (the simulator's exactly); the odometry's alpha4 is the noise of the translation
    it reads, which `turn_in_place` discards. With alpha4 (0.005) in its place every turn
    spread the particles by 7 cm per radian (apartment 3: 0.04 -> 0.23 m on one 164 degree
    turn), and the compass, re-weighting their headings, moved the estimate 3-9 cm while the
    robot stood still. A property of the drive, not of a scene."""
    alpha_slow: float = 0.05
    """Rate of the long-term likelihood average (augmented MCL)."""
    alpha_fast: float = 0.5
    """Rate of the short-term likelihood average (augmented MCL)."""
    reinit_ratio: float = 0.25
    """Re-initialise the whole set uniformly when w_fast / w_slow falls below this (the
    likelihood collapsed: kidnapped); 0 disables it."""
    roughening: tuple[float, float, float] = (0.02, 0.02, np.radians(1.0))
    """Std of the perturbation applied after resampling (m, m, rad)."""


@contextmanager
def numpy_random_from(rng: np.random.Generator):
    """filterpy draws from numpy's global RNG: seed it from `rng` and restore it after,
    so a run is reproducible from its Generator and nothing else is disturbed."""
    state = np.random.get_state()
    np.random.seed(int(rng.integers(2**32)))
    try:
        yield
    finally:
        np.random.set_state(state)


def sample_free_poses(free_space: shapely.Geometry, n: int, rng: np.random.Generator) -> np.ndarray:
    """n SE(2) poses (n, 3) uniform over a free-space polygon, uniform heading."""
    lo_x, lo_y, hi_x, hi_y = free_space.bounds
    out = np.empty((0, 3))
    while len(out) < n:
        xy = rng.uniform([lo_x, lo_y], [hi_x, hi_y], (2 * (n - len(out)) + 16, 2))
        xy = xy[shapely.contains_xy(free_space, xy[:, 0], xy[:, 1])]
        out = np.r_[out, np.c_[xy, rng.uniform(-np.pi, np.pi, len(xy))]]
    return out[:n]


def effective_sample_size(log_w: np.ndarray) -> float:
    w = np.exp(log_w - log_w.max())
    w /= w.sum()
    return float(1.0 / np.sum(w**2))


def kld_sample_count(n_bins: int, epsilon: float, quantile: float) -> int:
    """Fox's KLD bound: particles needed for `n_bins` occupied bins (Wilson-Hilferty)."""
    if n_bins <= 1:
        return 1
    k = n_bins - 1
    z = norm.ppf(quantile)
    return int(np.ceil(k / (2 * epsilon) * (1 - 2 / (9 * k) + np.sqrt(2 / (9 * k)) * z) ** 3))


def weighted_estimate(particles: np.ndarray, log_w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted mean (3,) with the circular mean for theta, covariance (3, 3) with
    wrapped angle residuals, and the best particle (3,)."""
    w = np.exp(log_w - log_w.max())
    w /= w.sum()
    mean = np.array([w @ particles[:, 0], w @ particles[:, 1],
                     np.arctan2(w @ np.sin(particles[:, 2]), w @ np.cos(particles[:, 2]))])
    d = particles - mean
    d[:, 2] = wrap_angle(d[:, 2])
    cov = (d * w[:, None]).T @ d
    return mean, cov, particles[np.argmax(log_w)].copy()


class ParticleFilter:
    """SE(2) Monte Carlo localisation. `free_space` (shapely) is the map prior: particles
    outside it get zero weight and random injections are drawn inside it."""

    def __init__(self, free_space: shapely.Geometry, config: ParticleFilterConfig,
                 rng: np.random.Generator):
        self.free = free_space
        shapely.prepare(self.free)
        self.config, self.rng = config, rng
        self.particles = np.zeros((0, 3))
        self.log_w = np.zeros(0)
        self.w_slow = self.w_fast = 0.0
        self.n_injected = 0
        self.reinitialised = False  # whether the last resampling step re-initialised globally
        self.injection_source = None
        """Where augmented MCL's injected particles come from: a function n -> (n, 3) poses
        (e.g. poses drawn from the current measurement: mixture MCL); None: uniform over
        the free space."""

    # --- initialisation -----------------------------------------------------------
    def init_uniform(self, n: int | None = None) -> None:
        """Global localisation: particles uniform over the free space (Heigl et al.)."""
        self._set(sample_free_poses(self.free, n or self.config.n_particles, self.rng))

    def init_gaussian(self, mean: np.ndarray, std: np.ndarray, n: int | None = None) -> None:
        """Tracking from a known start: particles ~ N(mean, diag(std^2))."""
        p = np.asarray(mean) + self.rng.normal(size=(n or self.config.n_particles, 3)) * std
        p[:, 2] = wrap_angle(p[:, 2])
        self._set(p)

    def _set(self, particles: np.ndarray) -> None:
        self.particles = particles
        self.log_w = np.full(len(particles), -np.log(len(particles)))

    # --- the filter step ----------------------------------------------------------
    def predict(self, odom_before: np.ndarray, odom_after: np.ndarray, in_place: bool = False) -> None:
        """Move every particle by the odometry motion, with Thrun's noise model; `in_place`:
        the robot was commanded to turn in place, so only the odometry's heading change
        moves the particles (`turn_in_place`), its translation is noise."""
        self.particles = sample_motion_model_odometry(self.particles, odom_before, odom_after,
                                                      self.config.alphas, self.rng, in_place,
                                                      self.config.in_place_alpha4)

    def predict_random_walk(self, std: np.ndarray) -> None:
        """Move every particle by a random walk with std (m, m, rad): no odometry."""
        self.particles = sample_motion_model_random_walk(self.particles, std, self.rng)

    def update(self, loglik: np.ndarray, fit_loglik: np.ndarray | None = None) -> None:
        """Weight by per-particle log-likelihoods (N,) (possibly tempered); zero weight
        outside the map. `fit_loglik` (N,): the same measurement as a likelihood that is
        comparable across steps (fixed temperature and scale), for the augmented-MCL
        averages; default `loglik`."""
        inside = shapely.contains_xy(self.free, self.particles[:, 0], self.particles[:, 1])
        loglik = np.where(inside, loglik, -np.inf)
        if not np.isfinite(loglik).any():  # every particle left the map: start over
            self.init_uniform(len(self.particles))
            return
        prev = self.log_w - np.logaddexp.reduce(self.log_w)
        fit = loglik if fit_loglik is None else np.where(inside, fit_loglik, -np.inf)
        # average likelihood under the previous weights (Thrun Table 8.3's w_avg, weighted)
        w_avg = float(np.exp(np.logaddexp.reduce(prev + fit)))
        c = self.config
        self.w_slow = w_avg if self.w_slow == 0 else self.w_slow + c.alpha_slow * (w_avg - self.w_slow)
        self.w_fast = w_avg if self.w_fast == 0 else self.w_fast + c.alpha_fast * (w_avg - self.w_fast)
        total = prev + loglik
        self.log_w = total - np.logaddexp.reduce(total)

    def injection_probability(self) -> float:
        """Augmented MCL's max(0, 1 - w_fast / w_slow) (Thrun Table 8.3)."""
        return max(0.0, 1.0 - self.w_fast / self.w_slow) if self.w_slow > 0 else 0.0

    def collapsed(self) -> bool:
        """Whether the short-term likelihood average fell below `reinit_ratio` of the
        long-term one."""
        return self.w_slow > 0 and self.w_fast < self.config.reinit_ratio * self.w_slow

    def resample_if_needed(self) -> bool:
        """Resample (KLD-adaptive count, random injection, roughening) when the effective
        sample size is low or an injection is due; re-initialise globally when the
        likelihood collapsed. Returns whether it resampled."""
        c = self.config
        self.n_injected, self.reinitialised = 0, False
        if self.collapsed():
            self.init_uniform()
            self.w_slow = self.w_fast = 0.0
            self.n_injected, self.reinitialised = len(self.particles), True
            return True
        p_inject = self.injection_probability()
        if (effective_sample_size(self.log_w) >= c.ess_fraction * len(self.particles)
                and p_inject * len(self.particles) < 1):
            return False
        w = np.exp(self.log_w - self.log_w.max())
        w /= w.sum()
        resample = systematic_resample if c.resampler == "systematic" else stratified_resample
        with numpy_random_from(self.rng):
            idx = resample(w)
        kept = self.particles[idx]
        n_new = int(np.clip(kld_sample_count(self._occupied_bins(kept), c.kld_epsilon, c.kld_quantile),
                            c.n_min, c.n_max))
        kept = kept[self.rng.choice(len(kept), n_new, replace=n_new > len(kept))]
        # augmented MCL: inject random particles while the short-term fit is worse
        inject = self.rng.random(n_new) < p_inject
        self.n_injected = int(inject.sum())
        if self.n_injected:
            kept[inject] = (sample_free_poses(self.free, self.n_injected, self.rng) if self.injection_source is None
                            else self.injection_source(self.n_injected))
        kept = kept + self.rng.normal(size=kept.shape) * np.asarray(c.roughening)
        kept[:, 2] = wrap_angle(kept[:, 2])
        self._set(kept)
        return True

    def _occupied_bins(self, particles: np.ndarray) -> int:
        keys = np.floor(particles / np.asarray(self.config.kld_bin)).astype(np.int64)
        return len(np.unique(keys, axis=0))

    def estimate(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(mean (3,), covariance (3, 3), best particle (3,))."""
        return weighted_estimate(self.particles, self.log_w)

    @property
    def weights(self) -> np.ndarray:
        w = np.exp(self.log_w - self.log_w.max())
        return w / w.sum()
