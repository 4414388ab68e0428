"""Poisson surface reconstruction of an oriented point set through pycolmap
(`pycolmap.poisson_meshing`, Kazhdan's screened Poisson), followed by removing the parts of the
watertight surface that lie far from any input point (Poisson closes the surface where there
is no data; those faces would occlude real sources in the renderers).

Points/normals are world-frame metres; the result is a `trimesh.Trimesh` with vertex colours.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from ibr.errors import InputError


class MeshingError(InputError):
    """The points could not be meshed (too few, or Poisson produced nothing)."""


MIN_POINTS = 50
"""Fewest points the Poisson solve is given (fewer cannot outline a surface)."""


@dataclass(frozen=True)
class PoissonConfig:
    """Settings of `poisson_mesh`."""

    depth: int = 9
    """Octree depth of the Poisson solve (resolution ~ scene extent / 2**depth)."""
    trim: float = 0.0
    """pycolmap's density trim (faces of lower sample density are dropped). Triangulated SIFT
    points are too sparse for density trimming, so it is off; `max_gap_spacing` cuts instead."""
    threads: int = 2
    """Worker threads of the Poisson solve (pycolmap's -1 = all oversubscribes small machines)."""
    max_gap_spacing: float = 8.0
    """Faces with a vertex farther from the nearest input point than this many times the
    cloud's median distance to the 8th nearest point are dropped. 8 bridges the textureless
    patches of a facade (no SIFT points there) and still cuts the closing lid; on the Strecha
    sets it raised ULR's leave-one-out coverage from about 0.55 to 0.8."""


def write_oriented_ply(path: Path, points: np.ndarray, normals: np.ndarray, colors: np.ndarray) -> None:
    """Binary little-endian PLY with x y z nx ny nz (float32) red green blue (uint8)."""
    dt = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"),
                   ("nz", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    rec = np.empty(len(points), dt)
    for i, a in enumerate("xyz"):
        rec[a], rec["n" + a] = points[:, i], normals[:, i]
    for i, a in enumerate(("red", "green", "blue")):
        rec[a] = colors[:, i]
    props = "".join(f"property {'float' if dt[n] == np.float32 else 'uchar'} {n}\n" for n in dt.names)
    header = f"ply\nformat binary_little_endian 1.0\nelement vertex {len(points)}\n{props}end_header\n"
    path.write_bytes(header.encode() + rec.tobytes())


def poisson_mesh(points: np.ndarray, normals: np.ndarray, colors: np.ndarray,
                 cfg: PoissonConfig = PoissonConfig()) -> trimesh.Trimesh:
    """Screened Poisson mesh of (N, 3) points with unit normals and uint8 colours."""
    import pycolmap

    if len(points) < MIN_POINTS:
        raise MeshingError(f"only {len(points)} points to mesh; need at least {MIN_POINTS}")
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "points.ply", Path(tmp) / "mesh.ply"
        write_oriented_ply(src, points, normals, colors)
        opts = pycolmap.PoissonMeshingOptions()
        opts.depth, opts.trim, opts.color, opts.num_threads = cfg.depth, cfg.trim, True, cfg.threads
        pycolmap.poisson_meshing(src, dst, opts)
        if not dst.is_file():
            raise MeshingError("Poisson meshing produced no surface")
        mesh = trimesh.load(dst, process=False, force="mesh")
    return drop_faces_far_from_points(mesh, points, cfg.max_gap_spacing)


def drop_faces_far_from_points(mesh: trimesh.Trimesh, points: np.ndarray, factor: float) -> trimesh.Trimesh:
    """The mesh without faces having a vertex farther than `factor` x the median distance
    from a point to its 8th nearest neighbour, from the nearest of `points` (N, 3)."""
    tree = cKDTree(points)
    spacing = np.median(tree.query(points, min(9, len(points)))[0][:, -1])
    far = tree.query(mesh.vertices)[0] > factor * max(spacing, 1e-9)
    keep = ~far[mesh.faces].any(axis=1)
    mesh.update_faces(keep)
    mesh.remove_unreferenced_vertices()
    return mesh
