"""Hybrid localisation: the feature-based PnP pose as a proposal inside the 6-DoF particle
filter (a mixture proposal, as in Thrun et al.'s Mixture-MCL: part of the particles come
from the measurement rather than from the motion model).

When the photo's SIFT features match the map (Foster, Wang & Grupen, IV-B), pycolmap's
RANSAC PnP gives a pose; every filter step then replaces a fraction of the particles with
samples around it, at the filter's current random-walk noise, and the rendered-view
likelihood (Heigl et al.) weights them like the others. When features do not match, PnP
fails and the filter runs on the rendered likelihood alone.

With `HybridConfig.feature_weight` > 0 the PnP inliers are also a second measurement: each
particle's weight gains a truncated reprojection log-likelihood of those correspondences
(sensor fusion). With a vertex-coloured proxy (`--model proxy-colors`) the rendered
likelihood alone has false maxima within the +-1 m prior that out-score the true pose, and
the proposal alone is not enough; the feature term pins the pose to the inliers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ibr.camera import Camera
from localization.feature_localizer import FeatureMap, PnPResult
from localization.pose6_filter import (Pose6Estimate, Pose6Filter, cam_from_world_of,
                                      particles_from_cam_from_world, perturb)


@dataclass(frozen=True)
class HybridConfig:
    """Settings of `localize_hybrid`."""

    pnp_fraction: float = 0.3
    """Fraction of the particles drawn around the PnP pose each step (when PnP succeeds)."""
    pnp_sigma_scale: float = 1.0
    """Spread of the PnP samples relative to the filter's current random-walk noise."""
    feature_weight: float = 5.0
    """Weight of the PnP inliers' reprojection log-likelihood (0: rendered likelihood only)."""
    reprojection_sigma_px: float = 2.0
    """Reprojection noise (pixels, 1-sigma) of the feature likelihood."""
    reprojection_cap_px: float = 8.0
    """Residuals are truncated here (pixels): a robust, bounded likelihood."""


@dataclass
class HybridResult:
    """estimate: the particle filter's result; pnp: the PnP result or None when it failed."""

    estimate: Pose6Estimate
    pnp: PnPResult | None


def pnp_proposal(pnp: PnPResult, pf: Pose6Filter, n: int, sigma_scale: float, rng: np.random.Generator):
    """proposal(step) -> (n, 6) particles around the PnP pose at the filter's current random-walk noise."""
    centre = particles_from_cam_from_world(pnp.cam_from_world)

    def proposal(step: int) -> np.ndarray:
        sigma_m, sigma_rad = pf.sigma
        return perturb(np.repeat(centre, n, axis=0), sigma_scale * sigma_m, sigma_scale * sigma_rad, rng)
    return proposal


def reprojection_loglik(pnp: PnPResult, camera: Camera, config: HybridConfig):
    """loglik(particles (N, 6)) -> (N,): feature_weight * mean over the PnP inliers of
    -min(r, cap)^2 / (2 sigma^2), r the reprojection error (pixels) at each particle's pose."""
    xyz, uv = pnp.inlier_xyz, pnp.inlier_uv
    cap2, s2 = config.reprojection_cap_px ** 2, 2 * config.reprojection_sigma_px ** 2

    def loglik(particles: np.ndarray) -> np.ndarray:
        T = cam_from_world_of(particles)
        pc = np.einsum("nij,mj->nmi", T[:, :3, :3], xyz) + T[:, None, :3, 3]
        z = pc[..., 2]
        pix = np.einsum("ij,nmj->nmi", camera.K, pc)
        with np.errstate(divide="ignore", invalid="ignore"):
            r2 = np.sum((pix[..., :2] / pix[..., 2:3] - uv) ** 2, axis=2)
        r2 = np.where((z > 0) & np.isfinite(r2), np.minimum(r2, cap2), cap2)
        return -config.feature_weight * r2.mean(axis=1) / s2
    return loglik


def localize_hybrid(pf: Pose6Filter, features: FeatureMap, image: np.ndarray, camera: Camera,
                    particles: np.ndarray, config: HybridConfig = HybridConfig(),
                    pnp: PnPResult | None = None, on_step=None) -> HybridResult:
    """Localise `image` (H, W, 3) uint8 (intrinsics of `camera`) from prior particles (N, 6):
    PnP first (unless `pnp` is given), then the particle filter with the PnP mixture proposal."""
    if pnp is None:
        pnp = features.localize(image, camera)
    proposal = extra = None
    if pnp is not None:
        n = max(1, round(config.pnp_fraction * pf.config.n_particles))  # of the thinned set
        proposal = pnp_proposal(pnp, pf, n, config.pnp_sigma_scale, pf.rng)
        if config.feature_weight > 0 and pnp.inlier_xyz is not None:
            extra = reprojection_loglik(pnp, camera, config)
    return HybridResult(pf.run(image, camera, particles, proposal, on_step, extra), pnp)
