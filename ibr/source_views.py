"""The source photos of a scene on the GPU, as the image-based renderers sample them: one
texture array of images (layer i = view i), one texture array of their proxy depth maps, and
shader storage buffers of each source's pixel_from_world matrix and centre.

pixel_from_world (4, 4) = [[K @ cam_from_world[:3]], [0, 0, 0, 1]]: for a world point P,
q = M @ (P, 1) gives pixels (q.x / q.z, q.y / q.z) and camera-z q.z in metres.
"""

from __future__ import annotations

import moderngl
import numpy as np

from ibr.camera import Camera
from ibr.errors import InputError


class SourceSizeError(InputError):
    """The source photos of a scene differ in size."""


def pixel_from_world(camera: Camera) -> np.ndarray:
    """(4, 4) matrix taking homogeneous world points to (u*z, v*z, z, 1) of `camera`."""
    M = np.eye(4)
    M[:3] = camera.K @ camera.cam_from_world[:3]
    return M


def project_with(M: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (..., 2) and camera-z (...) of world points (..., 3) under pixel_from_world M."""
    q = points @ M[:3, :3].T + M[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        return q[..., :2] / q[..., 2:3], q[..., 2]


class SourceViews:
    """GPU copies of N same-sized source views. images: (N, H, W, 3) uint8; depths:
    (N, H, W) float32 proxy camera-z (0 = empty) or None; cameras: their N cameras."""

    def __init__(self, ctx: moderngl.Context, cameras: list[Camera], images: np.ndarray,
                 depths: np.ndarray | None = None):
        sizes = {(c.width, c.height) for c in cameras}
        if len(sizes) != 1:
            raise SourceSizeError(f"source photos must share one size; got {sorted(sizes)}")
        self.ctx, self.cameras = ctx, list(cameras)
        self.size = sizes.pop()
        W, H = self.size
        N = len(cameras)
        self.images = ctx.texture_array((W, H, N), 3, np.ascontiguousarray(images, np.uint8).tobytes(),
                                        alignment=1)
        self.images.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self.images.repeat_x = self.images.repeat_y = False
        d = np.zeros((N, H, W), np.float32) if depths is None else np.ascontiguousarray(depths, np.float32)
        self.depths = ctx.texture_array((W, H, N), 1, d.tobytes(), dtype="f4")
        self.depths.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.matrices = np.stack([pixel_from_world(c) for c in cameras])
        self.centres = np.array([c.center for c in cameras])
        self.matrix_buffer = ctx.buffer(self.matrices.transpose(0, 2, 1).astype("f4").tobytes())
        self.centre_buffer = ctx.buffer(np.c_[self.centres, np.ones(N)].astype("f4").tobytes())

    def __len__(self) -> int:
        return len(self.cameras)

    def bind(self, prog: moderngl.Program, image_unit: int = 0, depth_unit: int = 1) -> None:
        """Bind the texture arrays to `u_images` / `u_depths` and the buffers to bindings 0, 1."""
        self.images.use(image_unit)
        self.depths.use(depth_unit)
        for name, unit in (("u_images", image_unit), ("u_depths", depth_unit)):
            if name in prog:
                prog[name] = unit
        self.matrix_buffer.bind_to_storage_buffer(0)
        self.centre_buffer.bind_to_storage_buffer(1)
        if "u_source_size" in prog:
            prog["u_source_size"] = tuple(float(x) for x in self.size)
        if "u_n_sources" in prog:
            prog["u_n_sources"] = len(self)

    def release(self) -> None:
        for obj in (self.images, self.depths, self.matrix_buffer, self.centre_buffer):
            obj.release()
