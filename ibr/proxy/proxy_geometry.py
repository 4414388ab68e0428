"""Geometric proxy from posed photos, cached beside the scene.

The pipeline Foster, Wang & Grupen use to get a proxy for unstructured lumigraph rendering
(section IV-B: features -> 3-D points with the known cameras -> oriented points -> Poisson
mesh), with their dense multi-view stereo replaced by triangulated SIFT matches:

1. SIFT features per image, matched between neighbouring views and triangulated with the
   fixed known poses (`ibr.proxy.triangulation`);
2. statistical outlier removal and PCA normals oriented towards the cameras (`ibr.proxy.normals`);
3. a screened Poisson mesh, trimmed to where there are points (`ibr.proxy.poisson`).

Optionally (`ProxyConfig.dense`) dense points from GPU plane-sweep stereo (`ibr.proxy.dense_points`)
join the SIFT points before meshing, closer to the paper's dense point cloud.

Results are cached in `scene.root / ".ibrnav_cache"` (a temporary folder for synthetic scenes),
keyed by a hash of the cameras, the images and the settings, so leave-one-out evaluation and
repeated renders do not recompute them.
"""

from __future__ import annotations

import hashlib
import os
import stat
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from ibr.proxy.dense_points import DenseConfig, dense_points
from ibr.proxy.normals import estimate_normals, remove_outliers
from ibr.proxy.poisson import MIN_POINTS, MeshingError, PoissonConfig, poisson_mesh
from ibr.scene import Scene
from ibr.proxy.triangulation import TriangulationConfig, sift_features, triangulate_views


@dataclass(frozen=True)
class ProxyConfig:
    """Settings of `build_proxy`."""

    triangulation: TriangulationConfig = field(default_factory=TriangulationConfig)
    """Feature matching and triangulation with known poses."""
    poisson: PoissonConfig = field(default_factory=PoissonConfig)
    """Poisson meshing."""
    normal_neighbours: int = 16
    """Neighbours used for each point's PCA normal."""
    dense: DenseConfig | None = None
    """Also mesh dense points from GPU plane-sweep depth maps (`ibr.proxy.dense_points`); None: the
    triangulated SIFT points alone."""


@dataclass
class Proxy:
    """mesh: the proxy surface (world metres, vertex colours); points (N, 3) and colors (N, 3)
    uint8: the triangulated points it was meshed from."""

    mesh: trimesh.Trimesh
    points: np.ndarray
    colors: np.ndarray


def cache_dir(scene: Scene) -> Path:
    """Where derived data of `scene` is cached (created on demand): `.ibrnav_cache` beside
    the scene, or the temp dir when the scene folder is read-only. Read-only means its mode
    has no owner write bit, so a shared data set stays untouched even for root (who may
    write anywhere). Entries are keyed by `scene_key`, so scenes never share one."""
    temp = Path(tempfile.gettempdir()) / "ibrnav_cache"
    root = Path(scene.root) if scene.root is not None else None
    base = root / ".ibrnav_cache" if root is not None and _writable(root) else temp
    try:
        base.mkdir(parents=True, exist_ok=True)
    except OSError:
        base = temp
        base.mkdir(parents=True, exist_ok=True)
    return base


def _writable(folder: Path) -> bool:
    try:
        return bool(folder.stat().st_mode & stat.S_IWUSR) and os.access(folder, os.W_OK)
    except OSError:
        return False


def scene_key(scene: Scene, cfg: ProxyConfig) -> str:
    """Hash of the scene's cameras, images and the settings (hex, 16 chars)."""
    h = hashlib.sha1(repr(cfg).encode())
    for v in scene.views:
        h.update(v.name.encode())
        h.update(np.ascontiguousarray(v.camera.K).tobytes())
        h.update(np.ascontiguousarray(v.camera.cam_from_world).tobytes())
        h.update(np.ascontiguousarray(v.image[::7, ::7]).tobytes())
    return h.hexdigest()[:16]


def triangulated_points(scene: Scene, cfg: ProxyConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cleaned points (N, 3), colours (N, 3) uint8 and oriented normals (N, 3) of the scene."""
    feats = [sift_features(v.image, cfg.triangulation.n_features, cfg.triangulation.contrast_threshold)
             for v in scene.views]
    tri = triangulate_views(scene.cameras, feats, cfg.triangulation)
    if len(tri.points) < MIN_POINTS:
        raise MeshingError(f"scene {scene.name!r}: only {len(tri.points)} points triangulated from its "
                           f"{len(scene)} photos; a proxy needs at least {MIN_POINTS} (more photos, more "
                           "overlap between them, or larger images)")
    keep = remove_outliers(tri.points)
    pts, cols, pairs = tri.points[keep], tri.colors[keep], tri.view_pairs[keep]
    centres = np.array([c.center for c in scene.cameras])
    eyes = 0.5 * (centres[pairs[:, 0]] + centres[pairs[:, 1]])
    if cfg.dense is not None:
        d_pts, d_cols, d_eyes = dense_points(scene, pts, cfg.dense)
        pts, cols, eyes = np.r_[pts, d_pts], np.r_[cols, d_cols], np.r_[eyes, d_eyes]
    return pts, cols, estimate_normals(pts, eyes, cfg.normal_neighbours)


def build_proxy(scene: Scene, cfg: ProxyConfig = ProxyConfig(), use_cache: bool = True) -> Proxy:
    """The proxy mesh of a posed scene (from its photos only), from the cache when present."""
    key = scene_key(scene, cfg)
    folder = cache_dir(scene)
    mesh_path, pts_path = folder / f"proxy_{key}.ply", folder / f"points_{key}.npz"
    if use_cache and mesh_path.is_file() and pts_path.is_file():
        data = np.load(pts_path)
        return Proxy(trimesh.load(mesh_path, process=False, force="mesh"), data["points"], data["colors"])
    pts, cols, normals = triangulated_points(scene, cfg)
    mesh = poisson_mesh(pts, normals, cols, cfg.poisson)
    if use_cache:
        mesh.export(mesh_path)
        np.savez_compressed(pts_path, points=pts, colors=cols)
    return Proxy(mesh, pts, cols)
