"""VuePlan Phase II visibility counts on the GL pipeline (Blaer & Allen 2009, Sec. 3.2.2-3.2.4):
for every potential view, the number of boundary-unseen voxels it sees, with all (voxel,
view) pairs tested in one batched compute pass (`explore/shaders/voxel_visibility.glsl`):
range, grazing angle at the exposed faces, then a voxel walk through the grid with a
distance-field skip -- the same test as the numpy walk (`voxel_grid.segments_clear`) and the
Embree queries (`voxel_occlusion.VoxelOccluder`, the exact reference), which it matches up
to rays through voxel edges or corners, where float32 may break the tie the other way.

Frames and units: voxel coordinates (world minus the grid origin, over voxel_m); metres for
the ranges. Runs on the shared GL context (llvmpipe on a CPU, or a GPU).
"""

from __future__ import annotations

import moderngl
import numpy as np

from ibr.gl import load_compute, shared_context

GROUP = 64           # local size of the compute shader (views per work group)
VOXELS_PER_INVOCATION = 64  # boundary voxels one invocation walks to its view
MAX_GROUPS_Y = 65535  # GL's guaranteed limit on work groups per dispatch axis


def face_bits(faces: np.ndarray) -> np.ndarray:
    """(m,) int: the exposed-face flags (m, 6) (FACE_NORMALS order) as bits 0..5."""
    return (np.asarray(faces, np.int64) << np.arange(6)).sum(axis=1)


class GLVoxelVisibility:
    """The compute program on one GL context; `count` runs one grid state."""

    def __init__(self, ctx: moderngl.Context | None = None):
        self.ctx = ctx or shared_context()
        self.program = load_compute(self.ctx, "voxel_visibility",
                                    {"VOXELS_PER_INVOCATION": VOXELS_PER_INVOCATION}, package="explore")

    def count(self, distance: np.ndarray, voxels: np.ndarray, faces: np.ndarray, views: np.ndarray,
              voxel_m: float, min_range_m: float, max_range_m: float, cos_max: float
              ) -> tuple[np.ndarray, int]:
        """(P,) number of voxels (m, 3) int (with exposed faces (m, 6) bool) visible from
        each view (P, 3) (voxel coordinates), and the number of rays walked (the pairs left
        after the range and grazing tests). distance (nx, ny, nz): `blocker_distance` of the
        blocked voxels (0 on them), in voxels."""
        n_views = len(views)
        if len(voxels) == 0 or n_views == 0:
            return np.zeros(n_views, np.int64), 0
        bufs = [self.ctx.buffer(np.ascontiguousarray(distance, "f4").tobytes()),
                self.ctx.buffer(np.c_[voxels, face_bits(faces)].astype("i4").tobytes()),
                self.ctx.buffer(np.c_[views, np.zeros(n_views)].astype("f4").tobytes()),
                self.ctx.buffer(np.zeros(n_views + 1, "u4").tobytes())]
        for i, b in enumerate(bufs):
            b.bind_to_storage_buffer(i)
        prog = self.program
        uniforms = {"u_shape": tuple(int(s) for s in distance.shape), "u_n_voxels": len(voxels),
                    "u_n_views": n_views, "u_voxel_m": float(voxel_m), "u_min_range_m": float(min_range_m),
                    "u_max_range_m": float(max_range_m), "u_cos_max": float(cos_max)}
        for name, value in uniforms.items():
            if name in prog:
                prog[name] = value
        gx = (n_views + GROUP - 1) // GROUP
        blocks = (len(voxels) + VOXELS_PER_INVOCATION - 1) // VOXELS_PER_INVOCATION
        for offset in range(0, blocks, MAX_GROUPS_Y):
            prog["u_voxel_offset"] = offset
            prog.run(gx, min(MAX_GROUPS_Y, blocks - offset))
        self.ctx.memory_barrier()
        counts = np.frombuffer(bufs[3].read(), "u4").astype(np.int64)
        for b in bufs:
            b.release()
        return counts[:-1], int(counts[-1])

    def release(self) -> None:
        self.program.release()
