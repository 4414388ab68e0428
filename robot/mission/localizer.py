"""The capture mission's localiser: SE(2) Monte Carlo localisation on odometry, compass and
vision fixes, so path following consumes a filter's estimate, never the simulator's truth.

- Prediction: every move of the robot moves the particles by the odometry with Thrun's
  sample_motion_model_odometry (Probabilistic Robotics, Table 5.6, alpha1..4;
  `localization.particle_filter.ParticleFilter.predict`), then weights them by the compass
  heading (Gaussian, `compass_sigma_rad`). A commanded turn in place moves them by the
  odometry's heading change alone (`motion_models.turn_in_place`): the translation the
  odometry reads while the robot turns on the spot is slip, and following it carried the
  estimate off with it. Their headings are then drawn from the compass's posterior (the
  optimal importance density), so the turns the robot makes between photos neither spread
  nor resample their positions (`_turn_with_compass`).
- Measurement at waypoints: the SIFT + RANSAC PnP fix of a photo against the map
  (`localization.feature_localizer`) as a Mixture-MCL step (Thrun, Fox, Burgard & Dellaert,
  "Robust Monte Carlo localization for mobile robots", 2001; the same idea as
  `localization.hybrid`'s PnP proposal): a fraction `pnp_fraction` of the particles is drawn
  around the PnP robot pose, the others keep their prior; every particle is then weighted
  by the importance weight of that mixture proposal, L(fix | x) prior(x) / q(x) (L Gaussian
  in x, y, theta with sigmas shrinking as 1/sqrt(inliers), plus an outlier floor; the prior
  a Gaussian fit of the predicted particles; q the mixture's density), so the posterior is
  the product of belief and fix wherever its particles came from (`mixture_log_weights`).
- When PnP fails the filter carries on with odometry alone and its spread grows;
  `needs_fix()` says when the spread is large enough to stop for an extra photo.
A `CompassDeadReckoning` is kept beside the filter only as the baseline it is compared with.
Frames: world SE(2) (x, y, theta), metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from localization.dead_reckoning import CompassDeadReckoning
from localization.motion_models import apply_odometry, turn_in_place, wrap_angle
from localization.particle_filter import ParticleFilter, ParticleFilterConfig
from robot.protocol import MotionResult, Robot
from robot.mission.random_stage import Body


@dataclass(frozen=True)
class MissionFilterConfig:
    """Settings of the mission's particle filter."""

    n_particles: int = 400
    """Particles at the start (KLD-sampling adapts the count between 150 and 1500)."""
    alphas: tuple[float, float, float, float] = (0.05, 0.005, 0.05, 0.005)
    """Odometry noise alpha1..4 of the prediction (above the simulator's, as on a real robot)."""
    init_std: tuple[float, float, float] = (0.3, 0.3, np.radians(8.0))
    """Spread of the particles around the start pose (m, m, rad)."""
    compass_sigma_rad: float = np.radians(5.0)
    """Compass likelihood's standard deviation per move (rad); 0: compass not used."""
    pnp_fraction: float = 0.2
    """Fraction of the particles drawn around the PnP pose at a fix."""
    pnp_sigma_xy_m: float = 0.25
    """PnP position sigma = this / sqrt(inliers), at least `pnp_min_sigma_xy_m` (m): 2.5-3.5 cm
    at the 50-100 inliers of a typical fix, the error measured against the truth (accepted
    fixes 2.2-3.9 cm at the median, office, 108 random photos; 0.6 had the filter lag them)."""
    pnp_min_sigma_xy_m: float = 0.02
    """Smallest PnP position sigma (m)."""
    pnp_sigma_theta_rad: float = np.radians(12.0)
    """PnP heading sigma = this / sqrt(inliers), at least 0.5 degrees (rad)."""
    pnp_outlier_loglik: float = -12.0
    """Log-likelihood floor of the PnP measurement (a wrong fix cannot zero every particle)."""
    relocalise_std_m: float = 0.25
    """`needs_fix` when the position spread (sqrt of the largest eigenvalue) exceeds this (m)."""
    margin_m: float = 3.0
    """The filter's map prior: the box around the mapped cameras (and, via `grow_prior`, the
    mission's navigation grid) grown by this (m)."""


