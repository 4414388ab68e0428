"""Unstructured lumigraph rendering (Buehler, Bosse, McMillan, Gortler & Cohen, SIGGRAPH 2001),
the view synthesis of Foster, Wang & Grupen (section V-C) over a proxy mesh.

For every pixel of the virtual camera C (centre c):

1. *Proxy.* Rasterise the proxy mesh from C; the pixel's camera-z gives its surface point P.
   Holes in the proxy are filled by interpolating the depths of nearby pixels (push-pull), as
   Foster et al. do for their rasterised point cloud; those pixels are reported as not covered.
2. *Candidate sources.* Source camera i (centre c_i) is a candidate if P projects inside its
   image (the field-of-view penalty is infinite otherwise) and P is visible from it: its
   camera-z is not behind the source's proxy depth map at that pixel (a shadow-map test), so
   occluded sources do not ghost.
3. *Penalties.* angle penalty = the angle at P between the rays to c_i and to c (radians);
   resolution penalty = max(0, (|P - c_i| - |P - c|) / |P - c|) (a source farther from the
   surface than the virtual camera sees it at lower resolution); penalty = alpha * angle +
   beta * resolution.
4. *k-nearest blending.* Keep the k + 1 smallest penalties; with thresh = the (k + 1)-th, the k
   best get weights w_i = (1 - p_i / thresh) / (p_i + eps), normalised, which fall smoothly to
   0 as a source leaves the k best (continuity) and go to 1 when a source's ray coincides with
   the desired ray (epipole consistency).
5. The pixel's colour is the weighted mean of the sources' colours at P's projections.

Steps 2-5 run in a fragment shader over a texture array (`ibr/shaders/ulr.glsl`);
`ulr_blend_numpy` is the same blend in numpy, the reference for tests and benchmarks.
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np
import trimesh

from ibr.camera import Camera
from ibr.render.depth_maps import render_depth_maps
from ibr.gl import load_program, shared_context
from ibr.render.hole_filling import push_pull
from ibr.scene import Scene
from ibr.source_views import SourceViews, project_with

MAX_K = 8


@dataclass(frozen=True)
class UlrConfig:
    """Settings of the unstructured lumigraph renderer."""

    k: int = 4
    """Number of sources blended per pixel (1..8)."""
    alpha: float = 1.0
    """Weight of the angle penalty (per radian)."""
    beta: float = 0.1
    """Weight of the relative resolution penalty."""
    visibility_tolerance: float = 0.02
    """Relative camera-z slack of the shadow-map visibility test (fraction of the depth)."""
    eps: float = 1e-4
    """Regulariser of the weights 1/p (radians)."""
    fill_holes: bool = True
    """Interpolate proxy depth into holes (push-pull) and fill colours no source covers."""
    near: float = 0.05
    """Near clipping distance of the proxy pass (metres)."""
    far: float = 1000.0
    """Far clipping distance of the proxy pass (metres)."""


@dataclass
class UlrFrame:
    """One rendered view. image (H, W, 3) uint8; covered (H, W) bool: pixels on the proxy
    blended from at least one visible source; depth (H, W) float32 virtual camera-z of the
    proxy (0 = hole); filled (H, W) bool: the pixels not covered, whose colour comes from hole
    filling (sources blended over interpolated depth, or push-pull of neighbouring colours)."""

    image: np.ndarray
    covered: np.ndarray
    depth: np.ndarray
    filled: np.ndarray


# --- the blend in numpy (reference) --------------------------------------------------------
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


def bilinear(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear samples (M, 3) float of image (H, W, 3) at pixels uv (M, 2), clamped at the edges."""
    H, W = image.shape[:2]
    u = np.clip(uv[:, 0], 0, W - 1)
    v = np.clip(uv[:, 1], 0, H - 1)
    u0, v0 = np.minimum(np.floor(u).astype(int), W - 2), np.minimum(np.floor(v).astype(int), H - 2)
    fu, fv = (u - u0)[:, None], (v - v0)[:, None]
    im = image.astype(np.float64)
    return ((1 - fu) * (1 - fv) * im[v0, u0] + fu * (1 - fv) * im[v0, u0 + 1]
            + (1 - fu) * fv * im[v0 + 1, u0] + fu * fv * im[v0 + 1, u0 + 1])


