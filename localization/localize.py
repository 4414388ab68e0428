"""Localising photos against a posed scene: `SceneLocalizer` builds the map once (feature
points, the proxy model the filter renders) and poses query photos against it.

Three methods, so each can be compared with the others on the same map: "pnp" (SIFT + RANSAC
PnP, Foster, Wang & Grupen IV-B), "pf" (the rendered-view localiser: a 6-DoF particle filter,
Heigl et al. / Loc-NeRF, then photometric Gauss-Newton, `render_localizer`) and "hybrid"
(a strong PnP pose as it is, else the rendered localiser with the PnP pose as one more
start, `hybrid`). Every result says whether it localised (`confidence`). Their
leave-one-out evaluation is `localization.eval`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ibr.camera import Camera
from ibr.errors import InputError
from ibr.proxy.proxy_geometry import build_proxy
from ibr.proxy.triangulation import Features, sift_features
from ibr.scene import Scene
from localization.confidence import Verdict, pnp_verdict
from localization.feature_localizer import FeatureLocalizerConfig, FeatureMap
from localization.hybrid import HybridConfig, localize_hybrid
from localization.pose6_filter import PriorBox, sample_around
from localization.render_localizer import RenderLocalizerConfig, RenderModel, localize_by_rendering

METHODS = ("pf", "pnp", "hybrid")
MODELS = ("proxy", "proxy-colors", "mesh")


class LocalizeError(InputError):
    """A localisation request that cannot be run (unknown method, too few views, ...)."""


@dataclass(frozen=True)
class LocConfig:
    """Settings of `SceneLocalizer` and `evaluate_localization`: one configuration for every
    scene (its scales come from the scene: `render_localizer`)."""

    render: RenderLocalizerConfig = field(default_factory=RenderLocalizerConfig)
    """The rendered-view localiser (filter, alignment, verdict)."""
    hybrid: HybridConfig = field(default_factory=HybridConfig)
    """When a PnP pose is taken as it is."""
    features: FeatureLocalizerConfig = field(default_factory=FeatureLocalizerConfig)
    """The feature map and PnP."""
    model: str = "proxy"
    """What the filter renders: "proxy" (the proxy mesh from the photos, `build_proxy`,
    textured by projecting the photos onto it with a per-face trust), "proxy-colors" (the
    same proxy with its vertex colours only) or "mesh" (the scene's own, e.g. a synthetic
    world's: an upper bound that needs the truth)."""
    success_m: float = 0.05
    """A query succeeds when its position error is below this (metres) ..."""
    success_deg: float = 5.0
    """... and its rotation error below this (degrees): the issue's definition of success,
    a criterion of evaluation, not a setting of the method."""


@dataclass
class LocResult:
    """cam_from_world (4, 4) estimate (None when no pose was found); seconds of the query;
    verdict: localised or not, confidence, reason; n_inliers of PnP (0 when not run or
    failed); source: "pnp" or "render"; particles (N, 6) and weights (N,) of the filter's
    last step (None without the filter)."""

    cam_from_world: np.ndarray | None
    seconds: float
    verdict: Verdict
    n_inliers: int = 0
    source: str = "pnp"
    particles: np.ndarray | None = None
    weights: np.ndarray | None = None

    @property
    def localized(self) -> bool:
        return self.verdict.localized


class SceneLocalizer:
    """Localises photos against the posed views of `scene` with one method.

    features: SIFT features per view of `scene` (optional; extracted here when missing).
    After construction `model` is the `RenderModel` the filter renders (methods pf and
    hybrid; `model.fine.renderer` draws its view at an estimate)."""

    def __init__(self, scene: Scene, method: str, config: LocConfig = LocConfig(),
                 features: list[Features] | None = None, ctx=None):
        if method not in METHODS:
            raise LocalizeError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
        if config.model not in MODELS:
            raise LocalizeError(f"unknown model {config.model!r}; use {', '.join(MODELS)}")
        if len(scene) < 2:
            raise LocalizeError(f"scene {scene.name!r} has {len(scene)} views; a map needs at least 2")
        self.scene, self.method, self.config = scene, method, config
        self.feature_map = self.model = None
        if method in ("pnp", "hybrid"):
            tri = config.features.triangulation
            feats = features or [sift_features(v.image, tri.n_features, tri.contrast_threshold) for v in scene.views]
            self.feature_map = FeatureMap.from_features(scene.cameras, feats, config.features)
        if method in ("pf", "hybrid"):
            self.model = self._render_model(ctx)

    def release(self) -> None:
        """Free the filter's GL model (call when done with this localiser)."""
        if self.model is not None:
            self.model.release()
            self.model = None

    def _render_model(self, ctx) -> RenderModel:
        """The two-level map `config.model` names."""
        cams, images = self.scene.cameras, [v.image for v in self.scene.views]
        cfg = self.config.render
        if self.config.model == "mesh":
            if self.scene.mesh is None:
                raise LocalizeError(f"scene {self.scene.name!r} has no mesh; use the proxy model")
            light = getattr(self.scene.world, "light", None)
            return RenderModel(self.scene.mesh, cams, images, cfg, textured=False, ctx=ctx, light=light)
        proxy = build_proxy(self.scene)
        textured = self.config.model == "proxy"
        return RenderModel(proxy.mesh, cams, images, cfg, textured=textured,
                           points=proxy.points if textured else None, ctx=ctx)

    def localize(self, image: np.ndarray, camera: Camera, prior: np.ndarray | None,
                 spread_m: float, spread_deg: float, rng: np.random.Generator,
                 on_step: Callable | None = None) -> LocResult:
        """Pose of the camera that took `image` (intrinsics of `camera`). prior: cam_from_world
        (4, 4) the particles start around (uniform within +-spread_m per axis and spread_deg);
        None: around every map view (global). PnP ignores the prior."""
        t = time.perf_counter()
        if self.method == "pnp":
            r = self.feature_map.localize(image, camera)
            if r is None:
                return LocResult(None, time.perf_counter() - t, pnp_verdict(0, 0, self.config.hybrid.strong))
            verdict = pnp_verdict(r.n_inliers, r.n_matches, self.config.hybrid.strong)
            return LocResult(r.cam_from_world, time.perf_counter() - t, verdict, r.n_inliers)
        spread = (spread_m, np.radians(spread_deg))
        n = max(self.config.render.filter.n_particles, self.config.render.filter.n_initial)
        particles = self._prior_particles(prior, n, *spread, rng)
        box = None if prior is None else PriorBox(prior, *spread)
        if self.method == "pf":
            res = localize_by_rendering(self.model, image, camera, particles, spread, rng, box, on_step=on_step)
            return LocResult(res.cam_from_world, time.perf_counter() - t, res.verdict, 0, "render",
                             res.estimate.particles, res.estimate.weights)
        h = localize_hybrid(self.model, self.feature_map, image, camera, particles, spread, rng, box,
                            self.config.hybrid, on_step)
        est = h.render.estimate if h.render is not None else None
        return LocResult(h.cam_from_world, time.perf_counter() - t, h.verdict,
                         0 if h.pnp is None else h.pnp.n_inliers, h.source,
                         None if est is None else est.particles, None if est is None else est.weights)

    def _prior_particles(self, prior, n, spread_m, spread_rad, rng) -> np.ndarray:
        if prior is not None:
            return sample_around(prior, n, spread_m, spread_rad, rng)
        cams = self.scene.cameras
        pick = rng.integers(len(cams), size=n)
        return np.concatenate([sample_around(cams[i].cam_from_world, int((pick == i).sum()),
                                             spread_m, spread_rad, rng) for i in range(len(cams))])
