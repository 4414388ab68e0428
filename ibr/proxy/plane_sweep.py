"""Plane-sweep multi-view stereo on the GPU (Collins 1996; NCC matching as in Gallup et al.
2007), the dense per-view depth that pycolmap's CUDA-only PatchMatch would give, computed with
the GL path every machine has (`ibr/shaders/plane_sweep.glsl`).

For a reference photo and its neighbouring photos (nearest centres and axes):
1. sweep D planes parallel to the reference image plane, uniform in inverse depth between the
   near and far depth; each plane induces a homography from the reference into a neighbour;
2. per pixel, the normalised cross-correlation (NCC) of a (2r+1)^2 window of the reference with
   its plane-warped image in each neighbour, averaged over the best-matching neighbours (so a
   neighbour that does not see the point does not veto it), scores the plane;
3. the best plane's depth is refined by a parabola through its neighbours' scores;
4. the depth maps of all views are then filtered for consistency: a pixel's depth is kept when
   its score is high enough and its 3-D point, projected into enough other views, lands at the
   depth those views estimated (relative difference below a tolerance).

Depths are camera-z in metres, 0 where rejected.
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from ibr.gl import load_program, shared_context
from ibr.scene import Scene
from ibr.source_views import SourceViews, pixel_from_world
from ibr.proxy.triangulation import neighbour_pairs


@dataclass(frozen=True)
class PlaneSweepConfig:
    """Settings of the plane sweep."""

    depth_range: tuple[float, float] = (0.5, 10.0)
    """Nearest and farthest plane depth (metres, camera-z of the reference)."""
    planes: int = 96
    """Number of planes swept."""
    radius: int = 2
    """NCC window half-size (pixels): windows are (2 radius + 1)^2."""
    neighbours: int = 4
    """Neighbouring photos matched per reference (at most 4)."""
    best_of: int = 2
    """A plane's score is the mean NCC of this many best-matching neighbours (occlusion-robust)."""
    min_variance: float = 1e-4
    """Smallest intensity variance (luma in [0, 1]) of a window that is matched at all."""
    min_score: float = 0.5
    """Smallest mean NCC of a kept depth."""
    consistency_tolerance: float = 0.01
    """Relative depth difference under which two views agree on a point."""
    min_consistent: int = 1
    """Other views that must agree for a depth to be kept."""


def view_neighbours(scene: Scene, k: int) -> list[list[int]]:
    """For each view, up to 4 neighbouring views (the pairs `neighbour_pairs` would match)."""
    pairs = neighbour_pairs(scene.cameras, k)
    out = [[] for _ in range(len(scene))]
    for i, j in pairs:
        out[i].append(int(j))
        out[j].append(int(i))
    return [nb[:4] for nb in out]


class PlaneSweep:
    """Per-view depth maps of a scene's photos by GPU plane sweeping."""

    def __init__(self, scene: Scene, config: PlaneSweepConfig | None = None,
                 ctx: moderngl.Context | None = None):
        self.cfg = config or PlaneSweepConfig()
        self.ctx = ctx or shared_context()
        self.scene = scene
        self.sources = SourceViews(self.ctx, scene.cameras, np.stack([v.image for v in scene.views]))
        self.prog = load_program(self.ctx, "plane_sweep", {"PLANES": self.cfg.planes, "RADIUS": self.cfg.radius,
                                                           "MIN_VARIANCE": f"{self.cfg.min_variance:.8f}",
                                                           "BEST_OF": self.cfg.best_of})
        self.vao = self.ctx.vertex_array(self.prog, [])
        W, H = self.sources.size
        self.fbo = self.ctx.framebuffer([self.ctx.texture((W, H), 4, dtype="f4")])
        self.neighbours = view_neighbours(scene, self.cfg.neighbours)

    def sweep(self, ref: int) -> tuple[np.ndarray, np.ndarray]:
        """Best depth (H, W) float32 metres and its mean NCC score (H, W) of view `ref`."""
        cams = self.scene.cameras
        nbs = self.neighbours[ref][: self.cfg.neighbours]
        mats = np.zeros((4, 4, 4))
        for n, j in enumerate(nbs):
            mats[n] = pixel_from_world(cams[j]) @ cams[ref].world_from_cam
        prog = self.prog
        self.sources.bind(prog)
        prog["u_reference"] = ref
        prog["u_size"] = tuple(float(x) for x in self.sources.size)
        prog["u_n_neighbours"] = len(nbs)
        prog["u_neighbours"] = tuple((nbs + [0, 0, 0, 0])[:4])
        prog["u_neighbour_from_ref"].write(mats.transpose(0, 2, 1).astype("f4").tobytes())
        prog["u_K_inv"].write(np.linalg.inv(cams[ref].K).T.astype("f4").tobytes())
        near, far = self.cfg.depth_range
        prog["u_inv_depth_near"], prog["u_inv_depth_far"] = 1.0 / near, 1.0 / far
        self.fbo.use()
        self.fbo.viewport = (0, 0, *self.sources.size)
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.vao.render(moderngl.TRIANGLES, vertices=3)
        W, H = self.sources.size
        out = np.frombuffer(self.fbo.read(components=4, dtype="f4"), "f4").reshape(H, W, 4)
        return out[..., 0].copy(), out[..., 1].copy()

    def depth_maps(self, views: list[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Raw depths and scores (N, H, W) of the given views (all by default)."""
        views = range(len(self.scene)) if views is None else views
        res = [self.sweep(i) for i in views]
        return np.stack([r[0] for r in res]), np.stack([r[1] for r in res])

    def release(self) -> None:
        self.ctx.detect_framebuffer(0).use()
        for obj in (self.sources, self.vao, self.fbo):
            obj.release()


def consistency_filter(scene: Scene, depths: np.ndarray, scores: np.ndarray,
                       cfg: PlaneSweepConfig) -> np.ndarray:
    """Depth maps (N, H, W) with the inconsistent or low-score pixels set to 0 (see module)."""
    cams = scene.cameras
    N, H, W = depths.shape
    grid = cams[0].pixel_grid()
    out = np.zeros_like(depths)
    for i in range(N):  # a loop over the views; all pixels at once
        P = cams[i].unproject(grid, depths[i].ravel())
        agree = np.zeros(H * W, int)
        for j in range(N):
            if j == i:
                continue
            uv, z = cams[j].project(P)
            ij = np.floor(np.nan_to_num(uv, nan=-1.0) + 0.5).astype(int)
            inside = (z > 0) & (ij[:, 0] >= 0) & (ij[:, 0] < W) & (ij[:, 1] >= 0) & (ij[:, 1] < H)
            dj = np.zeros(H * W)
            dj[inside] = depths[j][ij[inside, 1], ij[inside, 0]]
            agree += inside & (np.abs(dj - z) < cfg.consistency_tolerance * np.maximum(z, 1e-9))
        keep = (agree >= cfg.min_consistent) & (scores[i].ravel() >= cfg.min_score)
        out[i] = np.where(keep, depths[i].ravel(), 0.0).reshape(H, W)
    return out
