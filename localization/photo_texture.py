"""A photo-textured model for the rendered-view likelihood: the proxy mesh textured by
projecting the posed source photos onto it.

Heigl et al. weight a particle by comparing the camera image with the view the image-based
model (their light field) renders at the particle's pose. A vertex-coloured proxy is too
blurry a stand-in for real photos: its NCC peaks away from the true pose. Here every face
of the (lean) proxy is textured from one source photo that sees it (visible by a depth
test, not too oblique). Its texture coordinates are the face's projection into that photo,
so rendering the mesh is projective texturing from the photos, and the batched likelihood
pass (`render_likelihood`) draws it unchanged. Which photo: the one with the most pixels
per metre, or, once the filter knows roughly where it is (`PhotoTexture.focus`), the one
whose ray to the face is closest in angle to the ray from there: Buehler et al.'s angular
penalty (unstructured lumigraph rendering) with one view per face, as in view-dependent
texture mapping (Debevec et al. 1996). The proxy's depth errors then displace the texture
least for the views the filter compares.

Given the triangulated points the proxy was built from, each face also carries a trust in
[0, 1] (`localization.model_trust`: photo-consistency x support by points), the weight the
robust likelihood gives the pixels it covers; without points every face is trusted (the
cheap path, e.g. for exporting a textured mesh).

Frames and units: world metres; texture coordinates follow trimesh (v = 0 at the bottom).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import moderngl
import numpy as np
import trimesh
from PIL import Image

from ibr.camera import Camera
from ibr.mesh_renderer import MeshRenderer
from localization.model_trust import TrustConfig, face_trust


@dataclass(frozen=True)
class PhotoTextureConfig:
    """Settings of `PhotoTexture`."""

    cell_width: int = 768
    """Width in pixels each source photo is stored at in the texture atlas."""
    depth_tolerance: float = 0.03
    """A face point is visible in a photo when its camera-z is within this fraction of the
    photo's rendered proxy depth there (plus 2 cm)."""
    min_cos: float = 0.2
    """Faces seen more obliquely than this cosine (about 78 deg) are not textured from a photo."""


def face_visibility(mesh: trimesh.Trimesh, cameras: list[Camera], width: int,
                    config: PhotoTextureConfig, ctx: moderngl.Context | None = None) -> np.ndarray:
    """(F, N) pixels-per-metre score of face f in photo n: the photo's focal length (pixels at
    `width`) times |cos| of the viewing angle over the distance; 0 where the face is outside
    the photo, occluded (proxy depth test at its centroid and at points 80 % of the way to
    its corners) or seen more obliquely than `config.min_cos`."""
    renderer = MeshRenderer(mesh, ctx)
    tri = mesh.triangles
    centroid = tri.mean(axis=1)
    probes = np.concatenate([centroid[:, None], centroid[:, None] + 0.8 * (tri - centroid[:, None])], axis=1)
    score = np.zeros((len(mesh.faces), len(cameras)))
    for n, cam in enumerate(cameras):
        small = cam.scaled(width / cam.width)
        depth = renderer.render(small).depth
        uv, z = small.project(probes.reshape(-1, 3))
        uv, z = uv.reshape(-1, 4, 2), z.reshape(-1, 4)
        inside = (z > 0) & np.all((uv >= 0) & (uv < [small.width, small.height]), axis=2)
        ui = np.clip(uv[..., 0].astype(int), 0, small.width - 1)
        vi = np.clip(uv[..., 1].astype(int), 0, small.height - 1)
        d = depth[vi, ui]
        visible = inside & (d > 0) & (z <= d * (1 + config.depth_tolerance) + 0.02)
        view = cam.center - centroid
        dist = np.linalg.norm(view, axis=1)
        cos = np.abs(np.einsum("ij,ij->i", mesh.face_normals, view)) / np.maximum(dist, 1e-9)
        ok = np.all(visible, axis=1) & (cos >= config.min_cos)
        score[:, n] = np.where(ok, small.K[0, 0] * cos / np.maximum(dist, 1e-9), 0.0)
    renderer.release()
    return score


Cell = tuple[int, int, float]
"""Where a photo lies in the atlas: (x0, y0) of its top-left texel and its scale."""


