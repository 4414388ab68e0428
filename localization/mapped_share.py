"""How much of a query photo's view its map could have modelled at all, from a synthetic
world's true mesh: the evaluation's measure of the capture, not of the localiser.

The rendered-view localiser compares a photo with a proxy triangulated from the map's photos
(SIFT matches between two photos, `ibr.proxy.triangulation`). A surface that no two map
photos see at a matchable angle has few points or none, so the proxy there is mostly a guess
or a hole, and a query looking at it has little the model holds to be localised by (a
conservative measure: a flat, well-marked wall can still match beyond 30 degrees, as the
courtyard's low west face did on seed 4). The courtyard's old map (24
photos evenly spaced on a ring 16 m from its centre, 3-6 m apart) showed why this needs
measuring: its photos 3.5 m from the low building's west face saw that face from no other
photo within 30 degrees. Over its seeds 1-5 (20 novel queries each, a prior of 10 % of the
scene's depth), the render-only filter localised 92 % of the 36 queries with a mapped share
of at least 0.5 and 16 % of the 64 below it; the office's 100 queries (99 at 0.5 or more)
all succeeded. The default ring now steps by the depth ahead (`SyntheticWorld.default_cameras`,
54-59 photos): over seeds 1-10, 190 of 200 novel queries have a share of 0.5 or more
(median 0.78), and 96 % of those were localised.

`MappedShare(mesh, map_cameras)(query_camera)`: the share of the query's pixels whose true
surface point two map photos see, unoccluded, with rays between `min_angle_deg` and
`max_angle_deg` apart. Frames: world metres; cameras as `ibr.camera.Camera`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from ibr.camera import Camera
from ibr.mesh_renderer import MeshRenderer
from localization.render_likelihood import comparison_camera


@dataclass(frozen=True)
class MappedShareConfig:
    """Settings of `MappedShare`. Angles and pixels only: nothing depends on the scene's size."""

    width: int = 160
    """Width (pixels) the query and the map photos are rendered at."""
    max_angle_deg: float = 30.0
    """Largest angle between two map photos' rays to a point that SIFT still matches: its
    matching falls off beyond 30-40 degrees of viewpoint change (Mikolajczyk et al., "A
    comparison of affine region detectors", IJCV 2005, figure 13), a property of the
    descriptor, not of a scene."""
    min_angle_deg: float = 1.5
    """Smallest such angle: `TriangulationConfig.min_angle_deg`, below which no point is kept."""
    depth_tolerance: float = 0.02
    """A map photo sees a point when its own true depth there is within this share of the
    point's depth (otherwise something stands in front)."""


class MappedShare:
    """The mapped share of query views (module docstring) against one map: the true `mesh`
    (world metres) and the map photos' `cameras`, rendered once here."""

    def __init__(self, mesh: trimesh.Trimesh, cameras: list[Camera],
                 config: MappedShareConfig = MappedShareConfig(), ctx=None):
        self.config = config
        self.renderer = MeshRenderer(mesh, ctx)
        self.cameras = [comparison_camera(c, min(config.width, c.width)) for c in cameras]
        self.depths = [self.renderer.render(c).depth for c in self.cameras]

    def release(self) -> None:
        self.renderer.release()

    def seen(self, points: np.ndarray) -> np.ndarray:
        """(V, N) whether map photo v sees world point n (in its image, in front, unoccluded)."""
        out = np.zeros((len(self.cameras), len(points)), bool)
        for v, (cam, depth) in enumerate(zip(self.cameras, self.depths)):
            uv, z = cam.project(points)
            inside = (z > 0) & np.all((uv >= 0) & (uv <= [cam.width - 1, cam.height - 1]), axis=1)
            ij = np.clip(np.nan_to_num(np.round(uv)).astype(int), 0, [cam.width - 1, cam.height - 1])
            d = depth[ij[:, 1], ij[:, 0]]
            out[v] = inside & (np.abs(d - z) < self.config.depth_tolerance * np.maximum(z, 1e-9))
        return out

    def stereo_seen(self, points: np.ndarray) -> np.ndarray:
        """(N,) whether two map photos see each world point (N, 3) at a matchable angle."""
        c = self.config
        seen = self.seen(points)
        rays = np.stack([points - cam.center for cam in self.cameras])
        rays /= np.maximum(np.linalg.norm(rays, axis=2, keepdims=True), 1e-12)
        lo, hi = np.cos(np.radians(c.max_angle_deg)), np.cos(np.radians(c.min_angle_deg))
        ok = np.zeros(len(points), bool)
        for a in range(len(self.cameras) - 1):
            cos = np.einsum("nk,vnk->vn", rays[a], rays[a + 1:])
            ok |= seen[a] & np.any(seen[a + 1:] & (cos > lo) & (cos < hi), axis=0)
        return ok

    def __call__(self, camera: Camera) -> float:
        """The share (0-1) of `camera`'s pixels showing a surface two map photos see at a
        matchable angle (sky and pixels showing nothing count as not mapped)."""
        cam = comparison_camera(camera, min(self.config.width, camera.width))
        g = self.renderer.render(cam)
        if not g.mask.any():
            return 0.0
        return float(self.stereo_seen(g.world[g.mask]).sum() / g.mask.size)
