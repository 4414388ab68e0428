"""A synthetic world: ground-truth textured mesh, free-space floor plan and a light, with
a way to photograph it from any camera. Worlds are generated in code from a seed.

World frame: metres, z up, the floor/ground at z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
import trimesh

from ibr.camera import Camera, intrinsics_from_fov
from ibr.mesh_renderer import Light, MeshRenderer


@dataclass(eq=False)
class SyntheticWorld:
    """name, seed: what `make_world(name, seed)` was called with.
    mesh: ground-truth trimesh (textured; vertex attribute `specular`).
    free_space: shapely (Multi)Polygon of the floor a robot centre may occupy before
        inflating by its radius (z = 0 plane, metres).
    light, background: how photographs are lit, and the RGB in [0, 1] behind the mesh.
    view_height_m: height of the default photo positions (metres).
    look_outward: default photos look out from the free space's centre (a room) rather than
        in at it from a ring around the site (an outdoor site).
    """

    name: str
    seed: int
    mesh: trimesh.Trimesh
    free_space: shapely.Polygon | shapely.MultiPolygon
    light: Light
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    view_height_m: float = 1.2
    look_outward: bool = True
    _renderers: dict = field(default_factory=dict, repr=False)

    def renderer(self, ctx=None) -> MeshRenderer:
        """The mesh renderer of this world on `ctx` (the shared context by default), cached."""
        key = id(ctx)
        if key not in self._renderers:
            self._renderers[key] = MeshRenderer(self.mesh, ctx, background=self.background)
        return self._renderers[key]

    def photograph(self, camera: Camera, ctx=None) -> np.ndarray:
        """The lit photo (H, W, 3) uint8 that `camera` takes of this world."""
        return self.renderer(ctx).render(camera, self.light).color

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) axis-aligned bounds of the mesh, metres."""
        return self.mesh.bounds

    def default_cameras(self, n: int, width: int = 640, height: int = 480,
                        fov_deg: float = 60.0) -> list[Camera]:
        """`n` photo cameras at `view_height_m`, with a little seeded jitter: overlapping
        neighbours, as a person walking around with a camera would take them. Indoors
        they stand in the free space looking out from its centre; outdoors they stand on
        a ring at 40% of the site's half-size looking in at its centre."""
        rng = np.random.default_rng(self.seed + 1000)
        K = intrinsics_from_fov(fov_deg, width, height)
        centre = np.array(self.free_space.centroid.coords[0])
        inner = self.free_space.buffer(-0.5)
        cams = []
        for i in range(n):
            yaw = 2 * np.pi * i / n + rng.normal(0, 0.05)
            d = np.array([np.cos(yaw), np.sin(yaw)])
            if self.look_outward:
                xy = _stand_point(inner, centre, d) + rng.normal(0, 0.05, 2)
                target = np.r_[xy + 3 * d, self.view_height_m - 0.2]
            else:
                radius = 0.4 * np.ptp(self.bounds[:, :2], axis=0).max()
                xy = centre + radius * d + rng.normal(0, 0.05, 2)
                target = np.r_[centre, 0.25 * self.bounds[1, 2]]
            eye = np.r_[xy, self.view_height_m + rng.normal(0, 0.05)]
            cams.append(Camera.look_at(eye, target, K, width, height, name=f"view_{i:03d}"))
        return cams


def _stand_point(free: shapely.Geometry, centre: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """A point 35% along the outermost free stretch of the ray centre + r * direction."""
    r = np.linspace(0, 60, 1201)
    pts = centre + r[:, None] * direction
    inside = shapely.contains_xy(free, pts[:, 0], pts[:, 1])
    if not inside.any():
        raise ValueError("no free space along a default camera ray")
    last = np.flatnonzero(inside)[-1]
    first = last
    while first > 0 and inside[first - 1]:
        first -= 1
    return pts[first] + 0.35 * (pts[last] - pts[first])
