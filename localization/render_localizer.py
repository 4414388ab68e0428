"""Rendered-view localisation of one photo: find the basin with the particle filter, align
the pose by photometric Gauss-Newton, and say whether it localised.

    particle filter (Heigl et al. / Loc-NeRF, annealed; `pose6_filter`) on a coarse model at
    24-48 px  ->  its distinct modes, and pose proposals from features of the model's own
    rendered views (`rendered_matches`)  ->  Gauss-Newton on each (`direct_alignment`, coarse
    model, 48-96 px)  ->  the best few and the best proposal again on the fine model
    (192-384 px)  ->  the verdict (`confidence`: agreement with what the model reaches at its
    own photos, trusted support, no plausible rival mode).

The Gauss-Newton steps replace the fine annealing steps of a pure particle filter (the
gradient does in a dozen renders what a hundred particles do in each of many steps),
as MegaParticles and Loc-NeRF's successors use the image gradient.

`RenderModel` holds the map: the proxy at two levels of detail (`lean_model`), each
textured from the map's photos with a per-face trust (`photo_texture`, `model_trust`), the
scene's typical depth (the pixel-to-metre scale of every step) and the reference "explained"
share of the map photos.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import moderngl
import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from ibr.camera import Camera
from ibr.mesh_renderer import Light, MeshRenderer
from localization.confidence import ConfidenceConfig, Verdict, judge, plausible
from localization.direct_alignment import AlignConfig, Alignment, evaluate_pose, observed_at, refine_pose
from localization.lean_model import lean_mesh
from localization.model_trust import TrustConfig
from localization.photo_texture import PhotoTexture
from localization.pose6_filter import (Pose6Estimate, Pose6Filter, Pose6FilterConfig, PriorBox, cam_from_world_of)
from localization.render_likelihood import (BatchedLikelihood, LikelihoodConfig, comparison_camera,
                                            likelihood_renderer, truncation)
from localization.rendered_matches import RenderedMatchConfig, near_map_views, rendered_proposals


@dataclass(frozen=True)
class RenderLocalizerConfig:
    """Settings of `RenderModel` and `localize_by_rendering`."""

    filter: Pose6FilterConfig = field(default_factory=Pose6FilterConfig)
    align: AlignConfig = field(default_factory=AlignConfig)
    likelihood: LikelihoodConfig = field(default_factory=lambda: LikelihoodConfig(score="robust"))
    confidence: ConfidenceConfig = field(default_factory=ConfidenceConfig)
    trust: TrustConfig = field(default_factory=TrustConfig)
    """Trust of the faces of both levels (support in pixels at 384 px, the finest width).
    Judging the coarse level at its own width (96 px) trusted more of a sparse office but
    lured the search in the courtyard (office seed 1: 3 -> 4 of 6 queries; courtyard seed 1:
    2 -> 0 of 6), so both levels share the strict test."""
    fine_faces: int = 16000
    """Triangles of the fine model (alignment at the finest widths and the verdict)."""
    coarse_faces: int = 3000
    """Triangles of the coarse model (the filter and the first alignment): llvmpipe's cost
    grows with triangles, and at 24-96 px the detail is lost anyway."""
    coarse_widths: tuple[int, ...] = (48, 96)
    """Widths (pixels) of the first alignment of every mode, on the coarse model."""
    refine_widths: tuple[int, ...] = (192, 384)
    """Widths (pixels) of the final alignment on the fine model (capped at the photo's)."""
    modes: int = 8
    """Distinct modes of the filter's particles that are aligned."""
    fine_modes: int = 2
    """Best aligned modes that are aligned again on the fine model (the best is the answer,
    the second tells whether a rival explains the photo as well)."""
    mode_separation_px: float = 4.0
    """Modes closer than this (pixels at the filter's finest width) are one mode."""
    reference_views: int = 8
    """Map photos the reference "explained" share is measured on."""
    matches: RenderedMatchConfig | None = field(default_factory=RenderedMatchConfig)
    """Pose proposals from features of rendered views (`rendered_matches`), aligned beside
    the filter's modes; None: the filter's modes only."""
    proposals: int = 3
    """Proposals (most inliers first) aligned beside the filter's modes."""
    proposal_views: int = 2
    """Best modes of the filter the proposals' first round also renders at."""


@dataclass
class ModelLevel:
    """One level of detail of the map: the mesh it renders (world metres), its renderer,
    batched likelihood and texture (None for a mesh with its own texture or colours)."""

    mesh: trimesh.Trimesh
    renderer: MeshRenderer
    likelihood: BatchedLikelihood
    texture: PhotoTexture | None = None

    def focus(self, eye: np.ndarray, exclude: int | None = None) -> None:
        """Re-choose the textures for views near `eye`, without map photo `exclude`."""
        if self.texture is not None:
            self.texture.focus(self.renderer, eye, exclude)


def model_level(mesh: trimesh.Trimesh, faces: int, photos: tuple[list[Camera], list[np.ndarray]] | None,
                points: np.ndarray | None, trust: TrustConfig, config: RenderLocalizerConfig,
                ctx: moderngl.Context | None, light: Light | None) -> ModelLevel:
    """A `ModelLevel` of `mesh` decimated to `faces`, textured from `photos` (cameras, images)
    with trust (`trust`) from `points` when given."""
    lean = lean_mesh(mesh, faces)
    texture = None
    if photos is not None:
        texture = PhotoTexture(lean, photos[0], photos[1], ctx=ctx, points=points, trust_config=trust)
        lean = texture.textured_mesh()
    renderer = likelihood_renderer(lean, ctx)
    likelihood = BatchedLikelihood(renderer, config.likelihood, light)
    level = ModelLevel(lean, renderer, likelihood, texture)
    likelihood.focus = level.focus
    return level


class RenderModel:
    """The map the rendered-view localiser compares photos with.

    mesh: the proxy or a scene's mesh (world metres); cameras/images: the map photos;
    textured: texture the proxy from the photos (else the mesh's own colours or texture);
    points: triangulated points (P, 3) the proxy came from (per-face trust; None: all
    trusted)."""

    def __init__(self, mesh: trimesh.Trimesh, cameras: list[Camera], images: list[np.ndarray],
                 config: RenderLocalizerConfig = RenderLocalizerConfig(), textured: bool = True,
                 points: np.ndarray | None = None, ctx: moderngl.Context | None = None,
                 light: Light | None = None):
        self.config, self.cameras, self.images, self.light = config, list(cameras), list(images), light
        photos = (self.cameras, self.images) if textured else None
        self.fine = model_level(mesh, config.fine_faces, photos, points, config.trust, config, ctx, light)
        self.coarse = model_level(mesh, config.coarse_faces, photos, points, config.trust, config, ctx, light)
        self.depth_m = typical_depth(self.fine.renderer, self.cameras)
        """Median depth (metres) of the model seen from the map photos: the scene's scale."""
        self.reference = self.reference_explained()
        """Median share of a map photo's structure the model explains at its known pose, the
        photo itself left out of the texture (as for a query)."""

    def release(self) -> None:
        for level in (self.fine, self.coarse):
            level.likelihood.release()

    def align(self, level: ModelLevel, image: np.ndarray, camera: Camera, cam_from_world: np.ndarray,
              widths: tuple[int, ...]) -> Alignment:
        """Gauss-Newton alignment (`direct_alignment.refine_pose`) of `image` ((H, W, 3) uint8,
        intrinsics of `camera`) on `level` from `cam_from_world`, coarse to fine over `widths`."""
        c = self.config
        return refine_pose(level.renderer, image, camera, cam_from_world, widths, c.align, c.likelihood,
                           level.focus, self.light)

    def fine_widths(self, camera: Camera) -> tuple[int, ...]:
        """`refine_widths` capped at the photo's width (pixels)."""
        return tuple(min(w, camera.width) for w in self.config.refine_widths)

    def reference_explained(self) -> float:
        """`reference`: aligned-pose "explained" share over `reference_views` map photos."""
        n = len(self.cameras)
        width = self.config.refine_widths[-1]
        picks = np.unique(np.linspace(0, n - 1, min(n, self.config.reference_views)).round().astype(int))
        values = []
        for i in picks:
            cam = comparison_camera(self.cameras[i], min(width, self.cameras[i].width))
            self.fine.focus(cam.center, exclude=i)
            o = observed_at(self.images[i], cam)
            tau = truncation(o, self.config.likelihood)
            values.append(evaluate_pose(self.fine.renderer, o, cam, tau, self.config.likelihood, self.light).explained)
        return float(np.median(values))


def typical_depth(renderer: MeshRenderer, cameras: list[Camera], width: int = 64) -> float:
    """Median camera-z (metres) of the model over the pixels it covers in the map photos."""
    depths = [renderer.render(comparison_camera(c, width)).depth for c in cameras]
    d = np.concatenate([x[x > 0] for x in depths])
    if not len(d):
        raise ValueError("the model is not visible from any map photo")
    return float(np.median(d))


def pose_distance_px(a: np.ndarray, b: np.ndarray, depth_m: float, focal_px: float) -> float:
    """How far apart two cam_from_world poses look, in pixels: the centre offset at the
    scene's typical depth plus the rotation angle, both times the focal length."""
    ca, cb = np.linalg.inv(a)[:3, 3], np.linalg.inv(b)[:3, 3]
    angle = Rotation.from_matrix(a[:3, :3] @ b[:3, :3].T).magnitude()
    return float(focal_px * (np.linalg.norm(ca - cb) / depth_m + angle))


def distinct_modes(poses: list[np.ndarray], costs: np.ndarray, n: int, separation_px: float,
                   depth_m: float, focal_px: float) -> list[np.ndarray]:
    """Up to n of `poses` ((4, 4) each) in order of cost, each more than separation_px from
    the ones already taken."""
    taken: list[np.ndarray] = []
    for k in np.argsort(costs):
        if not np.isfinite(costs[k]):
            break
        if all(pose_distance_px(poses[k], t, depth_m, focal_px) > separation_px for t in taken):
            taken.append(poses[k])
            if len(taken) == n:
                break
    return taken


@dataclass
class RenderResult:
    """cam_from_world (4, 4) of the best aligned pose; verdict; estimate: the filter's last
    particles; aligned: the fine alignments, best first."""

    cam_from_world: np.ndarray
    verdict: Verdict
    estimate: Pose6Estimate
    aligned: list[Alignment]


def proposals(model: RenderModel, image: np.ndarray, camera: Camera, prior: PriorBox | None,
              modes: list[np.ndarray]) -> list[np.ndarray]:
    """The best `proposals` poses (4, 4) from rendered views' features (`rendered_matches`)
    at the prior (with its turned views), the filter's best `modes` and the map photos near
    the prior (`near_map_views`); without a prior (global localisation) at the modes alone;
    none with matching off."""
    cfg = model.config
    if cfg.matches is None or (prior is None and not modes):
        return []
    centre, spread_rad, modes = ((prior.cam_from_world, prior.spread_rad, modes) if prior is not None
                                 else (modes[0], 0.0, modes[1:]))
    near = ([] if prior is None else
            near_map_views(centre, prior.spread_m, spread_rad, model.cameras, cfg.matches.map_views))
    found = rendered_proposals(model.fine.renderer, model.fine.focus, image, camera, centre,
                               spread_rad, modes, cfg.matches, model.light, near)
    return [T for T, _ in found[:cfg.proposals]]


def localize_by_rendering(model: RenderModel, image: np.ndarray, camera: Camera, particles: np.ndarray,
                          spread: tuple[float, float], rng: np.random.Generator, prior: PriorBox | None = None,
                          starts: list[np.ndarray] = (),
                          on_step: Callable[[int, np.ndarray, np.ndarray], None] | None = None) -> RenderResult:
    """Localise `image` ((H, W, 3) uint8, intrinsics of `camera`) from prior particles (N, 6)
    drawn within `spread` (metres, radians) of the prior (support `prior`); `starts`: extra
    cam_from_world poses to align (e.g. a PnP pose). The extra starts and the proposals from
    rendered views' features are aligned beside the filter's modes, and the best of them (on
    the coarse model) always reaches the fine alignment, both as the coarse alignment left it
    and as it was found: on a coarse model that explains little of the photo its cost may tie
    with a wrong mode's, and its optimum may lie decimetres from the fine model's, while a
    proposal is as precise as the features it came from (pixels at 384 px).

    The answer is the fine alignment of least cost among those the verdict finds plausible
    (`confidence.plausible`: it explains about as much of the photo as the model does at its
    own photos), else of least cost: the cost sums evidence over the trusted pixels, so a
    wrong pose that sees more trusted model can cost less than the right one that sees a
    little of it well (courtyard seed 8, query 8: 3.5 m off at cost 0.945, explaining 0.29 of
    the photo, against 1 cm off at 0.960, explaining 0.90)."""
    cfg = model.config
    pf = Pose6Filter(model.coarse.likelihood, cfg.filter, rng, model.depth_m, spread, prior)
    est = pf.run(image, camera, particles, on_step)
    f_filter = comparison_camera(camera, cfg.filter.widths[-1]).K[0, 0]
    modes = distinct_modes(list(cam_from_world_of(est.particles)), est.costs, cfg.modes,
                           cfg.mode_separation_px, model.depth_m, f_filter)
    extra = list(starts) + proposals(model, image, camera, prior, modes[:cfg.proposal_views])
    coarse = [model.align(model.coarse, image, camera, T, cfg.coarse_widths) for T in modes + extra]
    widths = model.fine_widths(camera)
    f_fine = comparison_camera(camera, widths[-1]).K[0, 0]
    seeds = distinct_modes([a.cam_from_world for a in coarse], np.array([a.cost for a in coarse]),
                           cfg.fine_modes, cfg.confidence.distinct_px, model.depth_m, f_fine)
    if extra:
        k = int(np.argmin([a.cost for a in coarse[len(modes):]]))
        for T in (coarse[len(modes) + k].cam_from_world, extra[k]):  # aligned on the coarse model, and as found
            if all(pose_distance_px(T, U, model.depth_m, f_fine) > cfg.confidence.distinct_px for U in seeds):
                seeds.append(T)
    fine = [model.align(model.fine, image, camera, T, widths) for T in seeds]
    best, gap = answer(fine, model.reference, cfg.confidence, model.depth_m, f_fine)
    verdict = judge(best, model.reference, gap, cfg.confidence)
    return RenderResult(best.cam_from_world, verdict, est, [best] + sorted((a for a in fine if a is not best),
                                                                          key=lambda a: a.cost))


def answer(fine: list[Alignment], reference: float, config: ConfidenceConfig, depth_m: float,
           focal_px: float) -> tuple[Alignment, float | None]:
    """The answer among the fine alignments, and the cost gap to its best distinct rival
    (None without one): the alignment of least cost among those `plausible` against the
    model's `reference` explained share, else of least cost overall; rivals are the other
    plausible alignments more than `config.distinct_px` from it (pixels at focal length
    `focal_px`, depth `depth_m` metres)."""
    fine = sorted(fine, key=lambda a: a.cost)
    best = next((a for a in fine if plausible(a, reference, config)), fine[0])
    gaps = [a.cost - best.cost for a in fine if a is not best and plausible(a, reference, config)
            and pose_distance_px(a.cam_from_world, best.cam_from_world, depth_m, focal_px) > config.distinct_px]
    return best, min(gaps) if gaps else None
