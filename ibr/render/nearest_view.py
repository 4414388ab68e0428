"""Baseline view synthesis: the single nearest source photo reprojected through the proxy.

What a user would try first: pick the source camera closest to the virtual one (centre
distance plus the angle between the optical axes times the scene depth, both in metres),
rasterise the proxy from the virtual camera and fetch each surface point's colour from that
one photo where the point is inside it and visible (the same shadow-map test as ULR). Pixels
the one photo does not see are holes (filled by push-pull, reported as not covered).
"""

from __future__ import annotations

import numpy as np

from ibr.camera import Camera
from ibr.render.ulr import UlrConfig, UlrFrame, UlrRenderer


def nearest_source(camera: Camera, sources: list[Camera], scene_depth_m: float) -> int:
    """Index of the source whose centre distance + scene_depth_m * axis angle (metres) to
    `camera` is smallest."""
    C = np.array([s.center for s in sources])
    F = np.array([s.forward for s in sources])
    angle = np.arccos(np.clip(F @ camera.forward, -1.0, 1.0))
    return int(np.argmin(np.linalg.norm(C - camera.center, axis=1) + scene_depth_m * angle))


class NearestViewRenderer:
    """Reprojects the nearest source through the proxy; same arguments as `UlrRenderer`
    (whose shader does the reprojection with k = 1 and only that source)."""

    def __init__(self, scene, proxy_mesh, ctx=None, config: UlrConfig | None = None,
                 source_depths: np.ndarray | None = None):
        cfg = config or UlrConfig()
        self.ulr = UlrRenderer(scene, proxy_mesh, ctx, config=UlrConfig(**{**cfg.__dict__, "k": 1}),
                               source_depths=source_depths)

    def render_frame(self, camera: Camera) -> UlrFrame:
        depth = self.ulr.proxy_depth(camera)
        scene_depth = float(np.median(depth[depth > 0])) if (depth > 0).any() else 1.0
        i = nearest_source(camera, self.ulr.sources.cameras, scene_depth)
        return self.ulr.render_frame(camera, only_source=i)

    def render(self, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
        """(image (H, W, 3) uint8, covered (H, W) bool) of the virtual `camera`."""
        frame = self.render_frame(camera)
        return frame.image, frame.covered

    def release(self) -> None:
        self.ulr.release()
