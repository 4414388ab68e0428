"""Localising photos against a posed scene: `SceneLocalizer` builds the map once (feature
points, the proxy model the filter renders) and poses query photos against it.

Three methods, so each can be compared with the others on the same map: "pnp" (SIFT + RANSAC
PnP, Foster, Wang & Grupen IV-B), "pf" (the 6-DoF rendered-view particle filter, Heigl et al.
/ Loc-NeRF) and "hybrid" (the PnP pose as a mixture proposal inside the filter). Their
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
from ibr.scene import Scene
from ibr.proxy.triangulation import Features, sift_features
from localization.feature_localizer import FeatureLocalizerConfig, FeatureMap
from localization.hybrid import HybridConfig, localize_hybrid
from localization.lean_model import lean_mesh
from localization.photo_texture import PhotoTexture
from localization.pose6_filter import Pose6Filter, Pose6FilterConfig, PriorBox, sample_around
from localization.render_likelihood import BatchedLikelihood, LikelihoodConfig, likelihood_renderer

METHODS = ("pf", "pnp", "hybrid")
MODELS = ("auto", "proxy", "proxy-colors", "mesh")


class LocalizeError(InputError):
    """A localisation request that cannot be run (unknown method, too few views, ...)."""


@dataclass(frozen=True)
class LocConfig:
    """Settings of `SceneLocalizer` and `evaluate_localization`."""

    filter: Pose6FilterConfig = field(default_factory=lambda: Pose6FilterConfig(
        n_particles=100, n_initial=2000, steps=48, sizes=((48, 32), (96, 64), (192, 128), (384, 256))))
    """The 6-DoF particle filter (100 particles: llvmpipe renders every particle's view)."""
    hybrid: HybridConfig = field(default_factory=HybridConfig)
    """Share and spread of the PnP proposal."""
    features: FeatureLocalizerConfig = field(default_factory=FeatureLocalizerConfig)
    """The feature map and PnP."""
    model: str = "auto"
    """What the filter renders: "proxy" (the proxy mesh from the photos, `build_proxy`,
    textured by projecting the photos onto it: `photo_texture`), "proxy-colors" (the same
    proxy with its vertex colours only), "mesh" (the scene's own, e.g. a synthetic world's)
    or "auto" (the scene's mesh when it has one, else "proxy")."""
    max_faces: int = 16000
    """Triangles of the lean model the filter renders (decimated)."""
    success_m: float = 0.05
    """A query succeeds when its position error is below this (metres) ..."""
    success_deg: float = 5.0
    """... and its rotation error below this (degrees)."""


@dataclass
class LocResult:
    """cam_from_world (4, 4) estimate (None when PnP found no pose); seconds of the query;
    n_inliers of PnP (0 when not run or failed)."""

    cam_from_world: np.ndarray | None
    seconds: float
    n_inliers: int = 0
    particles: np.ndarray | None = None
    weights: np.ndarray | None = None


class SceneLocalizer:
    """Localises photos against the posed views of `scene` with one method.

    features: SIFT features per view of `scene` (optional; extracted here when missing).
    After construction `mesh` is the model the filter renders (methods pf and hybrid)."""

    def __init__(self, scene: Scene, method: str, config: LocConfig = LocConfig(),
                 features: list[Features] | None = None, ctx=None):
        if method not in METHODS:
            raise LocalizeError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
        if len(scene) < 2:
            raise LocalizeError(f"scene {scene.name!r} has {len(scene)} views; a map needs at least 2")
        self.scene, self.method, self.config = scene, method, config
        self.feature_map = self.likelihood = None
        if method in ("pnp", "hybrid"):
            n = config.features.triangulation.n_features
            feats = features or [sift_features(v.image, n) for v in scene.views]
            self.feature_map = FeatureMap.from_features(scene.cameras, feats, config.features)
        if method in ("pf", "hybrid"):
            self.likelihood = self._likelihood(ctx)

    def release(self) -> None:
        """Free the filter's GL model (call when done with this localiser)."""
        if self.likelihood is not None:
            self.likelihood.release()
            self.likelihood = None

    def _use_mesh(self) -> bool:
        return self.config.model == "mesh" or (self.config.model == "auto" and self.scene.mesh is not None)

    def _likelihood(self, ctx) -> BatchedLikelihood:
        """The batched likelihood over the model `config.model` names (lean, decimated)."""
        if self.config.model not in MODELS:
            raise LocalizeError(f"unknown model {self.config.model!r}; use {', '.join(MODELS)}")
        if self._use_mesh():
            if self.scene.mesh is None:
                raise LocalizeError(f"scene {self.scene.name!r} has no mesh; use the proxy model")
            self.mesh = lean_mesh(self.scene.mesh, self.config.max_faces)
            light = getattr(self.scene.world, "light", None)
            return BatchedLikelihood(likelihood_renderer(self.mesh, ctx), LikelihoodConfig(), light)
        self.mesh = lean_mesh(build_proxy(self.scene).mesh, self.config.max_faces)
        if self.config.model == "proxy-colors":
            return BatchedLikelihood(likelihood_renderer(self.mesh, ctx), LikelihoodConfig())
        texture = PhotoTexture(self.mesh, self.scene.cameras, [v.image for v in self.scene.views], ctx=ctx)
        self.mesh = texture.textured_mesh()
        renderer = likelihood_renderer(self.mesh, ctx)
        likelihood = BatchedLikelihood(renderer, LikelihoodConfig())
        likelihood.focus = lambda eye: texture.focus(renderer, eye)
        return likelihood

    def localize(self, image: np.ndarray, camera: Camera, prior: np.ndarray | None,
                 spread_m: float, spread_deg: float, rng: np.random.Generator,
                 on_step: Callable | None = None) -> LocResult:
        """Pose of the camera that took `image` (intrinsics of `camera`). prior: cam_from_world
        (4, 4) the particles start around (uniform within +-spread_m per axis and spread_deg);
        None: around every map view (global). PnP ignores the prior."""
        t = time.perf_counter()
        if self.method == "pnp":
            r = self.feature_map.localize(image, camera)
            return LocResult(None if r is None else r.cam_from_world, time.perf_counter() - t,
                             0 if r is None else r.n_inliers)
        n = max(self.config.filter.n_particles, self.config.filter.n_initial)
        particles = self._prior_particles(prior, n, spread_m, np.radians(spread_deg), rng)
        box = None if prior is None else PriorBox(prior, spread_m, np.radians(spread_deg))
        pf = Pose6Filter(self.likelihood, self.config.filter, rng, box)
        if self.method == "pf":
            est, inliers = pf.run(image, camera, particles, on_step=on_step), 0
        else:
            res = localize_hybrid(pf, self.feature_map, image, camera, particles, self.config.hybrid,
                                  on_step=on_step)
            est, inliers = res.estimate, 0 if res.pnp is None else res.pnp.n_inliers
        return LocResult(est.cam_from_world, time.perf_counter() - t, inliers, est.particles, est.weights)

    def _prior_particles(self, prior, n, spread_m, spread_rad, rng) -> np.ndarray:
        if prior is not None:
            return sample_around(prior, n, spread_m, spread_rad, rng)
        cams = self.scene.cameras
        pick = rng.integers(len(cams), size=n)
        return np.concatenate([sample_around(cams[i].cam_from_world, int((pick == i).sum()),
                                             spread_m, spread_rad, rng) for i in range(len(cams))])
