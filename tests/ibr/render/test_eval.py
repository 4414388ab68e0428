"""The image metrics of the renderers' evaluation (PSNR, SSIM, exposure matching) and the
leave-one-out evaluation at a reduced scale, on a tiny synthetic scene."""

from __future__ import annotations

import numpy as np
import pytest

from ibr.render.eval import exposure_matched, psnr, ssim

SCENE = "synthetic:office?views=16&width=96&height=72"


def test_psnr_and_ssim_known_answers():
    rng = np.random.default_rng(0)
    a = rng.integers(0, 256, (40, 50, 3)).astype(np.uint8)
    mask = np.ones((40, 50), bool)
    b = np.clip(a.astype(int) + rng.choice([-4, 4], a.shape), 0, 255).astype(np.uint8)
    mse = np.mean((a.astype(float) - b) ** 2)
    assert psnr(a, b, mask) == pytest.approx(10 * np.log10(255 ** 2 / mse))
    assert ssim(a, a, mask) == pytest.approx(1.0)
    assert 0.5 < ssim(a, b, mask) < 1.0
    assert ssim(a, 255 - a, mask) < 0.0
    assert np.isnan(psnr(a, b, np.zeros_like(mask)))


def test_exposure_matching_takes_out_a_gain_only():
    rng = np.random.default_rng(1)
    photo = rng.integers(20, 200, (30, 40, 3)).astype(np.uint8)
    darker = np.round(photo * np.array([0.8, 0.85, 0.9])).astype(np.uint8)
    mask = np.ones((30, 40), bool)
    assert psnr(darker, photo, mask) < 25.0
    assert psnr(exposure_matched(darker, photo, mask), photo, mask) > 45.0
    shuffled = darker[rng.permutation(30)]                   # wrong content stays wrong
    assert psnr(exposure_matched(shuffled, photo, mask), photo, mask) < 15.0


def test_eval_at_half_resolution_compares_like_sized_images(gl_ctx):
    from ibr.render.eval import EvalConfig, evaluate_scene
    from ibr.scene import load_scene

    scene = load_scene(SCENE)
    full, half = (evaluate_scene(scene, EvalConfig(methods=("ulr",), proxy="mesh", max_views=1, scale=s))
                  for s in (1.0, 0.5))
    f, h = full["methods"]["ulr"], half["methods"]["ulr"]
    assert abs(f["coverage_mean"] - h["coverage_mean"]) < 0.05 and h["psnr_mean"] > 12.0
