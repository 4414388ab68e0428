"""How far the photo-textured proxy can be trusted, face by face (the weights of the robust
rendered-view likelihood, `localization.render_likelihood`).

A proxy from SfM points and Poisson reconstruction is right where points were triangulated
and guesses elsewhere: it bridges gaps with smooth blobs, and a photo projected onto a blob
paints a plausible but wrong image. Two tests, both per face:

- photo-consistency (PMVS, Furukawa & Ponce 2010): a small patch on the face's plane,
  projected into the photo that sees the face best and into every other photo that sees it,
  should look the same in all of them if the face lies on the true surface. Its score is the
  median zero-mean NCC over the other photos (a patch flat in both photos scores 0.5: they
  cannot tell; flat in one and textured in the other, 0: they disagree; a face seen by fewer
  than two photos scores 0: nothing confirms it).
- geometric support: the distance from the face to the nearest triangulated point, in
  pixels of the best photo at the work width. A photo-consistency test alone is fooled by
  small baselines and repeated texture; a face far from every point is a guess.

trust = consistency x support, in [0, 1]. Distances are in pixels and patch statistics in
intensity units, so no threshold depends on the scene's size.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import map_coordinates
from scipy.spatial import cKDTree

from ibr.camera import Camera
from localization.render_likelihood import comparison_camera, luminance


@dataclass(frozen=True)
class TrustConfig:
    """Settings of `face_trust`."""

    work_width: int = 384
    """Width (pixels) the photos are compared at, and the unit of `support_px`."""
    half_patch: int = 3
    """The patch is (2 half_patch + 1)^2 samples, one pixel of the best photo apart."""
    min_std: float = 0.02
    """A patch whose luminance std is below this (intensity units, about sensor noise) is
    flat: NCC cannot judge two flat patches (0.5); a flat and a textured one disagree (0)."""
    support_px: tuple[float, float] = (2.0, 8.0)
    """Support is 1 within the first distance (pixels at the work width) of a triangulated
    point and falls linearly to 0 at the second. Measured on proxies of synthetic scenes with
    ground truth (office and courtyard, seed 1): faces within 8 px of a point are off the
    true surface by more than 5 % of their depth in at most 1 % of cases, 8-16 px in up to
    2 %, 16-32 px in 3-28 % (and by more than 2 % in 6-19 % at 8-16 px)."""


def face_patches(centroids: np.ndarray, normals: np.ndarray, camera: Camera, half: int) -> np.ndarray:
    """(F, S, 3) world points of a square patch on each face's plane around its centroid,
    one pixel of `camera` apart at the face's depth (S = (2 half + 1)^2)."""
    _, z = camera.project(centroids)
    step = np.maximum(z, 1e-6) / camera.K[0, 0]
    a = np.cross(normals, [0.0, 0.0, 1.0])
    a[np.linalg.norm(a, axis=1) < 1e-6] = [1.0, 0.0, 0.0]
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(normals, a)
    g = np.arange(-half, half + 1, dtype=float)
    gu, gv = [x.ravel() for x in np.meshgrid(g, g)]
    return (centroids[:, None] + step[:, None, None] * (gu[None, :, None] * a[:, None] + gv[None, :, None] * b[:, None]))


def sample(lum: np.ndarray, camera: Camera, points: np.ndarray) -> np.ndarray:
    """Bilinear luminance of `lum` (the photo at camera's size) at world points (..., 3);
    NaN outside the image or behind the camera."""
    uv, z = camera.project(points.reshape(-1, 3))
    uv = np.nan_to_num(uv, nan=-1.0, posinf=-1.0, neginf=-1.0)
    out = map_coordinates(lum, [uv[:, 1], uv[:, 0]], order=1, mode="constant", cval=np.nan)
    out[(z <= 0) | (uv[:, 0] < 0) | (uv[:, 1] < 0) | (uv[:, 0] > lum.shape[1] - 1) | (uv[:, 1] > lum.shape[0] - 1)] = np.nan
    return out.reshape(points.shape[:-1])


