"""Z-buffer scan simulator (Blaer & Allen, "View Planning and Automated Data Acquisition for
Three-Dimensional Modeling of Complex Sites", J. Field Robotics 2009, Sec. 4.1).

A laser scanner at a scan position shoots rays over the whole sphere. As in the paper the
sphere is chopped into 60 x 60 deg windows (three elevation bands centred at -60, 0 and
+60 deg, six azimuths each), every window is rendered with the mesh renderer (all 18 in
one batched draw), and the camera-z depth of each pixel is unprojected to a world point:
each pixel is one laser beam. Windows overlap near the poles; a beam is kept only in the
first window that contains it, so every direction is sampled once.

Range limits: the paper sets the near/far clipping planes; here the exact radial range
is applied to the unprojected points (a plane clips by camera z, not by range). Beams that
hit nothing within the maximum range are reported as *no-return* directions (a real
scanner knows which beams came back empty); beams that hit closer than the minimum range
are dropped. Optional Gaussian range noise comes from a `numpy.random.Generator`.

Frames: world metres, z up.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ibr.camera import Camera, intrinsics_from_fov
from ibr.mesh_renderer import MeshRenderer

WINDOW_DEG = 60.0
ELEVATIONS_DEG = (-60.0, 0.0, 60.0)
AZIMUTHS_DEG = tuple(range(0, 360, 60))


@dataclass(frozen=True)
class ScanConfig:
    """A simulated range scanner."""

    resolution_deg: float = 0.5
    """Angular step between beams (degrees); each 60 deg window is 60 / step pixels wide."""
    min_range_m: float = 0.5
    """Returns closer than this are dropped (metres)."""
    max_range_m: float = 60.0
    """Returns farther than this become no-return beams (metres)."""
    range_noise_m: float = 0.0
    """Standard deviation of Gaussian noise added to each range (metres)."""


@dataclass
class Scan:
    """One simulated scan. origin (3,) scanner centre, metres (world); points (N, 3) world
    points of the returns; no_return (M, 3) unit world directions of beams with no return
    within max_range_m; max_range_m the range those beams are known empty to."""

    origin: np.ndarray
    points: np.ndarray
    no_return: np.ndarray
    max_range_m: float


def window_cameras(origin: np.ndarray, pixels: int, heading_rad: float = 0.0) -> list[Camera]:
    """The 18 square 60 x 60 deg cameras (pixels x pixels) at `origin` (3,) that tile the
    sphere, starting at azimuth `heading_rad`."""
    K = intrinsics_from_fov(WINDOW_DEG, pixels, pixels)
    cams = []
    for el in np.radians(ELEVATIONS_DEG):
        for az in np.radians(AZIMUTHS_DEG) + heading_rad:
            d = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
            cams.append(Camera.look_at(origin, np.asarray(origin, float) + d, K, pixels, pixels,
                                       name=f"scan_el{np.degrees(el):+.0f}_az{np.degrees(az):.0f}"))
    return cams


@functools.lru_cache(maxsize=8)
def window_ownership(pixels: int, heading_rad: float = 0.0) -> np.ndarray:
    """(18, pixels, pixels) bool: beam (k, v, u) is kept, i.e. no earlier window contains
    its direction. Independent of the scan position."""
    cams = window_cameras(np.zeros(3), pixels, heading_rad)
    uv = cams[0].pixel_grid().reshape(-1, 2)
    lim = np.tan(np.radians(WINDOW_DEG / 2)) * (1 + 1e-9)
    keep = np.ones((len(cams), pixels * pixels), bool)
    for k, cam in enumerate(cams):
        d = cam.ray_directions(uv)
        for j in range(k):
            c = d @ cams[j].world_from_cam[:3, :3]  # into window j's frame
            inside = (c[:, 2] > 0) & (np.abs(c[:, 0]) <= lim * c[:, 2]) & (np.abs(c[:, 1]) <= lim * c[:, 2])
            keep[k] &= ~inside
    return keep.reshape(len(cams), pixels, pixels)


def simulate_scan(renderer: MeshRenderer, origin: np.ndarray, cfg: ScanConfig,
                  rng: np.random.Generator | None = None) -> Scan:
    """Render the 18 windows around `origin` (3,) (one batched draw), unproject the
    depths, apply the range limits and noise. Returns a `Scan`."""
    origin = np.asarray(origin, dtype=np.float64)
    pixels = max(2, int(round(WINDOW_DEG / cfg.resolution_deg)))
    cams = window_cameras(origin, pixels)
    _, depth = renderer.render_batch(cams)
    keep = window_ownership(pixels)
    uv = cams[0].pixel_grid().reshape(-1, 2)
    points, empty = [], []
    for cam, z, k in zip(cams, depth.reshape(len(cams), -1), keep.reshape(len(cams), -1)):
        d = cam.ray_directions(uv[k])
        z = z[k].astype(np.float64)
        p = cam.unproject(uv[k], z)
        r = np.linalg.norm(p - origin, axis=1)
        hit = (z > 0) & (r <= cfg.max_range_m)
        good = hit & (r >= cfg.min_range_m)
        if cfg.range_noise_m > 0:
            if rng is None:
                raise ValueError("range noise needs a numpy Generator")
            r = r + rng.normal(0.0, cfg.range_noise_m, len(r))
        points.append(origin + d[good] * r[good, None])
        empty.append(d[~hit])
    return Scan(origin, np.concatenate(points), np.concatenate(empty), cfg.max_range_m)
