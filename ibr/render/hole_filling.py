"""Hole filling by push-pull (Gortler et al. 1996, the lumigraph's pull-push): values known
at some pixels are averaged down an image pyramid with their weights (pull), then the coarse
levels fill the pixels that had no weight on the way back up (push). Used by the renderers
to interpolate the virtual view's proxy depth into holes, as Foster et al. (section V-C)
"handle holes in the rasterized point cloud by interpolating the depths from nearby pixels",
and to fill colours that no source covers.
"""

from __future__ import annotations

import numpy as np


def _pull(values: np.ndarray, weight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One pyramid level down: 2x2 weighted means (values premultiplied by weight)."""
    H, W = weight.shape
    ph, pw = H % 2, W % 2
    v = np.pad(values * weight[..., None], ((0, ph), (0, pw), (0, 0)))
    w = np.pad(weight, ((0, ph), (0, pw)))
    vs = v.reshape(v.shape[0] // 2, 2, v.shape[1] // 2, 2, -1).sum(axis=(1, 3))
    ws = w.reshape(w.shape[0] // 2, 2, w.shape[1] // 2, 2).sum(axis=(1, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(ws[..., None] > 0, vs / np.maximum(ws, 1e-12)[..., None], 0.0)
    return mean, np.minimum(ws, 1.0)


def push_pull(values: np.ndarray, known: np.ndarray) -> np.ndarray:
    """Fill the pixels where `known` (H, W) bool is false from the known ones.

    values: (H, W) or (H, W, C) float array. Returns the filled array, same shape and dtype
    float64; known pixels keep their values exactly. If no pixel is known, returns zeros.
    """
    squeeze = values.ndim == 2
    v = np.asarray(values, dtype=np.float64).reshape(*known.shape, -1)
    w = known.astype(np.float64)
    levels = [(v, w)]
    while min(levels[-1][1].shape) > 1:
        levels.append(_pull(*levels[-1]))
    filled = levels[-1][0]
    for v_l, w_l in reversed(levels[:-1]):
        up = np.repeat(np.repeat(filled, 2, axis=0), 2, axis=1)[: w_l.shape[0], : w_l.shape[1]]
        filled = w_l[..., None] * v_l + (1.0 - w_l[..., None]) * up
    out = np.where(known[..., None], v, filled)
    return out[..., 0] if squeeze else out
