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