def atlas_of(images: list[np.ndarray], cell_width: int,
             palette: np.ndarray) -> tuple[np.ndarray, list[Cell], np.ndarray]:
    """Pack photos (each scaled to `cell_width` wide) in a grid and a palette of flat colours
    (P, 3) uint8 (one 4x4 texel block each) below it. Returns the atlas (H, W, 3) uint8, per
    photo (x0, y0, scale), and the palette blocks' centres (P, 2) in atlas texels."""
    scaled = [cv2.resize(im, (cell_width, round(im.shape[0] * cell_width / im.shape[1])),
                         interpolation=cv2.INTER_AREA) for im in images]
    cols = int(np.ceil(np.sqrt(len(scaled))))
    rows = -(-len(scaled) // cols)
    ch = max(s.shape[0] for s in scaled)
    per_row = cols * cell_width // 4
    j = np.arange(len(palette))
    corner = np.c_[4 * (j % per_row), rows * ch + 4 * (j // per_row)]
    atlas = np.zeros((rows * ch + 4 * -(-len(palette) // per_row), cols * cell_width, 3), np.uint8)
    cells = []
    for i, s in enumerate(scaled):
        x0, y0 = (i % cols) * cell_width, (i // cols) * ch
        atlas[y0:y0 + s.shape[0], x0:x0 + cell_width] = s
        cells.append((x0, y0, cell_width / images[i].shape[1]))
    for (x0, y0), c in zip(corner, palette):
        atlas[y0:y0 + 4, x0:x0 + 4] = c
    return atlas, cells, corner + 2.0


def select_views(score: np.ndarray, centroids: np.ndarray, centres: np.ndarray,
                 eye: np.ndarray | None, exclude: int | None = None) -> np.ndarray:
    """(F,) photo index per face, -1 where none sees it. eye None: the photo with the highest
    `face_visibility` score. eye (3,) world: the visible photo whose ray to the face is closest
    in angle to the ray from `eye` (Buehler et al.'s angular penalty, unstructured lumigraph
    rendering), so a proxy's depth errors displace the texture least for views near `eye`.
    exclude: a photo not to use (a map photo judged as if it were a query)."""
    visible = score > 0
    if exclude is not None:
        visible = visible.copy()
        visible[:, exclude] = False
        score = np.where(visible, score, 0.0)
    if eye is None:
        choice = np.argmax(score, axis=1)
    else:
        to_src = centres[None] - centroids[:, None]
        to_eye = np.asarray(eye, float) - centroids
        cos = np.einsum("fnk,fk->fn", to_src, to_eye) / (
            np.linalg.norm(to_src, axis=2) * np.linalg.norm(to_eye, axis=1, keepdims=True) + 1e-12)
        choice = np.argmax(np.where(visible, cos, -2.0), axis=1)
    return np.where(visible.any(axis=1), choice, -1)


class PhotoTexture:
    """The proxy textured from posed photos, with the per-face choice of photo adjustable
    to a viewpoint. mesh: (world metres); cameras and images ((H, W, 3) uint8): the photos."""

    def __init__(self, mesh: trimesh.Trimesh, cameras: list[Camera], images: list[np.ndarray],
                 config: PhotoTextureConfig = PhotoTextureConfig(), ctx: moderngl.Context | None = None,
                 points: np.ndarray | None = None, trust_config: TrustConfig = TrustConfig()):
        self.mesh, self.cameras = mesh, list(cameras)
        self.score = face_visibility(mesh, cameras, config.cell_width, config, ctx)
        self.centroids = mesh.triangles.mean(axis=1)
        self.trust = np.ones(len(mesh.faces))
        """(F,) each face's trust in [0, 1] (`model_trust.face_trust`; 1 without points)."""
        if points is not None:
            self.trust = face_trust(self.centroids, mesh.face_normals, self.score, self.cameras,
                                    images, np.asarray(points, float).reshape(-1, 3), trust_config)
        self.centres = np.array([c.center for c in cameras])
        self.unseen = np.flatnonzero(~(self.score > 0).any(axis=1))
        palette = np.full((len(self.unseen), 3), 128, np.uint8)
        if mesh.visual.kind == "vertex" and len(self.unseen):
            rgb = np.asarray(mesh.visual.vertex_colors)[mesh.faces[self.unseen], :3]
            palette = rgb.mean(axis=1).astype(np.uint8)
        self.atlas, self.cells, self.palette_texels = atlas_of(images, config.cell_width, palette)

    def uv(self, eye: np.ndarray | None = None, exclude: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(3F, 2) texture coordinates of the split vertices for the photo choice of
        `select_views(..., eye, exclude)` (trimesh convention: v = 0 at the atlas's bottom)
        and their trust (3F,): the face's, 0 where no (remaining) photo sees it."""
        H, W = self.atlas.shape[:2]
        choice = select_views(self.score, self.centroids, self.centres, eye, exclude)
        tri = self.mesh.triangles
        texel = np.zeros((len(tri), 3, 2))
        for n, cam in enumerate(self.cameras):
            faces = np.flatnonzero(choice == n)
            x0, y0, s = self.cells[n]
            uv, _ = cam.project(tri[faces].reshape(-1, 3))  # pixel centres at integers
            texel[faces] = (uv.reshape(-1, 3, 2) + 0.5) * s + [x0, y0]
        texel[self.unseen] = self.palette_texels[:, None]
        trust = np.repeat(np.where(choice >= 0, self.trust, 0.0), 3)
        return np.c_[texel[..., 0].ravel() / W, 1.0 - texel[..., 1].ravel() / H], trust

    def textured_mesh(self, eye: np.ndarray | None = None) -> trimesh.Trimesh:
        """The mesh with vertices split per face and textured from the atlas (`uv(eye)`);
        the vertex attribute `trust` (3F,) carries each face's trust to the renderer."""
        uv, trust = self.uv(eye)
        visual = trimesh.visual.TextureVisuals(uv=uv, image=Image.fromarray(self.atlas))
        faces = np.arange(3 * len(self.mesh.faces)).reshape(-1, 3)
        mesh = trimesh.Trimesh(self.mesh.triangles.reshape(-1, 3), faces, visual=visual, process=False)
        mesh.vertex_attributes["trust"] = trust
        return mesh

    def focus(self, renderer: MeshRenderer, eye: np.ndarray, exclude: int | None = None) -> None:
        """Re-choose the faces' photos for views near `eye` (world metres), without photo
        `exclude` when given, in a renderer of `textured_mesh()`: only its texture
        coordinates and trust are rewritten."""
        renderer.write_uv(*self.uv(eye, exclude))
