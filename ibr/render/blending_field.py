"""The camera blending field of unstructured lumigraph rendering (Buehler, Bosse, McMillan,
Gortler & Cohen, SIGGRAPH 2001, Sec. 4-5): for a surface point P seen from the virtual
centre c, each source camera i (centre c_i) gets a penalty

    angle_i = the angle at P between the rays to c_i and to c (radians),
    res_i   = max(0, (|P - c_i| - |P - c|) / |P - c|)   (the source sees P at lower resolution),
    fov_i   = infinite when P does not project inside source i's image or is hidden from it,
    penalty_i = alpha * angle_i + beta * res_i (+ fov_i),

and the k best sources the weights w_i = (1 - p_i / thresh) / (p_i + eps), normalised, with
thresh the (k+1)-th smallest penalty (`k_nearest_weights`).

Sec. 5 (real time): the field is smooth away from depth edges, so it is evaluated only at
a sparse set of image-plane samples -- the projections of the proxy's visible vertices, the
epipoles (the source centres projected into the virtual view) and a regular grid -- which are
triangulated (Delaunay) and rasterised, the weights interpolated linearly across each
triangle. `field_samples` picks the samples, `blending_field` evaluates the weights there,
`triangle_weights` packs each triangle's sources and vertex weights for the shader
(`ibr/shaders/ulr.glsl`, PASS 2), which interpolates them per pixel, drops sources that fail
the per-pixel visibility test and renormalises.

Frames: world metres; image pixels (u right, v down, pixel centres at integers).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import Delaunay

from ibr.camera import Camera
from ibr.source_views import project_with


def angle_penalty(P: np.ndarray, eye: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """(M, N) angle (radians) at surface points P (M, 3) between the rays to the virtual
    centre `eye` (3,) and to each source centre (N, 3)."""
    a = eye - P
    b = centres[None] - P[:, None]
    cos = np.einsum("mj,mnj->mn", a, b) / (np.linalg.norm(a, axis=1)[:, None] * np.linalg.norm(b, axis=2))
    return np.arccos(np.clip(cos, -1.0, 1.0))


def resolution_penalty(P: np.ndarray, eye: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """(M, N) relative extra distance max(0, (|P - c_i| - |P - c|) / |P - c|)."""
    d_eye = np.linalg.norm(eye - P, axis=1)[:, None]
    return np.maximum(0.0, (np.linalg.norm(centres[None] - P[:, None], axis=2) - d_eye) / d_eye)


def k_nearest_weights(penalty: np.ndarray, k: int, eps: float) -> np.ndarray:
    """(M, N) normalised blending weights from penalties (M, N) (inf = not a candidate):
    the k smallest get (1 - p / thresh) / (p + eps), thresh = the (k+1)-th smallest (or
    1.5 x the largest finite + 1e-3 when there are at most k candidates); the rest get 0."""
    M, N = penalty.shape
    order = np.argsort(penalty, axis=1)
    p_sorted = np.take_along_axis(penalty, order, axis=1)
    n_valid = np.isfinite(p_sorted).sum(axis=1)
    n = np.minimum(n_valid, k)
    last = p_sorted[np.arange(M), np.maximum(n - 1, 0)]
    kth = p_sorted[:, k] if N > k else np.full(M, np.inf)
    thresh = np.where(n_valid > k, kth, last * 1.5 + 1e-3)
    rank = np.empty_like(order)
    np.put_along_axis(rank, order, np.arange(N)[None].repeat(M, 0), axis=1)
    with np.errstate(invalid="ignore"):
        w = (1.0 - penalty / thresh[:, None]) / (penalty + eps)
    w = np.where((rank < n[:, None]) & np.isfinite(penalty), w, 0.0)
    s = w.sum(axis=1, keepdims=True)
    return np.divide(w, s, out=np.zeros_like(w), where=s > 0)


def source_candidates(P: np.ndarray, check_visibility: np.ndarray, matrices: np.ndarray,
                      depths: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Field-of-view and visibility tests of points P (M, 3) in N sources (matrices (N, 4, 4),
    depth maps (N, H, W)). Returns candidate (M, N) bool and pixels (M, N, 2)."""
    N, H, W = depths.shape
    uv = np.empty((len(P), N, 2))
    ok = np.zeros((len(P), N), bool)
    for i in range(N):  # loop over the few sources; every point at once
        s, z = project_with(matrices[i], P)
        inside = (z > 0) & np.all(s >= -0.5, axis=1) & (s[:, 0] < W - 0.5) & (s[:, 1] < H - 0.5)
        ij = np.clip(np.floor(np.nan_to_num(s) + 0.5).astype(int), 0, [W - 1, H - 1])
        d = depths[i, ij[:, 1], ij[:, 0]]
        visible = (d > 0) & (z <= d * (1.0 + tolerance))
        ok[:, i] = inside & (visible | ~check_visibility)
        uv[:, i] = s
    return ok, uv


