"""Line-of-sight tests through a voxel grid with Embree (through `embreex`), for VuePlan
Phase II's visibility counts (Blaer & Allen 2009, Sec. 3.2.2): a ray from a boundary-unseen
voxel to a potential view is discarded when it crosses any blocked (seen-occupied or
unseen) voxel.

Instead of walking voxels, the faces between blocked and open voxels become a triangle
mesh (two triangles per face, voxel coordinates), and one occlusion query per segment
asks Embree whether any face lies on it. The segment starts where it leaves its first
voxel (that voxel, a boundary-unseen one, is allowed to be blocked), and the voxel it
enters next is looked up directly, because between two blocked voxels there is no face.
The answer is the voxel walk's (`voxel_grid.segments_clear`) except for segments that pass
exactly through a voxel edge or corner, where the two may break the tie differently.

Frames and units: voxel coordinates (world minus the grid origin, divided by voxel_m);
voxel (i, j, k) spans [i, i+1) x [j, j+1) x [k, k+1).
"""

from __future__ import annotations

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

_EPS = 1e-4  # voxels: the query starts this far past the first voxel's exit face


def blocker_faces(blocked: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The faces between blocked and open voxels of a (nx, ny, nz) bool grid as a triangle
    mesh: vertices (4F, 3) float32 (voxel coordinates) and triangles (2F, 3) int32."""
    corners = []
    unit = np.eye(3, dtype=np.int64)
    for a in range(3):
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[a], hi[a] = slice(0, -1), slice(1, None)
        face = np.argwhere(blocked[tuple(lo)] != blocked[tuple(hi)])  # (F, 3): the lower voxel
        base = face + unit[a]           # the face lies in the plane x_a = i_a + 1
        b, c = unit[(a + 1) % 3], unit[(a + 2) % 3]
        corners.append(np.stack([base, base + b, base + b + c, base + c], axis=1))
    quads = np.concatenate(corners).astype(np.float32)  # (F, 4, 3)
    n = len(quads)
    q = 4 * np.arange(n, dtype=np.int32)[:, None]
    tris = np.concatenate([q + [0, 1, 2], q + [0, 2, 3]]).astype(np.int32)
    return quads.reshape(-1, 3), tris


class VoxelOccluder:
    """Embree scene of the blocked/open faces of one grid state; `clear` answers many
    line-of-sight queries at once."""

    def __init__(self, blocked: np.ndarray):
        self.blocked = np.asarray(blocked, bool)
        vertices, triangles = blocker_faces(self.blocked)
        self.n_faces = len(triangles) // 2
        self._scene = None
        if self.n_faces:
            self._scene = rtcore_scene.EmbreeScene(robust=True)  # watertight: no leaks at edges
            TriangleMesh(scene=self._scene, vertices=vertices, indices=triangles)

    def clear(self, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
        """(R,) bool: true where segment p0 -> p1 (R, 3) (voxel coordinates, inside the
        grid) crosses no blocked voxel other than the one holding p0."""
        p0, p1 = np.asarray(p0, np.float64), np.asarray(p1, np.float64)
        d = p1 - p0
        first = np.floor(p0).astype(np.int64)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_axis = np.where(d > 0, (first + 1 - p0) / d, np.where(d < 0, (first - p0) / d, np.inf))
        axis = np.argmin(t_axis, axis=1)
        r = np.arange(len(p0))
        t_exit = t_axis[r, axis]
        out = t_exit < 1.0                           # the segment leaves its first voxel
        nxt = first.copy()
        nxt[r, axis] += np.sign(d[r, axis]).astype(np.int64)
        dims = np.array(self.blocked.shape)
        ok = np.all((nxt >= 0) & (nxt < dims), axis=1)
        c = np.clip(nxt, 0, dims - 1)
        clear = ~(out & ok & self.blocked[c[:, 0], c[:, 1], c[:, 2]])
        rows = np.flatnonzero(clear & out)
        if self._scene is None or len(rows) == 0:
            return clear
        length = np.linalg.norm(d[rows], axis=1)
        u = d[rows] / length[:, None]
        start = p0[rows] + t_exit[rows, None] * d[rows] + _EPS * u
        far = (1.0 - t_exit[rows]) * length - 2 * _EPS
        go = far > 0
        hit = np.zeros(len(rows), bool)
        if go.any():
            res = self._scene.run(start[go].astype(np.float32), u[go].astype(np.float32),
                                  dists=far[go].astype(np.float32), query="OCCLUDED")
            hit[go] = res >= 0
        clear[rows[hit]] = False
        return clear
