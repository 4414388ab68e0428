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

Two ways to get the weights (`UlrConfig.blending`): "pixel" evaluates steps 2-4 at every
pixel (the quality reference); "field" (the default, Buehler et al. Sec. 5) evaluates them
at a sparse set of samples -- the visible proxy vertices, the epipoles and a coarse grid --
triangulates them and lets the rasteriser interpolate the weights (`blending_field`); per
pixel only the sources the field names are looked up, with the visibility test, and
renormalised (a pixel none of them sees is left to hole filling, as in Buehler et al.'s
real-time renderer, which has no per-pixel pass). Hole filling (proxy depth and uncovered colours) runs on the GPU
(`hole_filling.GLPushPull`).
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np
import trimesh

from ibr.camera import Camera
from ibr.render.depth_maps import render_depth_maps
from ibr.gl import load_program, shared_context
from ibr.render.blending_field import (angle_penalty, blending_field, field_samples, k_nearest_weights,
                                      resolution_penalty, source_candidates, triangle_weights, triangulate)
from ibr.render.hole_filling import GLPushPull, push_pull
from ibr.scene import Scene
from ibr.source_views import SourceViews

MAX_K = 8
BLENDINGS = ("field", "pixel")

__all__ = ["UlrConfig", "UlrFrame", "UlrRenderer", "angle_penalty", "bilinear", "fill_depth_holes",
           "k_nearest_weights", "resolution_penalty", "source_candidates", "ulr_blend_numpy"]


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
    blending: str = "field"
    """"field": the blending field at sparse samples, rasterised (fast); "pixel": every pixel."""
    field_grid_cells: int = 32
    """Field grid: cells across the image's longer side (a fraction of the image, so the
    same for every scene)."""
    field_vertex_cells: int = 128
    """Proxy vertices kept as field samples: at most one per cell of 1/field_vertex_cells of
    the image's longer side."""

    def __post_init__(self):
        if self.blending not in BLENDINGS:
            raise ValueError(f"blending must be one of {BLENDINGS}, got {self.blending!r}")
        if self.field_grid_cells < 1 or self.field_vertex_cells < 1:
            raise ValueError("field_grid_cells and field_vertex_cells must be >= 1")


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
    metres); ctx: GL context (the shared one by default); k: sources blended per pixel;
    config.blending: "field" (sparse blending field, fast) or "pixel" (every pixel)."""

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
        self.slots = min(3 * self.cfg.k, len(cams))  # sources a field triangle can name
        self.depth_prog = load_program(self.ctx, "ulr", {"PASS": 0, "K": self.cfg.k})
        self.blend_prog = load_program(self.ctx, "ulr", {"PASS": 1, "K": self.cfg.k,
                                                         "EPS": f"{self.cfg.eps:.8f}"})
        self.field_prog = load_program(self.ctx, "ulr", {"PASS": 2, "K": self.cfg.k, "SLOTS": self.slots,
                                                         "EPS": f"{self.cfg.eps:.8f}"})
        self.vertices = np.asarray(proxy_mesh.vertices, np.float64)
        self.vbo = self.ctx.buffer(self.vertices.astype("f4").tobytes())
        self.ibo = self.ctx.buffer(np.asarray(proxy_mesh.faces, "i4").tobytes())
        self.depth_vao = self.ctx.vertex_array(self.depth_prog, [(self.vbo, "3f4", "in_position")], self.ibo)
        self.blend_vao = self.ctx.vertex_array(self.blend_prog, [])
        self._field_bufs: list = []   # [vbo, ssbo, vao] of the last field, reused while large enough
        self._fbos: dict = {}
        self._fillers: dict = {}

    def _targets(self, W: int, H: int):
        if (W, H) not in self._fbos:
            depth = self.ctx.framebuffer([self.ctx.texture((W, H), 1, dtype="f4")],
                                         self.ctx.depth_renderbuffer((W, H)))
            depth.color_attachments[0].filter = (moderngl.NEAREST, moderngl.NEAREST)
            color = self.ctx.framebuffer([self.ctx.texture((W, H), 4, dtype="f1")])
            color.color_attachments[0].filter = (moderngl.NEAREST, moderngl.NEAREST)
            view_depth = self.ctx.texture((W, H), 1, dtype="f4")
            view_depth.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._fbos[W, H] = (depth, color, view_depth)
        return self._fbos[W, H]

    def _filler(self, W: int, H: int, depth: bool) -> GLPushPull:
        if (W, H, depth) not in self._fillers:
            self._fillers[W, H, depth] = GLPushPull(self.ctx, (W, H), depth)
        return self._fillers[W, H, depth]

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

    def _draw(self, camera: Camera, depth_tex: moderngl.Texture, field: np.ndarray | None = None,
              uv: np.ndarray | None = None, only_source: int = -1) -> np.ndarray:
        """Blend into the colour target: the per-pixel pass, or the field pass when `field`
        (T, slots, 4) and the triangles' corner pixels `uv` (3T, 2) are given. Returns the
        (H, W, 4) uint8 read-back (alpha 255 where some source contributed)."""
        _, fbo, _ = self._targets(camera.width, camera.height)
        fbo.use()
        fbo.viewport = (0, 0, camera.width, camera.height)
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        self.ctx.disable(moderngl.DEPTH_TEST)
        prog = self.blend_prog if field is None else self.field_prog
        self.sources.bind(prog)
        depth_tex.use(2)
        prog["u_view_depth"] = 2
        prog["u_world_from_cam"].write(camera.world_from_cam.T.astype("f4").tobytes())
        prog["u_K_inv"].write(np.linalg.inv(camera.K).T.astype("f4").tobytes())
        uniforms = {"u_eye": tuple(camera.center), "u_only_source": only_source, "u_alpha": self.cfg.alpha,
                    "u_beta": self.cfg.beta, "u_visibility_tolerance": self.cfg.visibility_tolerance}
        for name, value in uniforms.items():
            if name in prog:  # the compiler drops the ones a pass does not use
                prog[name] = value
        if field is None:
            self.blend_vao.render(moderngl.TRIANGLES, vertices=3)
        else:
            vao = self._field_vao(uv.astype("f4"), field)
            prog["u_view_size"] = (float(camera.width), float(camera.height))
            vao.render(moderngl.TRIANGLES, vertices=len(uv))
        return np.frombuffer(fbo.read(components=4), np.uint8).reshape(camera.height, camera.width, 4).copy()

    def _field_vao(self, uv: np.ndarray, field: np.ndarray) -> moderngl.VertexArray:
        """Upload the field's triangle corners and weights (buffers grow, never shrink)."""
        if not self._field_bufs or self._field_bufs[0].size < uv.nbytes or self._field_bufs[1].size < field.nbytes:
            for obj in self._field_bufs:
                obj.release()
            vbo = self.ctx.buffer(reserve=max(uv.nbytes, 8) * 2)
            ssbo = self.ctx.buffer(reserve=max(field.nbytes, 16) * 2)
            self._field_bufs = [vbo, ssbo, self.ctx.vertex_array(self.field_prog, [(vbo, "2f4", "in_uv")])]
        vbo, ssbo, vao = self._field_bufs
        vbo.write(uv.tobytes())
        ssbo.write(np.ascontiguousarray(field, "f4").tobytes())
        ssbo.bind_to_storage_buffer(2)
        return vao

    def field(self, camera: Camera, view_depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The blending field of `camera` over its (hole-filled) proxy depth: the triangles'
        corner pixels (3T, 2) and per-triangle (T, slots, 4) weights (`blending_field`)."""
        c = self.cfg
        H, W = view_depth.shape
        samples = field_samples(camera, view_depth, self.vertices, self.sources.centres, c.field_grid_cells,
                                max(W, H) / c.field_vertex_cells, c.visibility_tolerance)
        weights = np.zeros((len(samples.uv), len(self.sources)))
        has = samples.has_surface
        weights[has] = blending_field(samples.P[has], samples.on_proxy[has], camera.center,
                                      self.sources.matrices, self.sources.centres, self.source_depths,
                                      c.k, c.alpha, c.beta, c.eps, c.visibility_tolerance)
        tri = triangulate(samples.uv)
        return samples.uv[tri.ravel()], triangle_weights(tri, weights, self.slots)

    def blend(self, camera: Camera, view_depth: np.ndarray, only_source: int = -1) -> np.ndarray:
        """(H, W, 4) uint8 per-pixel blended colours (alpha 255 where some source contributed)
        of the surface points given by `view_depth` (camera-z; negative = hole-filled)."""
        _, _, tex = self._targets(camera.width, camera.height)
        tex.write(np.ascontiguousarray(view_depth, "f4").tobytes())
        return self._draw(camera, tex, only_source=only_source)

    def render_frame(self, camera: Camera, only_source: int = -1) -> UlrFrame:
        """Render `camera`; see `UlrFrame`. Proxy holes and uncovered pixels are filled on
        the GPU (push-pull); only the proxy depth and the colours are read back."""
        W, H = camera.width, camera.height
        depth = self.proxy_depth(camera)
        depth_tex = self._targets(W, H)[0].color_attachments[0]
        view_depth = depth
        if self.cfg.fill_holes and (depth > 0).any() and not (depth > 0).all():
            depth_tex = self._filler(W, H, True).fill(depth_tex)
            view_depth = np.frombuffer(depth_tex.read(), "f4").reshape(H, W)
        if self.cfg.blending == "field" and only_source < 0 and (view_depth != 0).any():
            uv, weights = self.field(camera, view_depth)
            rgba = self._draw(camera, depth_tex, weights, uv)
        else:
            rgba = self._draw(camera, depth_tex, only_source=only_source)
        blended = rgba[..., 3] > 127
        covered = blended & (depth > 0)
        image = rgba[..., :3]
        if self.cfg.fill_holes and blended.any() and not blended.all():
            out = self._filler(W, H, False).fill(self._targets(W, H)[1].color_attachments[0])
            image = np.frombuffer(out.read(), np.uint8).reshape(H, W, 4)[..., :3].copy()
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
        for obj in (self.vbo, self.ibo, self.depth_vao, self.blend_vao, *self._field_bufs):
            obj.release()
        for obj in (self.depth_prog, self.blend_prog, self.field_prog):
            obj.release()
        for fbos in self._fbos.values():
            for f in fbos:
                f.release()
        for filler in self._fillers.values():
            filler.release()
