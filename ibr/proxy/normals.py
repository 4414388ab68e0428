"""Normals from neighbouring points (PCA over a KD-tree neighbourhood), oriented towards the
cameras that saw each point, statistical outlier removal, and repeats merged. Used to turn
triangulated SIFT points into an oriented point set for Poisson meshing (Foster et al.,
section IV-B).

Points are world-frame metres, (N, 3) float64.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def remove_outliers(points: np.ndarray, k: int = 12, n_std: float = 2.0) -> np.ndarray:
    """(N,) bool mask of points whose mean distance to their k nearest neighbours is within
    `n_std` standard deviations of the cloud's mean (statistical outlier removal)."""
    if len(points) <= k:
        return np.ones(len(points), bool)
    d, _ = cKDTree(points).query(points, k + 1)
    mean_d = d[:, 1:].mean(axis=1)
    return mean_d <= mean_d.mean() + n_std * mean_d.std()


def merge_repeats(points: np.ndarray, normals: np.ndarray, colors: np.ndarray,
                  cell_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points, normals, colors) merged to one per cube of `cell_m` metres: the mean of its
    points, their mean normal (unit; one of theirs where they cancel) and mean colour (uint8).
    Pair tracks triangulate one feature from several pairs a millimetre or two apart;
    merged, the cloud's spacing (`poisson.drop_faces_far_from_points`) and Poisson's sample
    weights count places on the surface, not repeats of one feature."""
    points, normals = np.asarray(points, float).reshape(-1, 3), np.asarray(normals, float).reshape(-1, 3)
    if len(points) == 0:
        return points, normals, np.asarray(colors, np.uint8).reshape(-1, 3)
    key = np.floor((points - points.min(axis=0)) / cell_m).astype(np.int64)
    _, first, inv, count = np.unique(key, axis=0, return_index=True, return_inverse=True, return_counts=True)
    inv = inv.ravel()

    def total(values: np.ndarray) -> np.ndarray:
        out = np.zeros((len(count), values.shape[1]))
        np.add.at(out, inv, values)
        return out

    n = total(normals)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(length > 1e-6, n / np.maximum(length, 1e-12), normals[first])
    colours = np.round(total(np.asarray(colors, float)) / count[:, None]).astype(np.uint8)
    return total(points) / count[:, None], n, colours


def estimate_normals(points: np.ndarray, viewpoints: np.ndarray, k: int = 16) -> np.ndarray:
    """Unit normals (N, 3): the smallest principal axis of each point's k nearest neighbours,
    flipped to face `viewpoints` (N, 3), a camera centre that observed the point."""
    k = min(k, len(points))
    _, idx = cKDTree(points).query(points, k)
    nb = points[idx.reshape(len(points), -1)]               # (N, k, 3)
    nb = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb)                  # (N, 3, 3)
    _, vecs = np.linalg.eigh(cov)                           # ascending eigenvalues
    n = vecs[:, :, 0]
    flip = np.einsum("ij,ij->i", n, viewpoints - points) < 0
    n[flip] *= -1
    return n / np.linalg.norm(n, axis=1, keepdims=True)
