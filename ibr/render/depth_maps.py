"""Per-source-view depth maps rendered from the proxy mesh: what the ULR visibility test
(shadow mapping against each source) and Heigl et al.'s local-depth light field look up.

Depth is camera-z in metres, 0 where the proxy does not cover the pixel.
"""

from __future__ import annotations

import moderngl
import numpy as np
import trimesh

from ibr.camera import Camera
from ibr.mesh_renderer import MeshRenderer


def render_depth_maps(mesh: trimesh.Trimesh, cameras: list[Camera],
                      ctx: moderngl.Context | None = None) -> np.ndarray:
    """(N, H, W) float32 camera-z depth of `mesh` seen by each camera (all one size), drawn
    in one batched pass of the mesh renderer."""
    renderer = MeshRenderer(mesh, ctx)
    return renderer.render_batch(cameras)[1]
