"""Basic mesh renderer: colour, camera-z depth, world position and normal (a G-buffer)
of a textured or vertex-coloured trimesh from any `Camera`, plus a batched pass that draws
many views of the mesh in one instanced draw call into the tiles of one framebuffer.

Frames: world positions and normals are in the world frame; depth is the camera-z in
metres (0 where nothing was hit). Images come back row-major (v, u), no flip needed
(see `Camera.gl_projection`).
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np
import trimesh

from ibr.camera import Camera
from ibr.gl import GL_CLIP_DISTANCE0, load_program, shared_context


@dataclass(frozen=True)
class Light:
    """Blinn-Phong lighting used to photograph synthetic worlds.

    position: (3,) world position of a point light (metres), or the direction *towards*
        the light when `directional` is true.
    ambient, diffuse: multipliers of the albedo; specular: strength of the highlight on
        surfaces whose per-vertex `specular` attribute is > 0; shininess: Phong exponent.
    """

    position: tuple[float, float, float] = (0.0, 0.0, 2.4)
    directional: bool = False
    ambient: float = 0.45
    diffuse: float = 0.65
    specular: float = 0.6
    shininess: float = 40.0


@dataclass
class GBuffer:
    """One rendered view. color (H, W, 3) uint8; depth (H, W) float32 camera-z in metres;
    world (H, W, 3) float32 world points; normal (H, W, 3) float32 unit world normals
    facing the camera when lit; mask (H, W) bool, true where the mesh was hit; trust (H, W)
    float32 the interpolated vertex trust (alpha; 1 unless the mesh has a `trust` attribute,
    0 where nothing was hit)."""

    color: np.ndarray
    depth: np.ndarray
    world: np.ndarray
    normal: np.ndarray
    mask: np.ndarray
    trust: np.ndarray | None = None


def mesh_vertex_data(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Interleaved float32 vertex data (V, 13) = position 3, normal 3, uv 2, rgba 4,
    specular 1; int32 faces (F, 3); the texture image (H, W, 3) uint8 or None. A per-vertex
    attribute `trust` (in [0, 1], e.g. `localization.model_trust`) becomes the alpha, which
    the renders carry in their colour attachment's alpha channel."""
    V = len(mesh.vertices)
    uv = np.zeros((V, 2))
    rgba = np.ones((V, 4))
    image = None
    visual = mesh.visual
    if isinstance(visual, trimesh.visual.TextureVisuals) and visual.uv is not None:
        uv = np.asarray(visual.uv, dtype=np.float64)
        material = visual.material
        img = getattr(material, "image", None) or getattr(material, "baseColorTexture", None)
        if img is not None:
            image = np.asarray(img.convert("RGB"))
    elif visual.kind == "vertex":
        rgba = np.asarray(visual.vertex_colors, dtype=np.float64) / 255.0
    elif visual.kind == "face":  # expand face colours onto vertices (last face wins)
        rgba[mesh.faces.ravel()] = np.repeat(visual.face_colors / 255.0, 3, axis=0)
    if "trust" in mesh.vertex_attributes:
        rgba[:, 3] = np.asarray(mesh.vertex_attributes["trust"], dtype=np.float64)
    specular = np.asarray(mesh.vertex_attributes.get("specular", np.zeros(V)), dtype=np.float64)
    data = np.c_[mesh.vertices, mesh.vertex_normals, uv, rgba, specular.reshape(V, 1)]
    return data.astype("f4"), np.asarray(mesh.faces, dtype="i4"), image


