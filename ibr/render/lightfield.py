"""Light-field rendering directly from real camera views through plane homographies
(Heigl, Denzler & Niemann; section 2 of the light-field particle-filter navigation paper).

A scene plane maps into camera i by a 3x3 projective matrix B_i, so a virtual view V sees
camera i's pixels through that plane with H = B_V B_i^-1 (and fetches them with B_i B_V^-1).

* *Neighbouring cameras.* The source camera centres are projected into the virtual view (by
  the usual projection, ignoring that a centre may lie behind V: the net is then mirrored and
  still says which sources contribute) and joined by a Delaunay triangulation (scipy).
* *Blending.* Each triangle is drawn for its three corner images; an image's weight is 1 at
  its own corner and 0 at the others, a flat ramp in between like Gouraud shading.
* *Single plane.* One plane approximates the scene. Heigl et al.'s cameras all look one way
  (at a ceiling); for scenes photographed from all sides we take the plane facing the virtual
  camera at the median depth of the proxy in its view (a focal plane, fixed per rendered view).
* *Local depth: approximating triangles.* A net vertex becomes a 3-D corner where the line
  from V's centre through camera i's centre meets the scene, found by looking up camera i's
  depth map in that direction; each triangle is subdivided at its edge midpoints (whose
  depth comes from the proxy seen by V), and each sub-triangle maps the images through its
  own plane.

Beyond the paper: the net only covers the convex hull of the projected centres, so by
default four far vertices at the corners of a frame around the image are added, each given
the source nearest to it (`extend_to_border`), to cover the whole view; and the centres are
projected from a point a little behind the virtual camera (`net_eye_back`), so that a
virtual camera on the capture path itself does not send its neighbours to infinity.
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np
import trimesh
from scipy.spatial import Delaunay, QhullError

from ibr.camera import Camera
from ibr.render.depth_maps import render_depth_maps
from ibr.gl import load_program, shared_context
from ibr.render.hole_filling import push_pull
from ibr.mesh_renderer import MeshRenderer
from ibr.scene import Scene
from ibr.source_views import SourceViews


@dataclass(frozen=True)
class LightFieldConfig:
    """Settings of the light-field renderer."""

    mode: str = "single_plane"
    """"single_plane" or "local_depth" (approximating triangles)."""
    max_edge_px: float = 32.0
    """Local-depth mode: triangles are split at their edge midpoints until their edges inside
    the image are shorter than this (pixels)."""
    extend_to_border: bool = True
    """Add four far net vertices so the net covers the whole image (not in the paper)."""
    fill_holes: bool = True
    """Fill pixels no triangle covers by push-pull (reported as not covered)."""
    net_eye_back: float = 0.3
    """Project the source centres for the net from a point this fraction of the focal-plane
    depth behind the virtual camera, on its optical axis (not in the paper; 0 = Heigl's net).
    Heigl's cameras form a 2-D grid the virtual camera sits in front of or behind; when it
    lies on the capture path itself (a held-out photo of a 1-D arc, as in the Strecha sets)
    its neighbours along the path project to near infinity, those slightly behind it
    mirrored to the wrong side, and the image falls in triangles of far-turned sources.
    Seen from a little behind, the neighbours project to finite pixels on their own side
    (fountain-P11 leave-one-out, single plane: 14.8 -> 19.6 dB mean PSNR)."""


@dataclass
class Net:
    """The triangle net in the virtual image. pixels (V, 2) (u, v); sources (V,) source index
    of each vertex; triangles (T, 3) vertex indices."""

    pixels: np.ndarray
    sources: np.ndarray
    triangles: np.ndarray
    n_projected: int = 0
    """Vertices [0, n_projected) are projected source centres; later ones border vertices."""


def focal_plane(camera: Camera, points: np.ndarray) -> np.ndarray:
    """(4,) plane (n, w) with n . X = w: facing `camera` (n = its optical axis) at the median
    camera-z of the `points` (N, 3) inside its view (all points in front if none is inside)."""
    uv, z = camera.project(points)
    inside = camera.in_image(uv, z)
    sel = z[inside] if inside.any() else z[z > 0]
    depth = float(np.median(sel)) if len(sel) else 1.0
    n = camera.forward
    return np.r_[n, n @ camera.center + depth]


def sees_point(source: Camera, X: np.ndarray) -> bool:
    """Whether world point X (3,) is in front of `source` and inside its image."""
    uv, z = source.project(X[None])
    return bool(z[0] > 0 and 0 <= uv[0, 0] < source.width and 0 <= uv[0, 1] < source.height)


def camera_net(camera: Camera, sources: list[Camera], extend_to_border: bool,
               focus: np.ndarray | None = None, eye_back: float = 0.0) -> Net:
    """Delaunay net of the source centres projected into `camera` (mirrored when behind).
    Only sources facing the same way that see `focus` (3,), the focal-plane point at the
    image centre, take part (when given). eye_back (metres): project the centres from a
    point that far behind the camera on its optical axis (0 = Heigl's net)."""
    C = np.array([s.center for s in sources])
    q = (camera.to_camera_frame(C) + [0.0, 0.0, eye_back]) @ camera.K.T
    z = np.where(np.abs(q[:, 2]) < 1e-9, 1e-9, q[:, 2])
    uv = q[:, :2] / z[:, None]
    facing = np.array([s.forward @ camera.forward > 0 and (focus is None or sees_point(s, focus))
                       for s in sources], bool)
    keep = np.flatnonzero(facing & np.all(np.abs(uv) < 1e7, axis=1))
    pixels, ids = uv[keep], keep
    n_projected = len(pixels)
    if extend_to_border and len(pixels):
        W, H = camera.width, camera.height
        corners = np.array([[-W, -H], [2 * W, -H], [2 * W, 2 * H], [-W, 2 * H]], float)
        corners = np.r_[corners, [[0.5 * W, 0.5 * H]] if len(pixels) < 2 else np.zeros((0, 2))]
        nearest = np.argmin(np.linalg.norm(corners[:, None] - pixels[None], axis=2), axis=1)
        pixels, ids = np.r_[pixels, corners], np.r_[ids, ids[nearest]]
    try:
        tri = Delaunay(pixels).simplices if len(pixels) >= 3 else np.zeros((0, 3), int)
    except QhullError:  # all centres on a line: no triangles
        tri = np.zeros((0, 3), int)
    return Net(pixels, ids, tri, n_projected)


def split_at_midpoints(bary: np.ndarray) -> np.ndarray:
    """Each triangle (M, 3, 3) of barycentric corners -> its four halves (4M, 3, 3), split at
    the edge midpoints."""
    a, b, c = bary[:, 0], bary[:, 1], bary[:, 2]
    ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
    return np.concatenate([np.stack(t, 1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])


def subdivide(corners: np.ndarray, max_edge_px: float, size: tuple[int, int],
              max_levels: int = 12) -> np.ndarray:
    """Split a net triangle (3, 2) (pixels) at its edge midpoints until every sub-triangle
    that overlaps the image of `size` (W, H) has edges shorter than `max_edge_px`; sub-
    triangles wholly outside the image are dropped. Returns barycentric corners (M, 3, 3)
    with respect to the original corners."""
    W, H = size
    done, todo = [], np.eye(3)[None]
    for _ in range(max_levels + 1):
        pix = todo @ corners                                        # (M, 3, 2)
        lo, hi = pix.min(axis=1), pix.max(axis=1)
        overlaps = (hi[:, 0] >= -1) & (lo[:, 0] <= W) & (hi[:, 1] >= -1) & (lo[:, 1] <= H)
        edge = np.linalg.norm(pix - np.roll(pix, 1, axis=1), axis=2).max(axis=1)
        small = edge <= max_edge_px
        done.append(todo[overlaps & small])
        todo = todo[overlaps & ~small]
        if not len(todo):
            break
        todo = split_at_midpoints(todo)
    return np.concatenate(done + [todo])


def plane_through(X: np.ndarray) -> np.ndarray:
    """(M, 4) planes (n, w) through triangles X (M, 3, 3); NaN rows where degenerate."""
    n = np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0])
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.where(norm > 1e-12, n / norm, np.nan)
    return np.c_[n, np.einsum("ij,ij->i", n, X[:, 0])]


def corner_point_from_source_depth(eye: np.ndarray, source: Camera, depth: np.ndarray) -> np.ndarray:
    """Heigl's local depth: the scene point on the line from the virtual centre `eye` through
    the source centre, looked up in the source's depth map (H, W); NaNs if not seen there."""
    d = source.center - eye
    if np.linalg.norm(d) < 1e-9:
        return np.full(3, np.nan)
    d /= np.linalg.norm(d)
    z_dir = source.cam_from_world[2, :3] @ d
    uv, _ = source.project(source.center[None] + d[None])
    u, v = np.floor(np.clip(np.nan_to_num(uv[0]), -1e6, 1e6) + 0.5).astype(int)
    if z_dir <= 1e-6 or not (0 <= u < source.width and 0 <= v < source.height) or depth[v, u] <= 0:
        return np.full(3, np.nan)
    return source.center + d * depth[v, u] / z_dir


def ray_points(camera: Camera, pixels: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """World points (M, 3) of `pixels` (M, 2) at the virtual proxy depth (H, W); NaN rows
    outside the image or where the proxy is missing."""
    ij = np.floor(pixels + 0.5).astype(int)
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < camera.width) & (ij[:, 1] >= 0) & (ij[:, 1] < camera.height)
    z = np.zeros(len(pixels))
    z[inside] = depth[ij[inside, 1], ij[inside, 0]]
    X = camera.unproject(pixels, z)
    X[z <= 0] = np.nan
    return X


def ray_plane_point(camera: Camera, pixel: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """Where the rays through pixels (2,) or (M, 2) meet `plane` (4,) (maybe behind the camera)."""
    d = camera.ray_directions(np.reshape(pixel, (-1, 2)))
    den = d @ plane[:3]
    den = np.where(np.abs(den) > 1e-12, den, 1e-12)
    X = camera.center + ((plane[3] - plane[:3] @ camera.center) / den)[:, None] * d
    return X[0] if np.ndim(pixel) == 1 else X


def net_vertices(camera: Camera, net: Net, sources: list[Camera], plane: np.ndarray,
                 local_depth: bool, max_edge_px: float, source_depths: np.ndarray | None,
                 view_depth: np.ndarray | None) -> np.ndarray:
    """Per-vertex attribute rows (3M, 12): pixel 2, Gouraud weights 3, sources 3, plane 4,
    of the net's triangles (single plane) or approximating sub-triangles (local depth)."""
    rows = []
    corner_X = {}
    for tri in net.triangles:
        corners = net.pixels[tri]
        bary = subdivide(corners, max_edge_px, (camera.width, camera.height)) if local_depth else np.eye(3)[None]
        if not len(bary):
            continue
        pix = bary @ corners                                        # (M, 3, 2)
        planes = np.tile(plane, (len(bary), 1))
        if local_depth:
            X = ray_points(camera, pix.reshape(-1, 2), view_depth).reshape(-1, 3, 3)
            for k, vid in enumerate(tri):  # corners: look up the source's own depth map
                if vid not in corner_X:
                    s = int(net.sources[vid])
                    corner_X[vid] = (corner_point_from_source_depth(camera.center, sources[s], source_depths[s])
                                     if vid < net.n_projected else np.full(3, np.nan))
                at_corner = bary[:, :, k] > 1 - 1e-9
                if np.isfinite(corner_X[vid]).all():
                    X[at_corner] = corner_X[vid]
            missing = ~np.isfinite(X).all(axis=2)
            X[missing] = ray_plane_point(camera, pix[missing], plane)
            local = plane_through(X)
            ok = np.isfinite(local).all(axis=1)
            planes[ok] = local[ok]
        src = np.broadcast_to(net.sources[tri], (len(bary), 3, 3))
        rows.append(np.concatenate([pix, bary, src, np.repeat(planes[:, None], 3, axis=1)], axis=2).reshape(-1, 12))
    return np.concatenate(rows) if rows else np.zeros((0, 12))


class LightFieldRenderer:
    """Heigl et al.'s light-field renderer of a scene's photos. proxy_mesh gives the focal
    plane's depth and, in local-depth mode, the depth maps."""

    def __init__(self, scene: Scene, proxy_mesh: trimesh.Trimesh, ctx: moderngl.Context | None = None,
                 config: LightFieldConfig | None = None, source_depths: np.ndarray | None = None):
        self.cfg = config or LightFieldConfig()
        if self.cfg.mode not in ("single_plane", "local_depth"):
            raise ValueError(f"mode must be single_plane or local_depth, got {self.cfg.mode!r}")
        self.ctx = ctx or shared_context()
        self.cameras = scene.cameras
        self.points = np.asarray(proxy_mesh.vertices)
        self.source_depths = None
        self.proxy = None
        if self.cfg.mode == "local_depth":
            self.source_depths = (render_depth_maps(proxy_mesh, self.cameras, self.ctx)
                                  if source_depths is None else source_depths)
            self.proxy = MeshRenderer(proxy_mesh, self.ctx)
        self.sources = SourceViews(self.ctx, self.cameras, np.stack([v.image for v in scene.views]))
        self.prog = load_program(self.ctx, "lightfield")
        self._fbos: dict = {}

    def net(self, camera: Camera, plane: np.ndarray | None = None) -> Net:
        """The Delaunay net of the sources that see the focal plane's centre point."""
        plane = focal_plane(camera, self.points) if plane is None else plane
        centre = np.array([(camera.width - 1) / 2, (camera.height - 1) / 2])
        depth = plane[3] - plane[:3] @ camera.center
        return camera_net(camera, self.cameras, self.cfg.extend_to_border,
                          ray_plane_point(camera, centre, plane), self.cfg.net_eye_back * depth)

    def render_frame(self, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
        """(image (H, W, 3) uint8, covered (H, W) bool) before and without hole filling."""
        W, H = camera.width, camera.height
        plane = focal_plane(camera, self.points)
        net = self.net(camera, plane)
        view_depth = self.proxy.render(camera).depth if self.proxy is not None else None
        rows = net_vertices(camera, net, self.cameras, plane, self.cfg.mode == "local_depth",
                            self.cfg.max_edge_px, self.source_depths, view_depth)
        if (W, H) not in self._fbos:
            self._fbos[W, H] = self.ctx.framebuffer([self.ctx.texture((W, H), 4, dtype="f1")])
        fbo = self._fbos[W, H]
        fbo.use()
        fbo.viewport = (0, 0, W, H)
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.ctx.disable(moderngl.CULL_FACE)
        if len(rows):
            data = np.zeros(len(rows), dtype=[("pixel", "f4", 2), ("weight", "f4", 3),
                                              ("sources", "f4", 3), ("plane", "f4", 4)])
            data["pixel"], data["weight"] = rows[:, :2], rows[:, 2:5]
            data["sources"], data["plane"] = rows[:, 5:8], rows[:, 8:12]
            vbo = self.ctx.buffer(data.tobytes())
            vao = self.ctx.vertex_array(self.prog, [(vbo, "2f4 3f4 3f4 4f4", "in_pixel", "in_weight",
                                                     "in_sources", "in_plane")])
            self.sources.bind(self.prog)
            self.prog["u_size"] = (float(W), float(H))
            self.prog["u_world_from_pixel"].write(
                (camera.world_from_cam[:3, :3] @ np.linalg.inv(camera.K)).T.astype("f4").tobytes())
            self.prog["u_eye"] = tuple(camera.center)
            vao.render(moderngl.TRIANGLES)
            vao.release()
            vbo.release()
        rgba = np.frombuffer(fbo.read(components=4), np.uint8).reshape(H, W, 4)
        return rgba[..., :3].copy(), rgba[..., 3] > 127

    def render(self, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
        """(image (H, W, 3) uint8, covered (H, W) bool) of the virtual `camera`; uncovered
        pixels are push-pull filled when `fill_holes`."""
        image, covered = self.render_frame(camera)
        if self.cfg.fill_holes and covered.any() and not covered.all():
            image = np.clip(np.round(push_pull(image.astype(np.float64), covered)), 0, 255).astype(np.uint8)
        return image, covered

    def release(self) -> None:
        """Free the GPU objects (binding the default framebuffer first, as `UlrRenderer`)."""
        self.ctx.detect_framebuffer(0).use()
        self.sources.release()
        for fbo in self._fbos.values():
            fbo.release()
