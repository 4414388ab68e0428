"""Rendered-view likelihood for a level robot camera (SE(2) poses), in any world: rooms,
apartments and outdoor sites alike.

The views of all N particles are drawn in one instanced pass (`MeshRenderer.draw_views`)
and read back at a small size (32x24 or 64x48: a few MB). Each view is compared with the
photo by a *horizon-free* normalised cross-correlation:

1. pixels where the model has no geometry take the world's background (the sky outdoors),
   as they do in the photo: the skyline of the buildings is the strongest cue outdoors,
   and a score over the covered pixels only rewards a close-up facade whose bright top
   mimics the sky (measured in the courtyard: such far poses out-score the truth);
2. every image row loses its mean before the correlation. A level camera's rows are lines
   of constant elevation, so the row means are the horizon profile (sky above, ground below,
   ceiling and floor indoors) that every level view of a site shares; left in, it makes all
   outdoor views correlate at 0.97-0.98 with the photo and the truth stands out by 0.01.
   Removed, what remains varies with position and heading (facade edges, doors, furniture,
   ground texture).

3. views are rendered at `oversample` times the comparison size and area-averaged down, as
   the photo is (`luminance`: INTER_AREA from the full image). Rendered straight at 32x24
   the ground's texture and the facade edges alias, and the view at the true pose matched
   its own photo at NCC 0.80 (measured in courtyard 3; 0.45 at 16x12); two times
   oversampled, 0.94 (0.87).

Score: NCC in [-1, 1]; log-likelihood -(1 - NCC) / temperature (dimensionless: the
temperature is in NCC units, the same in every world). Heigl et al.'s light-field
particle filter compares the camera image with the view rendered at each particle; this is
that comparison with the two changes above.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ibr.camera import Camera
from ibr.mesh_renderer import Light, MeshRenderer
from localization.pose_views import se2_views
from localization.render_likelihood import LUMA, luminance


def horizon_free(lum: np.ndarray) -> np.ndarray:
    """Luminance (..., h, w) with each row's mean removed."""
    return lum - lum.mean(axis=-1, keepdims=True)


def ncc_rows(views: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Horizon-free NCC (N,) of views (N, h, w) with the observation (h, w), luminance."""
    v = horizon_free(views).reshape(len(views), -1)
    o = horizon_free(observed).ravel()
    num = v @ o
    den = np.sqrt(np.einsum("ij,ij->i", v, v) * float(o @ o)) + 1e-9
    return num / den


@dataclass
class LevelViewLikelihood:
    """model: the map's renderer (its `background` is what it shows where there is no
    geometry); light: lighting of the renders (the world's); camera: the robot camera's
    intrinsics and full size (a `Camera`, pose ignored); cam_from_robot: the mount (4, 4)."""

    model: MeshRenderer
    light: Light | None
    camera: Camera
    cam_from_robot: np.ndarray
    oversample: int = 2
    """Views are rendered at this many times the comparison size and area-averaged down
    (a ratio of pixel sizes, the same in every world: the photo is area-averaged from its
    full size, and 2 removes most of the aliasing at a 1.4x cost on llvmpipe)."""

    def __post_init__(self):
        self._observed: np.ndarray | None = None

    def set_observation(self, image: np.ndarray, size: tuple[int, int]) -> None:
        """The photo (H, W, 3) uint8 to compare with, at `size` (width, height)."""
        self._observed = luminance(image, size)

    def observed_contrast(self) -> float:
        """The observation's horizon-free variance (luminance^2)."""
        return float(horizon_free(self._observed).var()) if self._observed is not None else 0.0

    def render(self, poses: np.ndarray, size: tuple[int, int]) -> np.ndarray:
        """Luminance (N, h, w) in [0, 1] of the views at SE(2) poses (N, 3), the background
        where there is no geometry; rendered `oversample` times larger, area-averaged."""
        k = self.oversample
        lum = self._render(poses, (size[0] * k, size[1] * k))
        if k == 1:
            return lum
        return lum.reshape(len(lum), size[1], k, size[0], k).mean(axis=(2, 4))

    def _render(self, poses: np.ndarray, size: tuple[int, int]) -> np.ndarray:
        """Luminance (N, h, w) of the views at `size`, rendered as they are."""
        W, H = size
        template = self.camera.scaled(W / self.camera.width)
        m = self.model
        clip, eyes = se2_views(poses, template, self.cam_from_robot, m.near, m.far)
        fbo, cols = m.draw_views(clip, eyes, size, self.light)
        aw, ah = fbo.size
        rows = ah // H
        n = len(poses)
        color = np.frombuffer(fbo.read(components=3, attachment=0), np.uint8).reshape(rows, H, cols, W, 3)
        depth = np.frombuffer(fbo.read(components=1, attachment=3, dtype="f4"), "f4").reshape(rows, H, cols, W)
        color = color.transpose(0, 2, 1, 3, 4).reshape(-1, H, W, 3)[:n]
        depth = depth.transpose(0, 2, 1, 3).reshape(-1, H, W)[:n]
        lum = color.astype(np.float32) @ (LUMA / 255.0)
        bg = float(np.asarray(m.background, np.float32) @ LUMA)
        return np.where(depth > 0, lum, bg)

    def ncc(self, poses: np.ndarray, size: tuple[int, int], chunk: int = 4096) -> np.ndarray:
        """Horizon-free NCC (N,) of the views at poses (N, 3) with the observation (which
        must have been set at `size`)."""
        if self._observed is None or self._observed.shape != (size[1], size[0]):
            raise RuntimeError(f"set_observation(image, {size}) first")
        poses = np.atleast_2d(poses)
        return np.concatenate([ncc_rows(self.render(poses[i:i + chunk], size), self._observed)
                               for i in range(0, len(poses), chunk)]) if len(poses) else np.zeros(0)
