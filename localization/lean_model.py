"""A lean copy of a proxy mesh for the particle likelihood: llvmpipe's cost grows with
triangles, and the likelihood needs the proxy's shape, not its detail, so this pass renders a
decimated copy.

Quadric edge-collapse decimation (Garland & Heckbert 1997, through `fast_simplification`);
each kept vertex takes the colour of the nearest vertex of the original mesh, so the lean
model still renders photo-like views.
"""

from __future__ import annotations

import fast_simplification
import numpy as np
import trimesh
from scipy.spatial import cKDTree


def lean_mesh(mesh: trimesh.Trimesh, max_faces: int) -> trimesh.Trimesh:
    """`mesh` (vertex-coloured, world metres) decimated to at most about `max_faces`
    triangles, vertex colours carried over; returned unchanged when already small enough
    or when textured (decimation would lose its UV layout)."""
    if len(mesh.faces) <= max_faces or mesh.visual.kind not in ("vertex", None):
        return mesh
    reduction = 1.0 - max_faces / len(mesh.faces)
    v, f = fast_simplification.simplify(np.asarray(mesh.vertices, np.float64),
                                        np.asarray(mesh.faces, np.int64), target_reduction=reduction)
    colors = None
    if mesh.visual.kind == "vertex":
        _, nearest = cKDTree(mesh.vertices).query(v)
        colors = np.asarray(mesh.visual.vertex_colors)[nearest]
    return trimesh.Trimesh(v, f, vertex_colors=colors, process=False)
