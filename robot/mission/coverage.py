"""Evaluation of a capture mission: how much of the true surface the photos cover.

Surface coverage (the measure of Foster, Wang & Grupen's evaluation, made exact here): the
ground-truth mesh is sampled uniformly by area; a sample counts as *covered* when at least two
photos see it from directions at least `min_angle_deg` apart (what view synthesis and stereo
need), each within `max_range_m`. A photo sees a sample when the sample projects inside its
image, faces it, and the segment between them is free: visibility is an embree ray cast
through trimesh. `coverage_curve` gives the coverage after every photo, in capture order.
Frames: world metres; cameras are `ibr.camera.Camera` (the photos' TRUE poses: this is
evaluation, it may use ground truth).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from trimesh.ray.ray_pyembree import RayMeshIntersector

from ibr.camera import Camera


@dataclass(frozen=True)
class CoverageConfig:
    """Settings of the coverage measure."""

    n_samples: int = 8000
    """Surface samples on the true mesh (area-uniform)."""
    min_angle_deg: float = 5.0
    """Two sightings count as a stereo pair when their directions differ at least this much (deg)."""
    max_range_m: float = 6.0
    """A photo sees a sample only within this distance (m)."""
    seed: int = 0
    """Seed of the surface samples (the same samples for every strategy compared)."""


@dataclass
class SurfaceSamples:
    """points (S, 3) world metres on the mesh, normals (S, 3) unit outward face normals."""

    points: np.ndarray
    normals: np.ndarray


def surface_samples(mesh: trimesh.Trimesh, n: int, rng: np.random.Generator) -> SurfaceSamples:
    """`n` points uniform by area on `mesh`, with their face normals."""
    areas = mesh.area_faces
    face = rng.choice(len(areas), size=n, p=areas / areas.sum())
    r1, r2 = rng.random(n), rng.random(n)
    flip = r1 + r2 > 1
    r1[flip], r2[flip] = 1 - r1[flip], 1 - r2[flip]
    tri = mesh.triangles[face]
    pts = tri[:, 0] + r1[:, None] * (tri[:, 1] - tri[:, 0]) + r2[:, None] * (tri[:, 2] - tri[:, 0])
    return SurfaceSamples(pts, mesh.face_normals[face])


def visible_samples(samples: SurfaceSamples, camera: Camera, rays: RayMeshIntersector,
                    max_range_m: float) -> np.ndarray:
    """(S,) bool: the samples `camera` sees (in its image, facing it, within range, unoccluded)."""
    c = camera.center
    to_cam = c - samples.points
    dist = np.linalg.norm(to_cam, axis=1)
    uv, z = camera.project(samples.points)
    ok = ((z > 0) & (dist < max_range_m) & (np.einsum("ij,ij->i", to_cam, samples.normals) > 0)
          & (uv[:, 0] >= -0.5) & (uv[:, 0] < camera.width - 0.5)
          & (uv[:, 1] >= -0.5) & (uv[:, 1] < camera.height - 0.5))
    idx = np.flatnonzero(ok)
    if len(idx) == 0:
        return ok
    dirs = to_cam[idx] / dist[idx, None]
    origins = samples.points[idx] + 1e-3 * dirs
    hits, ray, _ = rays.intersects_location(origins, dirs, multiple_hits=False)
    blocked = np.zeros(len(idx), bool)
    hit_d = np.linalg.norm(hits - origins[ray], axis=1)
    blocked[ray[hit_d < dist[idx][ray] - 2e-3]] = True
    ok[idx[blocked]] = False
    return ok


class CoverageTracker:
    """Coverage of a growing photo set: `add(camera)` after each photo returns the covered
    fraction so far. Exact: a sample is covered as soon as any two of its sightings are
    `min_angle_deg` apart."""

    def __init__(self, mesh: trimesh.Trimesh, config: CoverageConfig = CoverageConfig()):
        self.config = config
        self.samples = surface_samples(mesh, config.n_samples, np.random.default_rng(config.seed))
        self.rays = RayMeshIntersector(mesh)
        self.sightings: list[list[np.ndarray]] = []  # per photo: (visible idx, unit dirs)
        self.covered = np.zeros(config.n_samples, bool)
        self._dirs: dict[int, list[np.ndarray]] = {}
        self._cos = np.cos(np.radians(config.min_angle_deg))
        self.curve: list[tuple[int, float]] = []

    def add(self, camera: Camera) -> float:
        """Add one photo's camera; returns the coverage (fraction in [0, 1])."""
        vis = np.flatnonzero(visible_samples(self.samples, camera, self.rays, self.config.max_range_m))
        d = camera.center - self.samples.points[vis]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        for s, u in zip(vis, d):
            if self.covered[s]:
                continue
            seen = self._dirs.setdefault(int(s), [])
            if seen and (np.asarray(seen) @ u).min() <= self._cos:
                self.covered[s] = True
                del self._dirs[int(s)]
            else:
                seen.append(u)
        value = float(self.covered.mean())
        self.curve.append((len(self.curve) + 1, value))
        return value

    @property
    def value(self) -> float:
        return float(self.covered.mean())


