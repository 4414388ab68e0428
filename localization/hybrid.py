"""Hybrid localisation: feature-based PnP and the rendered-view localiser, never worse than
either part.

Foster, Wang & Grupen (IV-B) pose a photo by SIFT matches and RANSAC PnP; Heigl et al.'s
rendered-view filter needs no features. The hybrid arbitrates:

- a strong PnP pose (enough inliers, and enough of the matches: `HybridConfig.strong`) is
  the answer as it is. The rendered likelihood of a proxy is a worse judge of a pose than
  dozens of consistent correspondences, so it must not drag a good PnP pose away;
- a weak PnP pose is one more starting point of the rendered localiser's Gauss-Newton
  alignment (beside the filter's modes), and the rendered verdict decides;
- without a PnP pose the rendered localiser runs alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ibr.camera import Camera
from localization.confidence import Verdict, pnp_verdict
from localization.feature_localizer import FeatureMap, PnPResult
from localization.pose6_filter import PriorBox
from localization.render_localizer import RenderModel, RenderResult, localize_by_rendering


@dataclass(frozen=True)
class HybridConfig:
    """Settings of `localize_hybrid`."""

    strong: tuple[int, float] = (40, 0.25)
    """A PnP pose with at least this many RANSAC inliers and this inlier share of its matches
    is taken as it is (counts of correspondences, independent of the scene's scale)."""


@dataclass
class HybridResult:
    """cam_from_world (4, 4) or None; verdict; source: "pnp" or "render"; pnp: the PnP result
    (None when it failed); render: the rendered localiser's result (None when not run)."""

    cam_from_world: np.ndarray | None
    verdict: Verdict
    source: str
    pnp: PnPResult | None
    render: RenderResult | None


def localize_hybrid(model: RenderModel, features: FeatureMap, image: np.ndarray, camera: Camera,
                    particles: np.ndarray, spread: tuple[float, float], rng: np.random.Generator,
                    prior: PriorBox | None = None, config: HybridConfig = HybridConfig(),
                    on_step=None) -> HybridResult:
    """Localise `image` (H, W, 3) uint8 (intrinsics of `camera`): PnP, then, unless its pose
    is strong, the rendered localiser from prior particles (N, 6) with the PnP pose as an
    extra start."""
    pnp = features.localize(image, camera)
    if pnp is not None:
        verdict = pnp_verdict(pnp.n_inliers, pnp.n_matches, config.strong)
        if verdict.localized:
            return HybridResult(pnp.cam_from_world, verdict, "pnp", pnp, None)
    starts = [] if pnp is None else [pnp.cam_from_world]
    render = localize_by_rendering(model, image, camera, particles, spread, rng, prior, starts, on_step)
    return HybridResult(render.cam_from_world, render.verdict, "render", pnp, render)
