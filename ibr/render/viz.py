"""Rerun logging of image-based renders (entity tree: docs/ARCHITECTURE.md)."""

from __future__ import annotations

import numpy as np
import rerun as rr

from ibr.camera import Camera
from ibr.viz import log_camera


def log_render(camera: Camera, image: np.ndarray, covered: np.ndarray, method: str, step: int) -> None:
    """One rendered frame of a fly-through: the virtual camera with its image at
    world/render/<method>, the covered fraction under plots/render/<method>/coverage."""
    rr.set_time("step", sequence=step)
    log_camera(f"world/render/{method}", camera, image)
    rr.log(f"plots/render/{method}/coverage", rr.Scalars(float(covered.mean())))
