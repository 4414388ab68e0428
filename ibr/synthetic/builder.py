"""Build textured meshes out of quads: each quad gets its own tile of one texture atlas.

World frame: metres, z up. A quad is given by an origin corner and two edge vectors
(`u_edge` along the texture's width, `v_edge` along its height); its normal is
u_edge x v_edge, so give edges counter-clockwise as seen from the visible side.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import trimesh
from PIL import Image

from ibr.synthetic.textures import KINDS

ATLAS_WIDTH = 4096
PAD = 2  # texels between tiles


Texture = str | Callable[[np.random.Generator, int, int], np.ndarray]
"""A `textures.KINDS` name, or a function (rng, h, w) -> (h, w, 3) uint8 image, e.g.
`functools.partial(textures.painted_wall, color=(200, 180, 150))`."""


@dataclass
class Quad:
    origin: np.ndarray
    u_edge: np.ndarray
    v_edge: np.ndarray
    texture: Texture
    specular: float = 0.0


@dataclass
class QuadMeshBuilder:
    """Collects quads, then `build(rng, texels_per_m)` draws each quad's texture into an
    atlas (shelf packing) and returns one trimesh with TextureVisuals, a per-vertex
    `specular` attribute (read by `ibr.mesh_renderer`) and, in `metadata["quad_textures"]`,
    each quad's texture kind (quad i is faces 2i and 2i + 1)."""

    quads: list[Quad] = field(default_factory=list)

    def quad(self, origin, u_edge, v_edge, texture: Texture, specular: float = 0.0) -> None:
        self.quads.append(Quad(*(np.asarray(v, float) for v in (origin, u_edge, v_edge)),
                               texture, specular))

    def box(self, lo, hi, texture: Texture, specular: float = 0.0, bottom: bool = False) -> None:
        """Axis-aligned box from corner `lo` to `hi` with outward faces."""
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
        self.quad((x0, y0, z0), (dx, 0, 0), (0, 0, dz), texture, specular)   # -y face
        self.quad((x1, y1, z0), (-dx, 0, 0), (0, 0, dz), texture, specular)  # +y face
        self.quad((x1, y0, z0), (0, dy, 0), (0, 0, dz), texture, specular)   # +x face
        self.quad((x0, y1, z0), (0, -dy, 0), (0, 0, dz), texture, specular)  # -x face
        self.quad((x0, y0, z1), (dx, 0, 0), (0, dy, 0), texture, specular)   # top
        if bottom:
            self.quad((x0, y1, z0), (dx, 0, 0), (0, -dy, 0), texture, specular)

    def build(self, rng: np.random.Generator, texels_per_m: float) -> trimesh.Trimesh:
        sizes = [(max(8, round(np.linalg.norm(q.u_edge) * texels_per_m)),
                  max(8, round(np.linalg.norm(q.v_edge) * texels_per_m))) for q in self.quads]
        sizes = [(min(w, ATLAS_WIDTH - 2 * PAD), h) for w, h in sizes]
        slots, atlas_h = _shelf_pack(sizes)
        atlas = np.zeros((atlas_h, ATLAS_WIDTH, 3), np.uint8)
        verts, uvs, spec = [], [], []
        for q, (w, h), (x, y) in zip(self.quads, sizes, slots):
            draw = KINDS[q.texture] if isinstance(q.texture, str) else q.texture
            atlas[y : y + h, x : x + w] = draw(rng, h, w)
            o, a, b = q.origin, q.u_edge, q.v_edge
            verts += [o, o + a, o + a + b, o + b]
            u0, u1 = (x + 0.5) / ATLAS_WIDTH, (x + w - 0.5) / ATLAS_WIDTH
            v0, v1 = 1 - (y + h - 0.5) / atlas_h, 1 - (y + 0.5) / atlas_h  # image top = v1
            uvs += [(u0, v0), (u1, v0), (u1, v1), (u0, v1)]
            spec += [q.specular] * 4
        n = len(self.quads)
        base = 4 * np.arange(n)[:, None]
        faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]]).reshape(2, n, 3)
        faces = faces.transpose(1, 0, 2).reshape(-1, 3)
        visual = trimesh.visual.TextureVisuals(
            uv=np.array(uvs), material=trimesh.visual.material.SimpleMaterial(image=Image.fromarray(atlas)))
        mesh = trimesh.Trimesh(np.array(verts), faces, visual=visual, process=False)
        mesh.vertex_attributes["specular"] = np.array(spec, np.float32)
        mesh.metadata["quad_textures"] = [_texture_name(q.texture) for q in self.quads]
        return mesh


def _texture_name(texture: Texture) -> str:
    """The KINDS name of a quad's texture (a function's name for a callable)."""
    if isinstance(texture, str):
        return texture
    return getattr(texture, "func", texture).__name__


def _shelf_pack(sizes: list[tuple[int, int]]) -> tuple[list[tuple[int, int]], int]:
    """Place (w, h) rectangles on shelves of an ATLAS_WIDTH-wide image, tallest first.
    Returns the top-left (x, y) of each and the atlas height."""
    order = sorted(range(len(sizes)), key=lambda i: -sizes[i][1])
    slots = [(0, 0)] * len(sizes)
    x = y = shelf_h = 0
    for i in order:
        w, h = sizes[i]
        if x + w + PAD > ATLAS_WIDTH:
            x, y, shelf_h = 0, y + shelf_h + PAD, 0
        slots[i] = (x + PAD, y + PAD)
        x += w + PAD
        shelf_h = max(shelf_h, h + PAD)
    return slots, y + shelf_h + PAD
