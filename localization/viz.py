"""Rerun logging for localisation: `world/estimate` and its error against a known truth."""

from __future__ import annotations

import numpy as np
import rerun as rr

from localization.motion_models import wrap_angle


def log_estimate(pose: np.ndarray, path: str = "world/estimate", height_m: float = 0.05) -> None:
    """SE(2) estimate (x, y, theta) as a point with a heading arrow."""
    x, y, th = pose
    rr.log(path, rr.Arrows3D(origins=[[x, y, height_m]], vectors=[[0.3 * np.cos(th), 0.3 * np.sin(th), 0]],
                             colors=[[40, 160, 255]], radii=0.02))


def log_estimate_error(estimate: np.ndarray, truth: np.ndarray) -> None:
    """plots/estimate_error_m and plots/estimate_error_deg."""
    rr.log("plots/estimate_error_m", rr.Scalars(float(np.hypot(*(estimate[:2] - truth[:2])))))
    rr.log("plots/estimate_error_deg", rr.Scalars(float(np.degrees(abs(wrap_angle(estimate[2] - truth[2]))))))


def log_particles(particles: np.ndarray, weights: np.ndarray, path: str = "world/particles",
                  height_m: float = 0.03) -> None:
    """SE(2) particles (N, 3) as points coloured by weight (dark blue low, yellow high)."""
    w = (weights / max(weights.max(), 1e-300))[:, None]
    colors = ((1 - w) * [40, 40, 150] + w * [250, 230, 40]).astype(np.uint8)
    rr.log(path, rr.Points3D(np.c_[particles[:, :2], np.full(len(particles), height_m)],
                             colors=colors, radii=0.02))


def log_observed_vs_rendered(observed: np.ndarray, rendered: np.ndarray) -> None:
    """The camera image and the model's view at the estimate, side by side."""
    rr.log("localization/observed", rr.Image(observed))
    rr.log("localization/rendered_at_estimate", rr.Image(rendered))


def log_pose6_particles(centres: np.ndarray, weights: np.ndarray, path: str = "world/particles") -> None:
    """6-DoF particles: their camera centres (N, 3) as points coloured by weight."""
    w = (weights / max(weights.max(), 1e-300))[:, None]
    colors = ((1 - w) * [40, 40, 150] + w * [250, 230, 40]).astype(np.uint8)
    rr.log(path, rr.Points3D(centres, colors=colors, radii=0.02))


def log_camera_pose(path: str, camera, image: np.ndarray | None = None) -> None:
    """A posed camera (`ibr.camera.Camera`), e.g. world/estimate or world/truth, with its image."""
    from ibr.viz import log_camera

    log_camera(path, camera, image)


def log_particle_count(n: int) -> None:
    """plots/particles: how many particles the filter holds."""
    rr.log("plots/particles", rr.Scalars(float(n)))
