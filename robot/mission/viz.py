"""Rerun logging of the capture mission: the robot's map (`world/map/points`,
`world/map/mesh`, replaced per rebuild), where the map put each photo (`world/cameras/<name>`),
the virtual tour (`world/tour/camera`), the evaluation plots (`plots/coverage`,
`plots/photos`, `plots/dead_reckoning_error_m`) and eval-capture's views (`world/eval/true`
beside `world/eval/ulr`, `plots/eval/*` per view on the `step` timeline)."""

from __future__ import annotations

import numpy as np
import rerun as rr

from ibr.camera import Camera
from ibr.viz import log_camera, log_mesh, log_points


def log_posed_photo(camera: Camera, path_root: str = "world/cameras") -> None:
    """A photo's camera where the map put it (frustum only; the image is at world/robot/camera)."""
    log_camera(f"{path_root}/{camera.name}", camera)


def log_robot_map(points: np.ndarray, colors: np.ndarray, mesh) -> None:
    """The robot's current map: `world/map/points` and `world/map/mesh` (replaced per rebuild)."""
    log_points("world/map/points", points, colors, static=False)
    log_mesh("world/map/mesh", mesh, static=False)


def log_coverage(n_photos: int, coverage: float) -> None:
    """plots/coverage: fraction of the true surface covered after `n_photos` photos."""
    rr.log("plots/coverage", rr.Scalars(float(coverage)))
    rr.log("plots/photos", rr.Scalars(float(n_photos)))


def log_tour_frame(camera: Camera, image: np.ndarray) -> None:
    """One frame of the virtual tour at `world/tour/camera`."""
    log_camera("world/tour/camera", camera, image)


def log_dead_reckoning_error(dead_reckoning: np.ndarray, truth: np.ndarray) -> None:
    """plots/dead_reckoning_error_m: the baseline's position error, beside the filter's."""
    rr.log("plots/dead_reckoning_error_m", rr.Scalars(float(np.hypot(*(dead_reckoning[:2] - truth[:2])))))


def log_eval_view(k: int, camera: Camera, rendered: np.ndarray, truth: np.ndarray, metrics: dict) -> None:
    """eval-capture's view `k` (step timeline): the world's true render at `world/eval/true`,
    the model's ULR render at `world/eval/ulr`, and its `metrics` (psnr_db, ssim, covered;
    None where nothing was covered) at `plots/eval/<name>`."""
    rr.set_time("step", sequence=k)
    log_camera("world/eval/true", camera, truth)
    log_camera("world/eval/ulr", camera, rendered)
    for name, value in metrics.items():
        if value is not None and np.isfinite(value):
            rr.log(f"plots/eval/{name}", rr.Scalars(float(value)))