def coverage_curve(mesh: trimesh.Trimesh, cameras: list[Camera],
                   config: CoverageConfig = CoverageConfig()) -> np.ndarray:
    """(len(cameras),) coverage after each photo, in order."""
    tracker = CoverageTracker(mesh, config)
    return np.array([tracker.add(c) for c in cameras])


def path_length(poses: np.ndarray) -> float:
    """Length (m) of the polyline through SE(2) or 2-D poses (N, >=2)."""
    xy = np.asarray(poses)[:, :2]
    return float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum()) if len(xy) > 1 else 0.0


def achievable_coverage(mesh: trimesh.Trimesh, free_space, cameras_at, n_poses: int = 2000, n_headings: int = 8,
                        clearance_m: float = 0.15, config: CoverageConfig = CoverageConfig()) -> float:
    """The coverage a dense capture of the whole free space reaches: about `n_poses` camera
    poses, positions on a square grid over `free_space` (shapely, eroded by `clearance_m`,
    the robot's radius) with `n_headings` evenly spaced headings each; `cameras_at(poses)`
    turns SE(2) robot poses (N, 3) into cameras (the robot's camera height and intrinsics).
    A sample counts as covered when some sighting is `min_angle_deg` or more from its first
    sighting (a lower bound of the exact pairwise test, tight for so dense a set). The
    ceiling a capture strategy is measured against."""
    import shapely

    region = free_space.buffer(-clearance_m)
    n_pos = max(1, n_poses // n_headings)
    step = np.sqrt(region.area / n_pos)
    x0, y0, x1, y1 = region.bounds
    gx, gy = np.meshgrid(np.arange(x0 + step / 2, x1, step), np.arange(y0 + step / 2, y1, step))
    xy = np.c_[gx.ravel(), gy.ravel()]
    xy = xy[shapely.contains_xy(region, xy[:, 0], xy[:, 1])]
    heads = np.linspace(-np.pi, np.pi, n_headings, endpoint=False)
    poses = np.array([[x, y, h] for x, y in xy for h in heads])
    samples = surface_samples(mesh, config.n_samples, np.random.default_rng(config.seed))
    rays = RayMeshIntersector(mesh)
    first = np.zeros((config.n_samples, 3))
    seen = np.zeros(config.n_samples, bool)
    covered = np.zeros(config.n_samples, bool)
    cos = np.cos(np.radians(config.min_angle_deg))
    for cam in cameras_at(poses):
        vis = visible_samples(samples, cam, rays, config.max_range_m)
        d = cam.center - samples.points[vis]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        idx = np.flatnonzero(vis)
        new = ~seen[idx]
        first[idx[new]] = d[new]
        seen[idx[new]] = True
        covered[idx[~new]] |= np.einsum("ij,ij->i", first[idx[~new]], d[~new]) <= cos
    return float(covered.mean())