class MeshRenderer:
    """Renders one mesh. `render(camera)` gives a `GBuffer`; `render_batch(cameras)` draws
    all cameras (same size) in one instanced pass and returns their colours and depths."""

    ATTRS = ("in_position", "in_normal", "in_uv", "in_color", "in_specular")

    def __init__(self, mesh: trimesh.Trimesh, ctx: moderngl.Context | None = None,
                 background=(0.0, 0.0, 0.0), near: float = 0.05, far: float = 1000.0):
        self.ctx = ctx or shared_context()
        self.background = tuple(background)
        self.near, self.far = near, far
        data, faces, image = mesh_vertex_data(mesh)
        self.n_triangles = len(faces)
        self.vbo = self.ctx.buffer(data.tobytes())
        self.ibo = self.ctx.buffer(faces.tobytes())
        self.texture = self._upload_texture(image)
        self.anisotropy = 8.0
        """Most taps of the fragment shader's anisotropic texture filter (1: trilinear).
        The shader filters by hand (`albedo_at` in mesh.glsl), not with GL's anisotropic
        sampler: on llvmpipe that sampler did not finish one 320x240 photo looking down the
        apartment's corridor (seed 8, a capture mission's photo 1113) in 10 minutes at
        anisotropy 2, 4, 8 or 16 (23 ms at 1; Mesa 22.3.6, LLVM 15), and the mission stalled
        until its watchdog fired. Its cost is a known Mesa complaint (mesa-dist-win issue 86)."""
        self.prog = load_program(self.ctx, "mesh", {"BATCHED": 0})
        self.prog_batched = load_program(self.ctx, "mesh", {"BATCHED": 1})
        self.vao = self.ctx.vertex_array(
            self.prog, [(self.vbo, "3f4 3f4 2f4 4f4 1f4", *self.ATTRS)], self.ibo)
        self._fbos: dict[tuple[int, int], moderngl.Framebuffer] = {}

    def write_uv(self, uv: np.ndarray, trust: np.ndarray | None = None) -> None:
        """Replace the texture coordinates (V, 2) of the mesh's vertices (same order as the
        mesh, trimesh convention: v = 0 at the texture's bottom row) on the GPU, and their
        trust (V,) in [0, 1] (the colour's alpha) when given."""
        data = np.frombuffer(self.vbo.read(), "f4").reshape(-1, 13).copy()
        if len(uv) != len(data):
            raise ValueError(f"{len(uv)} texture coordinates for {len(data)} vertices")
        data[:, 6:8] = uv
        if trust is not None:
            data[:, 11] = trust
        self.vbo.write(data.tobytes())

    def release(self) -> None:
        """Free this renderer's GL objects (buffers, texture, programs, framebuffers)."""
        if self._fbos:
            self.ctx.detect_framebuffer(0).use()  # never leave a deleted framebuffer bound
        for fbo in self._fbos.values():
            for attachment in (*fbo.color_attachments, fbo.depth_attachment):
                attachment.release()
            fbo.release()
        self._fbos.clear()
        for obj in (self.vao, self.vbo, self.ibo, self.texture, self.prog, self.prog_batched):
            obj.release()

    def _upload_texture(self, image: np.ndarray | None) -> moderngl.Texture:
        if image is None:
            image = np.full((1, 1, 3), 255, np.uint8)
        limit = self.ctx.info["GL_MAX_TEXTURE_SIZE"]
        if max(image.shape[:2]) > limit:
            import cv2
            s = limit / max(image.shape[:2])
            image = cv2.resize(image, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        h, w = image.shape[:2]
        # trimesh's uv has v = 0 at the image's bottom row; GL's t = 0 is the first row sent
        tex = self.ctx.texture((w, h), 3, np.ascontiguousarray(image[::-1]).tobytes(), alignment=1)
        tex.build_mipmaps()
        tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        return tex

    def _fbo(self, width: int, height: int) -> moderngl.Framebuffer:
        key = (width, height)
        if key not in self._fbos:
            size = (width, height)
            self._fbos[key] = self.ctx.framebuffer(
                color_attachments=[self.ctx.texture(size, 4, dtype="f1"),
                                   self.ctx.texture(size, 4, dtype="f4"),
                                   self.ctx.texture(size, 4, dtype="f4"),
                                   self.ctx.texture(size, 1, dtype="f4")],
                depth_attachment=self.ctx.depth_renderbuffer(size))
        return self._fbos[key]

    def _begin(self, fbo: moderngl.Framebuffer, prog: moderngl.Program):
        fbo.use()
        fbo.viewport = (0, 0, *fbo.size)
        fbo.clear(0.0, 0.0, 0.0, 0.0, 1.0)  # every attachment reads 0 where nothing is drawn
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)
        self.texture.use(0)
        prog["u_texture"] = 0
        prog["u_max_aniso"] = self.anisotropy

    def render(self, camera: Camera, light: Light | None = None) -> GBuffer:
        """G-buffer of the mesh seen by `camera`; lit with Blinn-Phong when `light` is given."""
        W, H = camera.width, camera.height
        fbo = self._fbo(W, H)
        self._begin(fbo, self.prog)
        self.prog["u_clip_from_world"].write(
            camera.gl_clip_from_world(self.near, self.far).T.astype("f4").tobytes())
        self._set_light(self.prog, light)
        if light is not None:
            self.prog["u_eye"] = tuple(camera.center)
        self.vao.render(moderngl.TRIANGLES)
        rgba = np.frombuffer(fbo.read(components=4, attachment=0), np.uint8).reshape(H, W, 4)
        color = np.ascontiguousarray(rgba[..., :3])
        world = np.frombuffer(fbo.read(components=4, attachment=1, dtype="f4"), "f4").reshape(H, W, 4)
        normal = np.frombuffer(fbo.read(components=4, attachment=2, dtype="f4"), "f4").reshape(H, W, 4)
        depth = np.frombuffer(fbo.read(components=1, attachment=3, dtype="f4"), "f4").reshape(H, W)
        mask = world[..., 3] > 0.5
        return GBuffer(self._with_background(color, mask), depth.copy(), world[..., :3].copy(),
                       normal[..., :3].copy(), mask, rgba[..., 3] / np.float32(255.0))

    def _with_background(self, color: np.ndarray, mask: np.ndarray) -> np.ndarray:
        color = color.copy()
        color[~mask] = np.round(np.asarray(self.background) * 255).astype(np.uint8)
        return color

    def _set_light(self, prog: moderngl.Program, light: Light | None) -> None:
        prog["u_lit"] = light is not None
        if light is not None:
            prog["u_light"] = (*light.position, 0.0 if light.directional else 1.0)
            prog["u_light_terms"] = (light.ambient, light.diffuse, light.specular)
            prog["u_shininess"] = light.shininess

    def atlas_layout(self, n: int, width: int, height: int) -> tuple[int, int]:
        """(columns, rows) of the atlas that holds n views of width x height pixels. The
        tile count is rounded up to a power of two so that a particle count that changes
        every step (KLD-sampling) reuses a few cached framebuffers."""
        limit = self.ctx.info["GL_MAX_TEXTURE_SIZE"]
        n2 = 1 << max(0, int(n - 1).bit_length())
        cols = max(1, min(n2, limit // width))
        rows = -(-n2 // cols)
        if rows * height > limit:
            raise ValueError(f"{n} views of {width}x{height} exceed one {limit}px atlas")
        return cols, rows

    def draw_batch(self, cameras: list[Camera], light: Light | None = None) -> tuple[moderngl.Framebuffer, int]:
        """Draw N same-sized cameras with one instanced call; see `draw_views`."""
        W, H = cameras[0].width, cameras[0].height
        if any((c.width, c.height) != (W, H) for c in cameras):
            raise ValueError("draw_batch needs cameras of one size")
        clip = np.stack([c.gl_clip_from_world(self.near, self.far) for c in cameras])
        return self.draw_views(clip, np.stack([c.center for c in cameras]), (W, H), light)

    def draw_views(self, clip_from_world: np.ndarray, eyes: np.ndarray, size: tuple[int, int],
                   light: Light | None = None) -> tuple[moderngl.Framebuffer, int]:
        """Draw N views, given as world -> GL clip matrices (N, 4, 4) (see
        `Camera.gl_clip_from_world`) and camera centres (N, 3), with one instanced call into
        the tiles of an atlas framebuffer (view k at column k % cols, row k // cols) and
        leave them on the GPU. Returns the framebuffer (attachments: colour, world,
        normal, camera-z depth, as in `render`) and the number of columns."""
        n = len(clip_from_world)
        (W, H) = size
        cols, rows = self.atlas_layout(n, W, H)
        fbo = self._fbo(cols * W, rows * H)
        self._begin(fbo, self.prog_batched)
        k = np.arange(n)
        inst = np.c_[np.transpose(clip_from_world, (0, 2, 1)).reshape(n, 16), k % cols, k // cols,
                     eyes].astype("f4")
        ibuf = self.ctx.buffer(inst.tobytes())
        vao = self.ctx.vertex_array(self.prog_batched, [
            (self.vbo, "3f4 3f4 2f4 4f4 1f4", *self.ATTRS),
            (ibuf, "16f4 2f4 3f4/i", "in_clip_from_world", "in_tile", "in_eye")], self.ibo)
        self.prog_batched["u_tiles"] = (float(cols), float(rows))
        self._set_light(self.prog_batched, light)
        for i in range(4):
            self.ctx.enable_direct(GL_CLIP_DISTANCE0 + i)
        vao.render(moderngl.TRIANGLES, instances=n)
        for i in range(4):
            self.ctx.disable_direct(GL_CLIP_DISTANCE0 + i)
        vao.release()
        ibuf.release()
        return fbo, cols

    def render_batch(self, cameras: list[Camera], light: Light | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Colour (N, H, W, 3) uint8 and camera-z depth (N, H, W) float32 of N same-sized
        cameras, drawn by `draw_batch` in one call and read back."""
        fbo, _ = self.draw_batch(cameras, light)
        W, H = cameras[0].width, cameras[0].height
        aw, ah = fbo.size
        color = np.frombuffer(fbo.read(components=3, attachment=0), np.uint8).reshape(ah, aw, 3)
        depth = np.frombuffer(fbo.read(components=1, attachment=3, dtype="f4"), "f4").reshape(ah, aw)
        depth = _untile(depth, H, W, len(cameras))
        return self._with_background(_untile(color, H, W, len(cameras)), depth > 0), depth


def _untile(atlas: np.ndarray, H: int, W: int, n: int) -> np.ndarray:
    """(rows*H, cols*W, ...) atlas -> (n, H, W, ...) views in tile order (row-major)."""
    rows, cols = atlas.shape[0] // H, atlas.shape[1] // W
    tiles = atlas.reshape(rows, H, cols, W, *atlas.shape[2:]).swapaxes(1, 2)
    return tiles.reshape(rows * cols, H, W, *atlas.shape[2:])[:n].copy()
