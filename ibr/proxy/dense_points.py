"""Dense points from GPU plane-sweep depth maps (`ibr.proxy.plane_sweep`), the stand-in for the
dense multi-view stereo (PMVS) whose point cloud Foster, Wang & Grupen mesh into their proxy.

The photos are swept at reduced resolution between depths bracketing the sparse triangulated
points, the depth maps are filtered for consistency across views, and every `stride`-th kept
pixel is lifted to a world point with its colour and the camera that saw it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from ibr.proxy.plane_sweep import PlaneSweep, PlaneSweepConfig, consistency_filter
from ibr.scene import Scene, View


@dataclass(frozen=True)
class DenseConfig:
    """Settings of `dense_points`."""

    scale: float = 0.5
    """Resolution of the sweep relative to the photos."""
    planes: int = 96
    """Depth planes swept per view."""
    stride: int = 2
    """Keep every stride-th pixel (both axes) of the filtered depth maps."""
    depth_margin: float = 1.3
    """The sweep spans [p1 / margin, p99 * margin] of the sparse points' camera depths."""


def depth_range(scene: Scene, points: np.ndarray, margin: float) -> tuple[float, float]:
    """Near and far sweep depth (camera-z) bracketing `points` (N, 3) seen by the cameras."""
    z_all = []
    for cam in scene.cameras:
        uv, z = cam.project(points)
        inside = cam.in_image(uv, z)
        z_all.append(z[inside])
    z = np.concatenate(z_all)
    if len(z) < 10:
        return 0.3, 30.0
    return max(1e-3, np.percentile(z, 1) / margin), np.percentile(z, 99) * margin


def downscaled(scene: Scene, s: float) -> Scene:
    """The scene with photos and cameras scaled by `s`."""
    views = []
    for v in scene.views:
        cam = v.camera.scaled(s)
        img = cv2.resize(v.image, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
        views.append(View(cam, img, v.path))
    return dataclasses.replace(scene, views=views)


def dense_points(scene: Scene, sparse_points: np.ndarray,
                 cfg: DenseConfig = DenseConfig()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World points (N, 3), colours (N, 3) uint8 and the centres (N, 3) of the cameras that
    saw them, from consistency-filtered plane-sweep depth maps of every photo."""
    small = downscaled(scene, cfg.scale)
    sweep_cfg = PlaneSweepConfig(depth_range=depth_range(scene, sparse_points, cfg.depth_margin),
                                 planes=cfg.planes)
    sweep = PlaneSweep(small, sweep_cfg)
    depths, scores = sweep.depth_maps()
    sweep.release()
    depths = consistency_filter(small, depths, scores, sweep_cfg)
    pts, cols, eyes = [], [], []
    for view, depth in zip(small.views, depths):
        sub = np.zeros_like(depth, bool)
        sub[:: cfg.stride, :: cfg.stride] = True
        v, u = np.nonzero((depth > 0) & sub)
        pts.append(view.camera.unproject(np.c_[u, v].astype(float), depth[v, u]))
        cols.append(view.image[v, u])
        eyes.append(np.tile(view.camera.center, (len(u), 1)))
    return np.concatenate(pts), np.concatenate(cols), np.concatenate(eyes)
