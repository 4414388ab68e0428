"""Monte Carlo localisation of a robot by its camera: the particle filter's prediction is
the odometry, its measurement the rendered-view likelihood (Heigl et al.), evaluated
coarse-to-fine and tempered by how spread the particles are.

Coarse-to-fine: while the particles are spread (global localisation, after a kidnapping)
views are compared at `coarse_size`, which is cheaper and has a wider basin; once they
gather, at the likelihood's full size. Tempering: the likelihood temperature grows with the
spread, so a broad particle set is not collapsed onto a few lucky particles in one step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ibr.camera import Camera
from localization.particle_filter import ParticleFilter
from localization.pose_views import se2_views
from localization.render_likelihood import BatchedLikelihood, scores_to_loglik


@dataclass(frozen=True)
class RenderMCLConfig:
    coarse_size: tuple[int, int] = (32, 24)
    """Comparison size (px) while the particles are spread."""
    fine_below_m: float = 0.5
    """Switch to the full size once the position spread (m, 1-sigma) is below this."""
    temper_per_m: float = 2.0
    """Temperature multiplier per metre of position spread (1 + this * spread)."""


@dataclass
class StepReport:
    estimate: np.ndarray
    covariance: np.ndarray
    best: np.ndarray
    n_particles: int
    resampled: bool
    injected: int
    size: tuple[int, int]
    reinitialised: bool = False
    """Whether the filter re-initialised globally at this step (likelihood collapsed)."""


class RenderMCL:
    """pf: the SE(2) particle filter; likelihood: the batched rendered-view likelihood;
    camera: the robot camera's intrinsics and size (a `Camera`, pose ignored);
    cam_from_robot: the mount (4, 4)."""

    def __init__(self, pf: ParticleFilter, likelihood: BatchedLikelihood, camera: Camera,
                 cam_from_robot: np.ndarray, config: RenderMCLConfig = RenderMCLConfig()):
        self.pf, self.likelihood, self.config = pf, likelihood, config
        self.camera, self.cam_from_robot = camera, cam_from_robot

    def spread_m(self) -> float:
        _, cov, _ = self.pf.estimate()
        return float(np.sqrt(max(cov[0, 0] + cov[1, 1], 0.0) / 2))

    def measure(self, image: np.ndarray) -> tuple[int, int]:
        """Weight the particles by how well their rendered views match `image`."""
        spread = self.spread_m()
        size = self.config.coarse_size if spread > self.config.fine_below_m else self.likelihood.config.size
        self.likelihood.set_observation(image, size)
        template = self.camera.scaled(size[0] / self.camera.width)
        m = self.likelihood.model
        clip, eyes = se2_views(self.pf.particles, template, self.cam_from_robot, m.near, m.far)
        scores = self.likelihood.view_scores(clip, eyes)
        temperature = self.likelihood.config.temperature * (1 + self.config.temper_per_m * spread)
        # the weights are tempered; the augmented-MCL averages need the untempered
        # likelihood, or a spread filter would look as good as a converged one
        self.pf.update(scores_to_loglik(scores, self.likelihood.config, temperature),
                       fit_loglik=scores_to_loglik(scores, self.likelihood.config))
        return size

    def step(self, odom_before: np.ndarray, odom_after: np.ndarray, image: np.ndarray) -> StepReport:
        """Predict with the odometry, weight with the photo, resample when needed."""
        self.pf.predict(odom_before, odom_after)
        size = self.measure(image)
        mean, cov, best = self.pf.estimate()
        n = len(self.pf.particles)
        resampled = self.pf.resample_if_needed()
        return StepReport(mean, cov, best, n, resampled, self.pf.n_injected if resampled else 0, size,
                          self.pf.reinitialised if resampled else False)
