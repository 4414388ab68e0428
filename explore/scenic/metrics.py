"""Reconstruction quality as the Scenic Route Planner reports it (Mendez et al., Sec. 4.1.3,
Figure 5): coverage = fraction of ground-truth surface points with a reconstructed point
within d_i; outlier ratio = fraction of reconstructed points farther than d_i from the true
surface; mean error = mean distance to the surface of the inliers. Metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree


@dataclass
class GroundTruth:
    """mesh: the true surface; samples (M, 3): points sampled uniformly on it (metres)."""

    mesh: trimesh.Trimesh
    samples: np.ndarray

    @classmethod
    def from_mesh(cls, mesh: trimesh.Trimesh, n_samples: int, seed: int = 0) -> "GroundTruth":
        return cls(mesh, np.asarray(trimesh.sample.sample_surface(mesh, n_samples, seed=seed)[0]))


def evaluate(points: np.ndarray, gt: GroundTruth, d_i: float) -> dict[str, float]:
    """{'coverage', 'outlier_ratio', 'mean_error_m'} of reconstructed points (N, 3)."""
    if len(points) == 0:
        return {"coverage": 0.0, "outlier_ratio": 0.0, "mean_error_m": 0.0}
    near, _ = cKDTree(points).query(gt.samples, distance_upper_bound=d_i)
    coverage = float(np.mean(np.isfinite(near)))
    _, dist, _ = trimesh.proximity.closest_point(gt.mesh, points)
    inlier = dist <= d_i
    return {"coverage": coverage, "outlier_ratio": float(1.0 - inlier.mean()),
            "mean_error_m": float(dist[inlier].mean()) if inlier.any() else 0.0}
