"""Foster, Wang & Grupen's rendering-quality heuristic ("A Mobile Robot for Autonomous
Scene Capture and Rendering", Sec. IV-B, "Choosing a goal"), batched on the GPU.

For a candidate view C (centre L) the proxy mesh is rasterised with a shader that writes
the world point P of every pixel. The desired ray of that pixel is r = (L - P) / |L - P|;
each source camera C_i (centre L_i) that *sees* P offers the ray r_i = (L_i - P) / |L_i - P|,
and the pixel's score is the smallest angle theta_i = angle(r, r_i) (radians) over those
sources. "Sees" means: P projects inside C_i's image, in front of it, and is not occluded
according to C_i's depth map of the proxy (shadow-map test with a tolerance). A proxy
pixel no source sees scores `ViewQualityConfig.unseen_score` (default pi, the largest
possible angle: nothing can be rendered there). The view score is the mean over the
pixels where the proxy was hit; a view that hits no proxy at all scores
`ViewQualityConfig.empty_score` (default 0: nothing to gain).

Higher score = worse covered by the photos taken so far = more to gain by going there.

Batching: N candidate views are drawn with one instanced call of the mesh renderer
(`MeshRenderer.draw_views`, world-position attachment) into an atlas; a compute shader
(shaders/view_quality.glsl) scores every pixel of a tile and reduces the tile in shared
memory (one work group per view); only N x 4 numbers are read back. Sources live in a
shader storage buffer (projection + centre) and their depth maps in one texture array, so
hundreds of sources work; up to MAX_SHARED_SOURCES of them, each work group first bounds
its tile's proxy points with a box and copies to shared memory only the sources that may
see some of it (conservative culling; identical scores, ~1.6x faster on llvmpipe). `view_quality_numpy` is the same per-pixel computation in numpy
(the reference for tests and the benchmark's baseline).

Frames: world metres; candidate views as GL clip matrices (`Camera.gl_clip_from_world`)
of `config.size` and centres, as `localization.pose_views.se2_views` builds them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import moderngl
import numpy as np
import trimesh

from ibr.camera import Camera
from ibr.errors import InputError
from ibr.gl import load_compute, shared_context
from ibr.mesh_renderer import MeshRenderer
from localization.pose_views import se2_views


MAX_SHARED_SOURCES = 256
"""Up to this many sources are culled per view and copied into the work group's shared
memory; with more, every source is read from the storage buffer for every pixel."""


class ViewQualityError(InputError):
    """Sources or candidate views that cannot be scored (none, wrong shapes, NaN)."""


@dataclass(frozen=True)
class ViewQualityConfig:
    size: tuple[int, int] = (64, 48)
    """(width, height) in pixels at which candidate views are rasterised and scored."""
    depth_long_side: int = 160
    """Long side in pixels of each source's depth map (the visibility test's resolution)."""
    depth_tolerance_rel: float = 0.03
    """Visibility: a source sees P when its camera-z z <= d (1 + rel) + abs, d = depth map."""
    depth_tolerance_m: float = 0.03
    """Absolute part of the visibility tolerance (metres)."""
    near: float = 0.05
    """Near plane (metres) of every render; a point closer than this to a source is unseen."""
    far: float = 1000.0
    """Far plane (metres) of every render."""
    unseen_score: float = float(np.pi)
    """Score (radians) of a proxy pixel no source sees."""
    empty_score: float = 0.0
    """Score of a candidate view in which the proxy covers no pixel."""
    background_score: float | None = None
    """None: the view score is the mean over proxy pixels only (the paper). A number: pixels
    where the proxy is missing also count, with this score (e.g. pi: a hole in a rough map
    is unexplored), so the mean is over the whole view."""
    batch: int = 256
    """Candidate views drawn and scored per GPU pass (bounds the atlas size)."""


def resampled(camera: Camera, width: int, height: int) -> Camera:
    """`camera` with the same field of view at width x height pixels (pixel-centre
    convention exact: u' = sx (u + 0.5) - 0.5, v' likewise)."""
    if (camera.width, camera.height) == (width, height):
        return camera
    sx, sy = width / camera.width, height / camera.height
    S = np.array([[sx, 0, 0.5 * sx - 0.5], [0, sy, 0.5 * sy - 0.5], [0, 0, 1.0]])
    return Camera(S @ camera.K, width, height, camera.cam_from_world, camera.name)


def pixel_from_world(cameras: list[Camera]) -> np.ndarray:
    """(S, 4, 4) matrices taking homogeneous world points to (z u, z v, z, 1) in each
    camera's pixels; row 2 is the camera z (metres)."""
    M = np.zeros((len(cameras), 4, 4))
    for i, c in enumerate(cameras):
        M[i, :3] = c.K @ c.cam_from_world[:3]
        M[i, 3, 3] = 1.0
    return M