def source_candidates(P: np.ndarray, check_visibility: np.ndarray, matrices: np.ndarray,
                      depths: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Field-of-view and visibility tests of points P (M, 3) in N sources (matrices (N, 4, 4),
    depth maps (N, H, W)). Returns candidate (M, N) bool and pixels (M, N, 2)."""
    N, H, W = depths.shape
    uv = np.empty((len(P), N, 2))
    ok = np.zeros((len(P), N), bool)
    for i in range(N):  # loop over the few sources; every pixel at once
        s, z = project_with(matrices[i], P)
        inside = (z > 0) & np.all(s >= -0.5, axis=1) & (s[:, 0] < W - 0.5) & (s[:, 1] < H - 0.5)
        ij = np.clip(np.floor(np.nan_to_num(s) + 0.5).astype(int), 0, [W - 1, H - 1])
        d = depths[i, ij[:, 1], ij[:, 0]]
        visible = (d > 0) & (z <= d * (1.0 + tolerance))
        ok[:, i] = inside & (visible | ~check_visibility)
        uv[:, i] = s
    return ok, uv


def ulr_blend_numpy(P: np.ndarray, check_visibility: np.ndarray, eye: np.ndarray,
                    matrices: np.ndarray, centres: np.ndarray, images: np.ndarray,
                    depths: np.ndarray, cfg: UlrConfig) -> tuple[np.ndarray, np.ndarray]:
    """ULR colours (M, 3) float in [0, 255] and validity (M,) of surface points P (M, 3) (world)
    seen from `eye`; check_visibility (M,) bool is false for hole-filled points."""
    ok, uv = source_candidates(P, check_visibility, matrices, depths, cfg.visibility_tolerance)
    pen = cfg.alpha * angle_penalty(P, eye, centres) + cfg.beta * resolution_penalty(P, eye, centres)
    w = k_nearest_weights(np.where(ok, pen, np.inf), cfg.k, cfg.eps)
    rgb = np.zeros((len(P), 3))
    for i in range(len(centres)):
        sel = w[:, i] > 0
        rgb[sel] += w[sel, i, None] * bilinear(images[i], uv[sel, i])
    return rgb, w.sum(axis=1) > 0


# --- the GL renderer -------------------------------------------------------------------------
def fill_depth_holes(depth: np.ndarray) -> np.ndarray:
    """Virtual-view camera-z (H, W) with holes (0) filled by push-pull and marked negative."""
    known = depth > 0
    if known.all() or not known.any():
        return depth
    filled = push_pull(depth, known)
    return np.where(known, depth, -np.abs(filled)).astype(np.float32)


class UlrRenderer:
    """Unstructured lumigraph renderer of a scene's photos over a proxy mesh.

    scene: the posed source photos (all one size); proxy_mesh: the geometric proxy (world
    metres); ctx: GL context (the shared one by default); k: sources blended per pixel."""

    def __init__(self, scene: Scene, proxy_mesh: trimesh.Trimesh, ctx: moderngl.Context | None = None,
                 k: int = 4, config: UlrConfig | None = None, source_depths: np.ndarray | None = None):
        self.cfg = config or UlrConfig(k=k)
        if not 1 <= self.cfg.k <= MAX_K:
            raise ValueError(f"k must be in 1..{MAX_K}, got {self.cfg.k}")
        self.ctx = ctx or shared_context()
        self.scene = scene
        cams = scene.cameras
        self.source_depths = (render_depth_maps(proxy_mesh, cams, self.ctx) if source_depths is None
                              else source_depths)
        self.sources = SourceViews(self.ctx, cams, np.stack([v.image for v in scene.views]),
                                   self.source_depths)
        self.depth_prog = load_program(self.ctx, "ulr", {"PASS": 0, "K": self.cfg.k})
        self.blend_prog = load_program(self.ctx, "ulr", {"PASS": 1, "K": self.cfg.k,
                                                         "EPS": f"{self.cfg.eps:.8f}"})
        vertices = np.asarray(proxy_mesh.vertices, "f4")
        self.vbo = self.ctx.buffer(vertices.tobytes())
        self.ibo = self.ctx.buffer(np.asarray(proxy_mesh.faces, "i4").tobytes())
        self.depth_vao = self.ctx.vertex_array(self.depth_prog, [(self.vbo, "3f4", "in_position")], self.ibo)
        self.blend_vao = self.ctx.vertex_array(self.blend_prog, [])
        self._fbos: dict = {}

    def _targets(self, W: int, H: int):
        if (W, H) not in self._fbos:
            depth = self.ctx.framebuffer([self.ctx.texture((W, H), 1, dtype="f4")],
                                         self.ctx.depth_renderbuffer((W, H)))
            color = self.ctx.framebuffer([self.ctx.texture((W, H), 4, dtype="f1")])
            view_depth = self.ctx.texture((W, H), 1, dtype="f4")
            view_depth.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._fbos[W, H] = (depth, color, view_depth)
        return self._fbos[W, H]

    def proxy_depth(self, camera: Camera) -> np.ndarray:
        """(H, W) float32 camera-z of the proxy seen by `camera` (0 = no proxy)."""
        fbo, _, _ = self._targets(camera.width, camera.height)
        fbo.use()
        fbo.viewport = (0, 0, camera.width, camera.height)
        fbo.clear(0.0, 0.0, 0.0, 0.0, 1.0)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)
        self.depth_prog["u_clip_from_world"].write(
            camera.gl_clip_from_world(self.cfg.near, self.cfg.far).T.astype("f4").tobytes())
        self.depth_vao.render(moderngl.TRIANGLES)
        data = fbo.read(components=1, attachment=0, dtype="f4")
        return np.frombuffer(data, "f4").reshape(camera.height, camera.width).copy()

    def blend(self, camera: Camera, view_depth: np.ndarray, only_source: int = -1) -> np.ndarray:
        """(H, W, 4) uint8 blended colours (alpha 255 where some source contributed) of the
        surface points given by `view_depth` (camera-z; negative = hole-filled)."""
        _, fbo, tex = self._targets(camera.width, camera.height)
        tex.write(np.ascontiguousarray(view_depth, "f4").tobytes())
        fbo.use()
        fbo.viewport = (0, 0, camera.width, camera.height)
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        self.ctx.disable(moderngl.DEPTH_TEST)
        prog = self.blend_prog
        self.sources.bind(prog)
        tex.use(2)
        prog["u_view_depth"] = 2
        prog["u_world_from_cam"].write(camera.world_from_cam.T.astype("f4").tobytes())
        prog["u_K_inv"].write(np.linalg.inv(camera.K).T.astype("f4").tobytes())
        prog["u_eye"] = tuple(camera.center)
        prog["u_only_source"] = only_source
        prog["u_alpha"], prog["u_beta"] = self.cfg.alpha, self.cfg.beta
        prog["u_visibility_tolerance"] = self.cfg.visibility_tolerance
        self.blend_vao.render(moderngl.TRIANGLES, vertices=3)
        return np.frombuffer(fbo.read(components=4), np.uint8).reshape(camera.height, camera.width, 4).copy()

    def render_frame(self, camera: Camera, only_source: int = -1) -> UlrFrame:
        """Render `camera`; see `UlrFrame`."""
        depth = self.proxy_depth(camera)
        view_depth = fill_depth_holes(depth) if self.cfg.fill_holes else depth
        rgba = self.blend(camera, view_depth, only_source)
        blended = rgba[..., 3] > 127
        covered = blended & (depth > 0)
        image = rgba[..., :3]
        if self.cfg.fill_holes and blended.any() and not blended.all():
            image = np.clip(np.round(push_pull(image.astype(np.float64), blended)), 0, 255).astype(np.uint8)
        return UlrFrame(image, covered, depth, ~covered)

    def render(self, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
        """(image (H, W, 3) uint8, covered (H, W) bool) of the virtual `camera`."""
        frame = self.render_frame(camera)
        return frame.image, frame.covered

    def release(self) -> None:
        """Free the GPU objects (the default framebuffer is bound first: deleting the bound
        one leaves moderngl pointing at a dead framebuffer)."""
        self.ctx.detect_framebuffer(0).use()
        self.sources.release()
        for obj in (self.vbo, self.ibo, self.depth_vao, self.blend_vao):
            obj.release()
        for fbos in self._fbos.values():
            for f in fbos:
                f.release()
