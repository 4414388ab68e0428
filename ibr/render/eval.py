"""Leave-one-out evaluation of the image-based renderers: for each photo of a scene, build
the model (proxy geometry, source depth maps) from the *other* photos, render at the held-out
photo's true camera with every method, and compare with the photo over the pixels the method
covers (PSNR, SSIM) together with the covered fraction.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter

from ibr.progress import progress
from ibr.render.renderers import METHODS, RendererError, make_renderers, proxy_mesh
from ibr.scene import Scene

log = logging.getLogger(__name__)


class EvalError(RendererError):
    """Bad evaluation request (unknown method, too few views, no mesh for --proxy mesh)."""


def psnr(image: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> float:
    """PSNR (dB) of uint8 images (H, W, 3) over the pixels of `mask` (H, W); nan if empty."""
    if not mask.any():
        return float("nan")
    mse = np.mean((image[mask].astype(np.float64) - reference[mask]) ** 2)
    return float("inf") if mse == 0 else float(10 * np.log10(255.0 ** 2 / mse))


def exposure_matched(image: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """`image` (H, W, 3) uint8 times the per-channel gain that best fits it to `reference` over
    `mask` in least squares (g = sum(a b) / sum(a a)), rounded back to uint8: takes out a
    difference in exposure / white balance between the photos, which no renderer can know."""
    if not mask.any():
        return image
    a, b = image[mask].astype(np.float64), reference[mask].astype(np.float64)
    gain = (a * b).sum(axis=0) / np.maximum((a * a).sum(axis=0), 1e-12)
    return np.clip(np.round(image * gain), 0, 255).astype(np.uint8)


def ssim(image: np.ndarray, reference: np.ndarray, mask: np.ndarray, sigma: float = 1.5) -> float:
    """Mean SSIM (Wang et al. 2004; Gaussian window sigma 1.5 px, K1 = 0.01, K2 = 0.03, on each
    colour channel) over the pixels of `mask`; nan if empty."""
    if not mask.any():
        return float("nan")
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2
    a, b = image.astype(np.float64), reference.astype(np.float64)
    blur = lambda x: gaussian_filter(x, (sigma, sigma, 0))  # noqa: E731
    mu_a, mu_b = blur(a), blur(b)
    var_a, var_b = blur(a * a) - mu_a ** 2, blur(b * b) - mu_b ** 2
    cov = blur(a * b) - mu_a * mu_b
    s = ((2 * mu_a * mu_b + c1) * (2 * cov + c2)) / ((mu_a ** 2 + mu_b ** 2 + c1) * (var_a + var_b + c2))
    return float(s.mean(axis=2)[mask].mean())


@dataclass(frozen=True)
class EvalConfig:
    """Settings of `evaluate_scene`."""

    methods: tuple[str, ...] = METHODS
    """Renderers to compare (subset of METHODS)."""
    proxy: str = "photos"
    """"photos": proxy triangulated from the other photos; "dense": also with plane-sweep
    points (`ibr.proxy.dense_points`); "mesh": the scene's own mesh."""
    max_views: int = 0
    """Evaluate only the first this many held-out views (0 = all)."""
    k: int = 4
    """Sources blended per pixel by ULR."""
    scale: float = 1.0
    """Render and compare at this fraction of the photos' resolution (the held-out photo is
    area-downsampled; the proxy and the sources stay at full resolution)."""


def evaluate_scene(scene: Scene, cfg: EvalConfig = EvalConfig()) -> dict:
    """Leave-one-out PSNR / SSIM / coverage of each method; the JSON-ready result
    {"scene", "proxy", "methods": {m: {"psnr_mean", "ssim_mean", "coverage_mean",
    "psnr_common_mean", "per_view"}}}. PSNR and SSIM are over the pixels each method covers
    (so covering harder pixels costs PSNR); psnr_common is over the pixels every compared
    method covers in that view, the like-for-like comparison; psnr_exposure is over the
    covered pixels after `exposure_matched` (the Strecha photos differ in exposure by up to
    ~25%, which favours whichever method happens to copy a photo exposed like the held-out one)."""
    unknown = set(cfg.methods) - set(METHODS)
    if unknown:
        raise EvalError(f"unknown method(s) {sorted(unknown)}; choose from {list(METHODS)}")
    if len(scene) < 3:
        raise EvalError(f"scene {scene.name!r} has {len(scene)} views; leave-one-out needs at least 3")
    if cfg.proxy == "mesh" and scene.mesh is None:
        raise EvalError(f"scene {scene.name!r} has no mesh; use --proxy photos")
    per = {m: [] for m in cfg.methods}
    views = scene.views[: cfg.max_views] if cfg.max_views else scene.views
    for n, held in enumerate(progress(views, desc="held-out views", logger=log)):
        sources = scene.without(held.name)
        log.info(f"[{n + 1}/{len(views)}] {held.name}: proxy from {len(sources)} photos")
        mesh = proxy_mesh(sources, cfg.proxy)
        camera, photo = at_scale(held.camera, held.image, cfg.scale)
        renders = {}
        for m, r in make_renderers(sources, mesh, cfg.methods, cfg.k).items():
            renders[m] = r.render(camera)
            r.release()
        common = np.logical_and.reduce([covered for _, covered in renders.values()])
        for m, (image, covered) in renders.items():
            row = {"view": held.name, "psnr": psnr(image, photo, covered),
                   "ssim": ssim(image, photo, covered), "coverage": float(covered.mean()),
                   "psnr_common": psnr(image, photo, common),
                   "psnr_exposure": psnr(exposure_matched(image, photo, covered), photo, covered)}
            per[m].append(row)
            log.info(f"    {m:17s} PSNR {row['psnr']:6.2f} dB  SSIM {row['ssim']:.3f}  coverage {row['coverage']:.3f}"
                f"  (PSNR {row['psnr_common']:6.2f} dB on the {common.mean():.3f} all methods cover)")
    return {"scene": scene.name, "proxy": cfg.proxy, "methods": {m: summarise(rows) for m, rows in per.items()}}


def at_scale(camera, image: np.ndarray, scale: float):
    """The camera at `scale` x its resolution and its photo (H, W, 3) uint8 area-resampled to it."""
    if scale == 1.0:
        return camera, image
    cam = camera.scaled(scale)
    return cam, cv2.resize(image, (cam.width, cam.height), interpolation=cv2.INTER_AREA)


def summarise(rows: list[dict]) -> dict:
    """Means over the views with a finite score (PSNR is nan where nothing was covered)."""
    def mean(key):
        v = np.array([r[key] for r in rows], dtype=np.float64)
        v = v[np.isfinite(v)]
        return float(v.mean()) if len(v) else float("nan")
    return {"psnr_mean": mean("psnr"), "ssim_mean": mean("ssim"), "coverage_mean": mean("coverage"),
            "psnr_common_mean": mean("psnr_common"), "psnr_exposure_mean": mean("psnr_exposure"),
            "per_view": rows}