def patch_agreement(ref: np.ndarray, other: np.ndarray, min_std: float) -> np.ndarray:
    """(F,) zero-mean NCC of patches (F, S) in two photos; 0.5 where both are flat (std <
    min_std: NCC cannot tell), 0 where only one is (one photo sees texture where the other
    sees none, e.g. a face bulging past a roofline is sky in one photo and wall in another),
    NaN where either patch left its image."""
    a = ref - ref.mean(axis=1, keepdims=True)
    b = other - other.mean(axis=1, keepdims=True)
    sa, sb = a.std(axis=1), b.std(axis=1)
    ncc = (a * b).mean(axis=1) / np.maximum(sa * sb, 1e-12)
    flat_a, flat_b = sa < min_std, sb < min_std
    return np.where(flat_a & flat_b, 0.5, np.where(flat_a | flat_b, 0.0, ncc))


def photo_consistency(centroids: np.ndarray, normals: np.ndarray, visibility: np.ndarray,
                      cameras: list[Camera], lums: list[np.ndarray], config: TrustConfig) -> np.ndarray:
    """(F,) PMVS-style consistency in [0, 1]: the median NCC of each face's patch between its
    best photo (highest visibility score) and every other photo that sees it; 0 when fewer
    than two photos see it. visibility: (F, N) scores, 0 = unseen; lums: photos' luminance
    at the cameras' sizes."""
    F, N = visibility.shape
    best = np.argmax(visibility, axis=1)
    S = (2 * config.half_patch + 1) ** 2
    patches, ref = np.zeros((F, S, 3)), np.full((F, S), np.nan)
    for m in np.unique(best):
        sel = np.flatnonzero(best == m)
        patches[sel] = face_patches(centroids[sel], normals[sel], cameras[m], config.half_patch)
        ref[sel] = sample(lums[m], cameras[m], patches[sel])
    agree = np.full((F, N), np.nan)
    for n in range(N):
        faces = np.flatnonzero((visibility[:, n] > 0) & (best != n))
        if len(faces):
            agree[faces, n] = patch_agreement(ref[faces], sample(lums[n], cameras[n], patches[faces]),
                                              config.min_std)
    seen_twice = (visibility > 0).sum(axis=1) >= 2
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows: faces seen once
        med = np.nanmedian(agree, axis=1)
    return np.where(seen_twice & np.isfinite(med), np.clip(med, 0.0, 1.0), 0.0)


def geometric_support(centroids: np.ndarray, visibility: np.ndarray, cameras: list[Camera],
                      points: np.ndarray, config: TrustConfig) -> np.ndarray:
    """(F,) support in [0, 1]: 1 within `support_px[0]` pixels (best photo, work width) of a
    triangulated point (points (P, 3) world), falling linearly to 0 at `support_px[1]`."""
    if len(points) == 0:
        return np.zeros(len(centroids))
    dist, _ = cKDTree(points).query(centroids)
    best = np.argmax(visibility, axis=1)
    focal = np.array([c.K[0, 0] for c in cameras])
    centres = np.array([c.center for c in cameras])
    depth = np.linalg.norm(centres[best] - centroids, axis=1)
    px = dist * focal[best] / np.maximum(depth, 1e-9)
    lo, hi = config.support_px
    return np.clip((hi - px) / (hi - lo), 0.0, 1.0)


def face_trust(centroids: np.ndarray, normals: np.ndarray, visibility: np.ndarray, cameras: list[Camera],
               images: list[np.ndarray], points: np.ndarray, config: TrustConfig = TrustConfig()) -> np.ndarray:
    """(F,) trust in [0, 1] of each face: `photo_consistency` x `geometric_support`, with the
    photos compared at `config.work_width`. cameras: the photos' cameras (any size);
    visibility (F, N): `photo_texture.face_visibility` scores."""
    small = [comparison_camera(c, config.work_width) for c in cameras]
    lums = [luminance(im, (c.width, c.height)) for c, im in zip(small, images)]
    consistency = photo_consistency(centroids, normals, visibility, small, lums, config)
    return consistency * geometric_support(centroids, visibility, small, points, config)
