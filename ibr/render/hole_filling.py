"""Hole filling by push-pull (Gortler et al. 1996, the lumigraph's pull-push): values known
at some pixels are averaged down an image pyramid with their weights (pull), then the coarse
levels fill the pixels that had no weight on the way back up (push). Used by the renderers
to interpolate the virtual view's proxy depth into holes, as Foster et al. (section V-C)
"handle holes in the rasterized point cloud by interpolating the depths from nearby pixels",
and to fill colours that no source covers.

`push_pull` is the numpy reference; `GLPushPull` runs the same pyramid in compute shaders
(`ibr/shaders/push_pull.glsl`) on textures that stay on the GPU, for the renderers' frame loop.
"""

from __future__ import annotations

import moderngl
import numpy as np

from ibr.gl import load_compute


def _pull(values: np.ndarray, weight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One pyramid level down: 2x2 weighted means (values premultiplied by weight)."""
    H, W = weight.shape
    ph, pw = H % 2, W % 2
    v = np.pad(values * weight[..., None], ((0, ph), (0, pw), (0, 0)))
    w = np.pad(weight, ((0, ph), (0, pw)))
    vs = v.reshape(v.shape[0] // 2, 2, v.shape[1] // 2, 2, -1).sum(axis=(1, 3))
    ws = w.reshape(w.shape[0] // 2, 2, w.shape[1] // 2, 2).sum(axis=(1, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(ws[..., None] > 0, vs / np.maximum(ws, 1e-12)[..., None], 0.0)
    return mean, np.minimum(ws, 1.0)


def push_pull(values: np.ndarray, known: np.ndarray) -> np.ndarray:
    """Fill the pixels where `known` (H, W) bool is false from the known ones.

    values: (H, W) or (H, W, C) float array. Returns the filled array, same shape and dtype
    float64; known pixels keep their values exactly. If no pixel is known, returns zeros.
    """
    squeeze = values.ndim == 2
    v = np.asarray(values, dtype=np.float64).reshape(*known.shape, -1)
    w = known.astype(np.float64)
    levels = [(v, w)]
    while min(levels[-1][1].shape) > 1:
        levels.append(_pull(*levels[-1]))
    filled = levels[-1][0]
    for v_l, w_l in reversed(levels[:-1]):
        up = np.repeat(np.repeat(filled, 2, axis=0), 2, axis=1)[: w_l.shape[0], : w_l.shape[1]]
        filled = w_l[..., None] * v_l + (1.0 - w_l[..., None]) * up
    out = np.where(known[..., None], v, filled)
    return out[..., 0] if squeeze else out


def _set(prog, **uniforms) -> None:
    """Set the uniforms the compiler kept (unused ones are optimised away)."""
    for name, value in uniforms.items():
        if name in prog:
            prog[name] = value


class GLPushPull:
    """`push_pull` on the GPU for one image size (W, H) and one kind of source: depth=True
    fills a camera-z texture (R, known where > 0) into an r32f texture whose filled pixels are
    negative (as `ulr.fill_depth_holes`); depth=False fills an RGBA texture (known where
    alpha > 0.5) into an rgba8 one, alpha passed through. Levels are rgba32f textures."""

    GROUP = 8  # local size of the compute shaders (both axes)

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int], depth: bool):
        self.ctx, self.size, self.depth = ctx, tuple(size), depth
        defines = {"DEPTH": int(depth)}
        self.pull, self.push, self.final = (load_compute(ctx, "push_pull", {**defines, "MODE": m})
                                            for m in (0, 1, 2))
        self.levels = []
        w, h = self.size
        while min(w, h) > 1:  # the numpy pyramid: halve (rounding up) until a side is 1
            w, h = (w + 1) // 2, (h + 1) // 2
            tex = ctx.texture((w, h), 4, dtype="f4")
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self.levels.append(tex)
        self.out = ctx.texture(self.size, 1 if depth else 4, dtype="f4" if depth else "f1")
        self.out.filter = (moderngl.NEAREST, moderngl.NEAREST)

    def _run(self, prog: moderngl.ComputeShader, size: tuple[int, int]) -> None:
        prog.run((size[0] + self.GROUP - 1) // self.GROUP, (size[1] + self.GROUP - 1) // self.GROUP)
        self.ctx.memory_barrier()

    def fill(self, source: moderngl.Texture) -> moderngl.Texture:
        """The filled copy of `source` (a texture of `size`, nearest filtering), as `out`."""
        if tuple(source.size) != self.size:
            raise ValueError(f"push-pull built for {self.size}, got a texture of {source.size}")
        if not self.levels:
            raise ValueError(f"push-pull needs an image larger than 1 pixel, got {self.size}")
        source.use(0)
        _set(self.pull, u_source=0, u_fine=1)
        for i, tex in enumerate(self.levels):
            if i:
                self.levels[i - 1].use(1)
            _set(self.pull, u_first=i == 0)
            tex.bind_to_image(0, read=False, write=True)
            self._run(self.pull, tex.size)
        _set(self.push, u_coarse=2)
        for i in range(len(self.levels) - 2, -1, -1):
            self.levels[i + 1].use(2)
            self.levels[i].bind_to_image(0, read=True, write=True)
            self._run(self.push, self.levels[i].size)
        source.use(0)
        self.levels[0].use(2)
        _set(self.final, u_source=0, u_coarse=2)
        self.out.bind_to_image(0, read=False, write=True)
        self._run(self.final, self.size)
        return self.out

    def release(self) -> None:
        for obj in (*self.levels, self.out, self.pull, self.push, self.final):
            obj.release()