@dataclass(frozen=True)
class SourceSet:
    """The sources as both scorers see them. pixel_from_world (S, 4, 4) into depth-map
    pixels; centres (S, 3) world metres; depths (S, h, w) float32 camera-z of the proxy
    (0 = empty)."""

    pixel_from_world: np.ndarray
    centres: np.ndarray
    depths: np.ndarray


class ViewQuality:
    """Scores candidate views of `proxy_mesh` against the source photos `sources`.

    proxy_mesh: the map's mesh (rough Poisson mesh is fine; llvmpipe cost grows with its
        triangles). sources: the photos' cameras (any sizes). ctx: GL context (shared one by
        default).
    """

    def __init__(self, proxy_mesh: trimesh.Trimesh, sources: list[Camera],
                 ctx: moderngl.Context | None = None, config: ViewQualityConfig = ViewQualityConfig()):
        if len(sources) == 0:
            raise ViewQualityError("ViewQuality needs at least one source camera")
        if proxy_mesh is None or len(proxy_mesh.faces) == 0:
            raise ViewQualityError("ViewQuality: the proxy mesh has no faces")
        self.config = config
        self.ctx = ctx or shared_context()
        self.renderer = MeshRenderer(proxy_mesh, self.ctx, near=config.near, far=config.far)
        self.sources = self._build_sources(list(sources))
        shared = len(sources) <= MAX_SHARED_SOURCES
        self.program = load_compute(self.ctx, "view_quality", {
            "SHARED_SOURCES": int(shared), "MAX_SHARED": MAX_SHARED_SOURCES}, package="explore")
        self._upload_sources()

    def _build_sources(self, sources: list[Camera]) -> SourceSet:
        s = self.config.depth_long_side / max(sources[0].width, sources[0].height)
        W, H = max(1, round(sources[0].width * s)), max(1, round(sources[0].height * s))
        cams = [resampled(c, W, H) for c in sources]  # one depth-map size; per-source K'
        depths = np.concatenate([self.renderer.render_batch(cams[i:i + 256])[1]
                                 for i in range(0, len(cams), 256)])
        return SourceSet(pixel_from_world(cams), np.stack([c.center for c in cams]),
                         depths.astype(np.float32))

    def _upload_sources(self) -> None:
        s = self.sources
        n, h, w = s.depths.shape
        limit = self.ctx.info["GL_MAX_ARRAY_TEXTURE_LAYERS"]
        if n > limit:
            raise ViewQualityError(f"{n} sources exceed this GL's {limit} texture-array layers")
        self._depth_tex = self.ctx.texture_array((w, h, n), 1, s.depths.tobytes(), dtype="f4")
        self._depth_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        packed = np.zeros((n, 16), np.float32)  # std430 struct Source: 3 rows, centre
        packed[:, :12] = s.pixel_from_world[:, :3].reshape(n, 12)
        packed[:, 12:15] = s.centres
        self._source_buf = self.ctx.buffer(packed.tobytes())
        p, c = self.program, self.config
        p["u_n_sources"] = n
        p["u_depth_size"] = (w, h)
        p["u_near"] = c.near
        p["u_tol_rel"] = c.depth_tolerance_rel
        p["u_tol_abs"] = c.depth_tolerance_m
        p["u_unseen_score"] = c.unseen_score

    def release(self) -> None:
        """Free this scorer's GL objects (a mission builds a new one per map)."""
        (self.ctx.screen or self.ctx.detect_framebuffer(0)).use()  # never free the bound one
        for obj in (self._depth_tex, self._source_buf, self.program):
            obj.release()
        self.renderer.release()

    # --- scoring ----------------------------------------------------------------------
    def view_stats(self, clip_from_world: np.ndarray, eyes: np.ndarray) -> np.ndarray:
        """(N, 3) float64 per candidate view: (score (rad), fraction of the view's pixels on
        the proxy, fraction of those seen by at least one source). Views: world -> GL clip
        matrices (N, 4, 4) at `config.size` and centres (N, 3)."""
        clip, eyes = _check_views(clip_from_world, eyes)
        n = len(clip)
        raw = np.zeros((n, 4))
        if n == 0:
            return raw[:, :3]
        eye_buf = self.ctx.buffer(np.c_[eyes, np.ones(n)].astype(np.float32).tobytes())
        out = self.ctx.buffer(reserve=16 * n)
        for first in range(0, n, self.config.batch):
            sl = slice(first, min(n, first + self.config.batch))
            fbo, cols = self.renderer.draw_views(clip[sl], eyes[sl], self.config.size)
            fbo.color_attachments[1].use(0)
            self._depth_tex.use(1)
            self._source_buf.bind_to_storage_buffer(0)
            eye_buf.bind_to_storage_buffer(1)
            out.bind_to_storage_buffer(2)
            p = self.program
            p["u_tile"] = self.config.size
            p["u_cols"] = cols
            p["u_first"] = first
            p.run(group_x=sl.stop - sl.start)
        raw = np.frombuffer(out.read(), np.float32).reshape(n, 4).astype(np.float64)
        eye_buf.release()
        out.release()
        return _stats_from_sums(raw[:, 0], raw[:, 1], raw[:, 2], self.config)

    def score_views(self, clip_from_world: np.ndarray, eyes: np.ndarray) -> np.ndarray:
        """(N,) view scores (mean per-pixel angle, radians; higher = more to gain) of views
        given as clip matrices (N, 4, 4) at `config.size` and centres (N, 3)."""
        return self.view_stats(clip_from_world, eyes)[:, 0]

    def score_cameras(self, cameras: list[Camera]) -> np.ndarray:
        """(N,) scores of candidate cameras (their intrinsics are used as they are; they
        must have `config.size`)."""
        for c in cameras:
            if (c.width, c.height) != tuple(self.config.size):
                raise ViewQualityError(f"candidate camera {c.name!r} is {c.width}x{c.height}, "
                                       f"config.size is {self.config.size}")
        if not cameras:
            return np.zeros(0)
        c = self.config
        clip = np.stack([cam.gl_clip_from_world(c.near, c.far) for cam in cameras])
        return self.score_views(clip, np.stack([cam.center for cam in cameras]))

    def pose_views(self, poses: np.ndarray, template: Camera, cam_from_robot: np.ndarray):
        """(clip (N, 4, 4), eyes (N, 3)) of a robot camera at SE(2) poses (N, 3), the
        template's field of view resampled to `config.size`."""
        tmpl = resampled(template, *self.config.size)
        return se2_views(np.asarray(poses, dtype=np.float64).reshape(-1, 3), tmpl, cam_from_robot,
                         self.config.near, self.config.far)

    def score_poses(self, poses: np.ndarray, template: Camera, cam_from_robot: np.ndarray) -> np.ndarray:
        """(N,) scores of SE(2) robot poses (N, 3) (x, y, theta: metres, radians) for a camera
        with the intrinsics of `template` (resampled to `config.size`) mounted at
        `cam_from_robot` (4, 4)."""
        return self.score_views(*self.pose_views(poses, template, cam_from_robot))

    def seen_free(self, points: np.ndarray, margin_m: float = 0.3,
                  blocked: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None) -> np.ndarray:
        """(N,) bool: some source saw through each world point (N, 3) (metres): the point
        projects inside the source's depth map, in front of it, at least `margin_m` (metres,
        camera z) nearer than the proxy there, so the photo's ray crossed it: empty space.
        A point behind a wall, inside furniture, or where the proxy has a hole is not. The
        candidates of the heuristic must stand there: a view from behind the proxy sees only
        surfaces no source saw and would score the most.

        blocked(source centres (K, 3), points (K, 3)) -> (K,) bool: sight lines another
        sensor found blocked (the ultrasonic, `explore.frontier.SonarGrid.blocks`); they
        do not count. The proxy misses what SfM found no point on (the plain side of a
        bed the camera stood next to), and its rays then "see" through it."""
        s = self.sources
        n_src, h, w = s.depths.shape
        P = np.c_[np.asarray(points, dtype=np.float64).reshape(-1, 3), np.ones(len(points))]
        q = np.einsum("sij,nj->sni", s.pixel_from_world[:, :3], P)  # (S, N, 3): z u, z v, z
        z = q[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            px = np.floor(q[..., :2] / z[..., None] + 0.5)
        ok = (z > self.config.near) & np.all((px >= 0) & (px < [w, h]), axis=-1)
        d = np.zeros(z.shape)
        src = np.broadcast_to(np.arange(n_src)[:, None], z.shape)
        d[ok] = s.depths[src[ok], px[..., 1][ok].astype(int), px[..., 0][ok].astype(int)]
        seen = ok & (d > 0) & (z < d - margin_m)
        if blocked is not None and seen.any():
            si, ni = np.nonzero(seen)
            seen[si, ni] = ~blocked(s.centres[si], P[ni, :3])
        return np.any(seen, axis=0)

    def score_views_numpy(self, clip_from_world: np.ndarray, eyes: np.ndarray) -> np.ndarray:
        """The naive path (tests, benchmark baseline): one render and read-back per view,
        then `view_quality_numpy`. Same (N, 3) as `view_stats`."""
        clip, eyes = _check_views(clip_from_world, eyes)
        W, H = self.config.size
        out = np.zeros((len(clip), 3))
        for k in range(len(clip)):
            fbo, _ = self.renderer.draw_views(clip[k:k + 1], eyes[k:k + 1], (W, H))
            world = np.frombuffer(fbo.read(viewport=(0, 0, W, H), components=4, attachment=1,
                                           dtype="f4"), "f4").reshape(H, W, 4)
            out[k] = view_quality_numpy(world[None, ..., :3], world[None, ..., 3] > 0.5,
                                        eyes[k:k + 1], self.sources, self.config)[0]
        return out


def view_quality_numpy(world: np.ndarray, mask: np.ndarray, eyes: np.ndarray, sources: SourceSet,
                       config: ViewQualityConfig = ViewQualityConfig()) -> np.ndarray:
    """Reference per-pixel heuristic in numpy (float64). world (N, H, W, 3) proxy points per
    pixel of each candidate view, mask (N, H, W) true where the proxy was hit, eyes (N, 3)
    candidate centres, sources as `ViewQuality.sources`. Returns (N, 3) like `view_stats`."""
    n = len(world)
    sums, counts, seen_counts = np.zeros(n), np.zeros(n), np.zeros(n)
    S, h, w = sources.depths.shape
    for k in range(n):
        P = world[k][mask[k]].astype(np.float64)  # (M, 3)
        r = eyes[k] - P
        r /= np.linalg.norm(r, axis=1, keepdims=True)
        best = np.full(len(P), -2.0)
        best_ray = r.copy()
        for i in range(S):
            q = P @ sources.pixel_from_world[i, :3, :3].T + sources.pixel_from_world[i, :3, 3]
            z = q[:, 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                px = np.floor(q[:, :2] / z[:, None] + 0.5)
            ok = (z > config.near) & np.all((px >= 0) & (px < [w, h]), axis=1)
            d = np.zeros(len(P))
            d[ok] = sources.depths[i, px[ok, 1].astype(int), px[ok, 0].astype(int)]
            ok &= (d > 0) & (z <= d * (1 + config.depth_tolerance_rel) + config.depth_tolerance_m)
            ri = sources.centres[i] - P
            ri /= np.linalg.norm(ri, axis=1, keepdims=True)
            c = np.einsum("ij,ij->i", r, ri)
            better = ok & (c > best)
            best[better] = c[better]
            best_ray[better] = ri[better]
        seen = best > -1.5
        angle = np.arctan2(np.linalg.norm(np.cross(r, best_ray), axis=1), np.einsum("ij,ij->i", r, best_ray))
        score = np.where(seen, angle, config.unseen_score)
        sums[k], counts[k], seen_counts[k] = score.sum(), len(P), seen.sum()
    return _stats_from_sums(sums, counts, seen_counts, config, mask[0].size if n else 1)


def _stats_from_sums(sums, counts, seen, config: ViewQualityConfig, n_px: int | None = None) -> np.ndarray:
    n_px = n_px or config.size[0] * config.size[1]
    m = np.maximum(counts, 1.0)
    score = np.where(counts > 0, sums / m, config.empty_score)
    if config.background_score is not None:
        score = (sums + config.background_score * (n_px - counts)) / n_px
    return np.c_[score, counts / n_px, np.where(counts > 0, seen / m, 0.0)]


def _check_views(clip_from_world, eyes) -> tuple[np.ndarray, np.ndarray]:
    clip = np.asarray(clip_from_world, dtype=np.float64)
    eyes = np.asarray(eyes, dtype=np.float64)
    if clip.ndim != 3 or clip.shape[1:] != (4, 4) or eyes.shape != (len(clip), 3):
        raise ViewQualityError(f"views must be clip (N, 4, 4) and eyes (N, 3), got {clip.shape} "
                               f"and {eyes.shape}")
    if not (np.all(np.isfinite(clip)) and np.all(np.isfinite(eyes))):
        raise ViewQualityError("candidate views contain NaN or infinite values")
    return clip, eyes