class MissionLocalizer:
    """The particle filter plus the dead-reckoning baseline. `pose`: the filter's estimate (3,)."""

    def __init__(self, start: np.ndarray, bounds_xy: np.ndarray, config: MissionFilterConfig,
                 rng: np.random.Generator, start_std: np.ndarray | None = None):
        self.config = config
        lo, hi = self._box(bounds_xy)
        # alpha_fast == alpha_slow: no random injection, no global re-initialisation (the
        # robot is never kidnapped, and a box prior would scatter particles through walls)
        pf_cfg = ParticleFilterConfig(n_particles=config.n_particles, n_min=150, n_max=1500,
                                      alphas=config.alphas, alpha_slow=0.1, alpha_fast=0.1, reinit_ratio=0.0,
                                      roughening=(0.01, 0.01, np.radians(0.5)))
        self.pf = ParticleFilter(shapely.box(*lo, *hi), pf_cfg, rng)
        self.pf.init_gaussian(np.asarray(start, float), np.asarray(config.init_std if start_std is None else start_std))
        self.dead_reckoning = CompassDeadReckoning(np.asarray(start, float).copy())
        self._update_estimate()

    def _box(self, bounds_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        xy = np.asarray(bounds_xy, float).reshape(-1, 2)
        return xy.min(0) - self.config.margin_m, xy.max(0) + self.config.margin_m

    def grow_prior(self, bounds_xy: np.ndarray) -> None:
        """Grow the map prior (the box) to cover the points `bounds_xy` (K, 2) (m) plus
        `margin_m`: as the map grows, the robot is sent beyond the first box, and particles
        outside it would be zeroed (all of them: the filter would restart uniformly)."""
        lo, hi = self._box(bounds_xy)
        x0, y0, x1, y1 = self.pf.free.bounds
        box = shapely.box(min(lo[0], x0), min(lo[1], y0), max(hi[0], x1), max(hi[1], y1))
        shapely.prepare(box)
        self.pf.free = box

    def _update_estimate(self) -> None:
        self.mean, self.cov, _ = self.pf.estimate()

    def set_particles(self, particles: np.ndarray, log_w: np.ndarray) -> None:
        """Replace the filter's particles (N, 3) and log-weights (N,), e.g. as a resumed
        mission committed them; the estimate follows."""
        self.pf.particles, self.pf.log_w = np.asarray(particles, float), np.asarray(log_w, float)
        self._update_estimate()

    @property
    def pose(self) -> np.ndarray:
        return self.mean.copy()

    @property
    def spread_m(self) -> float:
        """Position spread: sqrt of the largest eigenvalue of the x, y covariance (m)."""
        return float(np.sqrt(max(np.linalg.eigvalsh(self.cov[:2, :2]).max(), 0.0)))

    def needs_fix(self) -> bool:
        return self.spread_m > self.config.relocalise_std_m

    # --- the filter steps -------------------------------------------------------------
    def predict(self, odom_before: np.ndarray, odom_after: np.ndarray, compass_rad: float,
                in_place: bool = False) -> None:
        """A move: odometry prediction, then the compass heading likelihood. `in_place`: a
        commanded turn in place, whose odometry translation is slip, not motion
        (`motion_models.turn_in_place`), and whose headings are drawn from the compass's
        posterior (`_turn_with_compass`)."""
        self.dead_reckoning.update(odom_before, odom_after, compass_rad, in_place)
        if in_place and self.config.compass_sigma_rad > 0:
            self._turn_with_compass(turn_in_place(odom_before, odom_after)[0], compass_rad)
        else:
            self.pf.predict(odom_before, odom_after, in_place)
            if self.config.compass_sigma_rad > 0:
                d = wrap_angle(self.pf.particles[:, 2] - compass_rad)
                self.pf.update(-0.5 * (d / self.config.compass_sigma_rad) ** 2)
        self.pf.resample_if_needed()
        self._update_estimate()

    def _turn_with_compass(self, rot: float, compass_rad: float) -> None:
        """A turn in place by `rot` (rad, odometry) with the compass reading `compass_rad`,
        by the optimal importance density (Doucet, Godsill & Andrieu 2000): each particle's
        heading is drawn from the product of its motion's heading noise (Thrun's alpha1,
        N(theta + rot, alpha1 rot^2)) and the compass's N(compass, sigma^2), and weighted by
        that product's mass, N(compass; theta + rot, alpha1 rot^2 + sigma^2). Its position
        moves by the turn's slip alone (`ParticleFilterConfig.in_place_alpha4`). Drawn from
        the motion and weighted by the compass, as a drive is, a 90-degree turn's 20-degree
        heading noise against the compass's 5 left a fifth of the particles' weight, every
        turn resampled the positions, and the estimate of a robot turning on the spot walked
        6-10 cm in 40 turns (0.4-1.3 cm so; `test_turning_in_place_leaves_the_estimate_where_the_robot_is`)."""
        pf = self.pf
        n = len(pf.particles)
        var_motion, var_compass = pf.config.alphas[0] * rot ** 2, self.config.compass_sigma_rad ** 2
        heading = pf.particles[:, 2] + rot
        slip = pf.rng.normal(size=n) * np.sqrt(pf.config.in_place_alpha4) * abs(rot)
        x = apply_odometry(pf.particles, np.c_[np.full(n, rot), slip, np.zeros(n)])  # turned, then slipped
        d = wrap_angle(compass_rad - heading)
        mean = heading + d * var_motion / (var_motion + var_compass)
        sd = np.sqrt(var_motion * var_compass / (var_motion + var_compass))
        x[:, 2] = wrap_angle(mean + pf.rng.normal(size=n) * sd)
        pf.particles = x
        pf.update(-0.5 * d ** 2 / (var_motion + var_compass))

    def pnp_sigmas(self, n_inliers: int) -> np.ndarray:
        c = self.config
        s = 1.0 / np.sqrt(max(n_inliers, 1))
        return np.array([max(c.pnp_sigma_xy_m * s, c.pnp_min_sigma_xy_m)] * 2
                        + [max(c.pnp_sigma_theta_rad * s, np.radians(0.5))])

    def pnp_loglik(self, particles: np.ndarray, fix: np.ndarray, sigmas: np.ndarray) -> np.ndarray:
        """Log-likelihood (N,) of the PnP robot pose `fix` (3,) at each particle (N, 3)."""
        d = particles - fix
        d[:, 2] = wrap_angle(d[:, 2])
        return np.logaddexp(-0.5 * np.sum((d / sigmas) ** 2, axis=1), self.config.pnp_outlier_loglik)

    def update_pnp(self, fix: np.ndarray, n_inliers: int) -> None:
        """The Mixture-MCL measurement step for a PnP robot pose `fix` (3,) (module docstring)."""
        pf, rng = self.pf, self.pf.rng
        n = len(pf.particles)
        m = max(1, round(self.config.pnp_fraction * n))
        sig = self.pnp_sigmas(n_inliers)
        keep = np.sort(rng.choice(n, n - m, replace=False))
        prior_w = pf.log_w[keep] - np.logaddexp.reduce(pf.log_w[keep])
        drawn = fix + rng.normal(size=(m, 3)) * sig
        drawn[:, 2] = wrap_angle(drawn[:, 2])
        x = np.r_[pf.particles[keep], drawn]
        pf.particles = x
        pf.log_w = np.r_[prior_w + np.log(n - m), np.zeros(m)]  # all: samples of the mixture, mean weight 1
        pf.update(self.mixture_log_weights(x, fix, sig, m / n))
        pf.resample_if_needed()
        self._update_estimate()

    def mixture_log_weights(self, x: np.ndarray, fix: np.ndarray, sig: np.ndarray, share: float) -> np.ndarray:
        """Importance log-weights (N,) of particles `x` (N, 3) drawn from the mixture
        proposal q = (1 - share) * prior + share * N(fix, sig) for the posterior
        L(fix | x) * prior(x): L * prior / q, the prior being a Gaussian fit of the predicted
        particles (widened by 5 cm and 2 degrees, and floored `pnp_outlier_loglik` below its
        peak like the fix's likelihood: the belief may be wrong too, so a confident but wrong
        prior cannot veto a fix entirely, and a second fix that agrees decides). Weighting each part by its own proposal only and mixing them in the
        ratio of their sizes (as before) kept 80 % of the mass on the prior however badly it
        fitted the fix: the filter's estimate was 13 cm off where its fixes were 3 cm off
        (office, 108 + 42 photos)."""
        mean, cov = self.mean, self.cov + np.diag([0.05**2, 0.05**2, np.radians(2) ** 2])
        log_prior = _gauss_logpdf(x, mean, cov)
        log_prior = np.logaddexp(log_prior, _gauss_logpdf(mean[None], mean, cov)[0] + self.config.pnp_outlier_loglik)
        log_draw = _gauss_logpdf(x, fix, np.diag(sig ** 2))
        log_q = np.logaddexp(np.log1p(-share) + log_prior, np.log(share) + log_draw)
        return self.pnp_loglik(x, fix, sig) + log_prior - log_q


def _gauss_logpdf(x: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Log-density (N,) of a Gaussian in (x, y, theta) at `x` (N, 3), the heading wrapped."""
    d = x - mean
    d[:, 2] = wrap_angle(d[:, 2])
    inv = np.linalg.inv(cov)
    return -0.5 * (np.einsum("ni,ij,nj->n", d, inv, d) + np.log(np.linalg.det(2 * np.pi * cov)))


class FilteredBody(Body):
    """A `Body` whose estimate (`est.pose`) is the mission localiser's: every move predicts
    the filter (and the dead-reckoning baseline, `localizer.dead_reckoning`)."""

    def __init__(self, robot: Robot, localizer: MissionLocalizer, path_m: float = 0.0):
        self.robot, self.est, self.path_m, self.bumps = robot, localizer, path_m, 0

    def move(self, turn: float = 0.0, drive: float = 0.0) -> MotionResult:
        before = self.robot.odometry()
        motion = self.robot.turn(turn) if turn else self.robot.drive(drive)
        after = self.robot.odometry()
        self.est.predict(before, after, self.robot.compass(), in_place=bool(turn))
        self.path_m += float(np.hypot(*(after[:2] - before[:2])))
        self.bumps += motion.blocked
        return motion