def blending_field(P: np.ndarray, check_visibility: np.ndarray, eye: np.ndarray, matrices: np.ndarray,
                   centres: np.ndarray, depths: np.ndarray, k: int, alpha: float, beta: float,
                   eps: float, tolerance: float) -> np.ndarray:
    """(M, N) camera blending weights of surface points P (M, 3) seen from `eye` (3,): the
    penalties above, infinite outside a source's image or (where check_visibility) behind its
    proxy depth map (relative slack `tolerance`), then `k_nearest_weights`."""
    ok, _ = source_candidates(P, check_visibility, matrices, depths, tolerance)
    pen = alpha * angle_penalty(P, eye, centres) + beta * resolution_penalty(P, eye, centres)
    return k_nearest_weights(np.where(ok, pen, np.inf), k, eps)


@dataclass
class FieldSamples:
    """Image-plane samples of the blending field. uv (S, 2) pixels; P (S, 3) world surface
    points; has_surface (S,) bool (false: no proxy there, the sample gets no weights);
    on_proxy (S,) bool: P is on the rasterised proxy (true) or interpolated into a hole."""

    uv: np.ndarray
    P: np.ndarray
    has_surface: np.ndarray
    on_proxy: np.ndarray


def field_samples(camera: Camera, depth: np.ndarray, vertices: np.ndarray, centres: np.ndarray,
                  grid_cells: int, vertex_cell_px: float, tolerance: float) -> FieldSamples:
    """The samples of Sec. 5 for a view: a regular grid with `grid_cells` cells across the
    image's longer side (its outer ring on the image border, so the triangles cover every
    pixel), the proxy `vertices` (V, 3) that project inside the image and are visible (their
    camera-z within `tolerance` (relative) of the proxy `depth` (H, W), camera-z, negative =
    hole-filled, 0 = none), at most one per vertex_cell_px cell, and the epipoles of the
    source `centres` (N, 3) that lie inside the image. Pixel-sized constants are fractions
    of the image, so they do not depend on the scene."""
    H, W = depth.shape
    step = max(W, H) / grid_cells
    gu = np.linspace(-0.5, W - 0.5, max(2, int(np.ceil(W / step)) + 1))
    gv = np.linspace(-0.5, H - 0.5, max(2, int(np.ceil(H / step)) + 1))
    grid = np.stack(np.meshgrid(gu, gv), axis=-1).reshape(-1, 2)
    uv_v, z_v = camera.project(vertices)
    pix = np.floor(uv_v + 0.5).astype(np.int64)
    inside = (z_v > 0) & np.all(pix >= 0, axis=1) & (pix[:, 0] < W) & (pix[:, 1] < H)
    pix, uv_v, z_v, verts = pix[inside], uv_v[inside], z_v[inside], vertices[inside]
    d = depth[pix[:, 1], pix[:, 0]]
    seen = (d > 0) & (np.abs(z_v - d) <= tolerance * z_v)
    cell = np.floor(uv_v[seen] / vertex_cell_px).astype(np.int64)
    _, first = np.unique(cell[:, 0] * (W + 1) + cell[:, 1], return_index=True)
    uv_v, verts = uv_v[seen][first], verts[seen][first]
    uv_e, z_e = camera.project(centres)
    epi = (z_e > 0) & np.all(uv_e >= 0, axis=1) & (uv_e[:, 0] <= W - 1) & (uv_e[:, 1] <= H - 1)
    uv_px = np.concatenate([grid, uv_e[epi]])
    ij = np.clip(np.floor(uv_px + 0.5).astype(np.int64), 0, [W - 1, H - 1])
    z = depth[ij[:, 1], ij[:, 0]]
    P_px = camera.unproject(uv_px, np.abs(z))
    return FieldSamples(np.concatenate([uv_px, uv_v]), np.concatenate([P_px, verts]),
                        np.r_[z != 0, np.ones(len(verts), bool)], np.r_[z > 0, np.ones(len(verts), bool)])


def triangulate(uv: np.ndarray) -> np.ndarray:
    """(T, 3) int Delaunay triangles of image-plane samples uv (S, 2) (duplicates ignored)."""
    return Delaunay(uv).simplices.astype(np.int64)


def triangle_weights(triangles: np.ndarray, weights: np.ndarray, n_slots: int) -> np.ndarray:
    """(T, n_slots, 4) float32 per triangle: (weight at vertex 0, 1, 2, source index) of the
    sources with weight at one of its vertices, largest first, padded with source -1; a
    triangle with more sources keeps the n_slots strongest (the others are the small
    weights of sources leaving the k best)."""
    Wt = weights[triangles]                                 # (T, 3, N)
    strength = Wt.max(axis=1)                               # (T, N)
    m = min(n_slots, weights.shape[1])
    order = np.argsort(-strength, axis=1, kind="stable")[:, :m]            # (T, m)
    w = np.take_along_axis(Wt, order[:, None, :], axis=2)   # (T, 3, n_slots)
    active = np.take_along_axis(strength, order, axis=1) > 0
    out = np.zeros((len(triangles), n_slots, 4), np.float32)
    out[:, m:, 3] = -1
    out[:, :m, :3] = np.transpose(w, (0, 2, 1))
    out[:, :m, 3] = np.where(active, order, -1)
    return out
