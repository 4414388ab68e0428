"""`ibrnav render` / `ibrnav eval-ibr` end to end on a tiny synthetic scene, and the metrics."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
from PIL import Image

from ibr import render_cli
from ibr.errors import InputError
from ibr.eval_ibr import exposure_matched, psnr, ssim

SCENE = "synthetic:office?views=16&width=96&height=72"


def _run(*argv):
    parser = argparse.ArgumentParser()
    render_cli.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args([str(a) for a in argv])
    return args.func(args)


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


def test_eval_ibr_writes_leave_one_out_json(gl_ctx, tmp_path):
    out = tmp_path / "eval.json"
    assert _run("eval-ibr", SCENE, "--json", out, "--proxy", "mesh", "--max-views", 2) == 0
    result = json.loads(out.read_text())
    assert result["scene"] == "synthetic:office"
    assert set(result["methods"]) == {"ulr", "nearest", "lightfield", "lightfield_local"}
    for m, r in result["methods"].items():
        assert len(r["per_view"]) == 2 and 0.0 <= r["coverage_mean"] <= 1.0
        assert all("psnr_common" in row for row in r["per_view"]) and "psnr_common_mean" in r
    for m in ("ulr", "nearest"):  # (the office's outward-looking ring defeats the light field's net)
        r = result["methods"][m]
        assert r["coverage_mean"] > 0.1 and r["psnr_mean"] > 12.0 and 0.0 < r["ssim_mean"] <= 1.0
        assert r["psnr_exposure_mean"] >= r["psnr_mean"] - 0.1   # a fitted gain cannot hurt much
    assert result["methods"]["ulr"]["coverage_mean"] > result["methods"]["nearest"]["coverage_mean"]


def test_render_from_view_and_fly_through(gl_ctx, tmp_path):
    from ibr.scene import load_scene

    names = [v.name for v in load_scene(SCENE)][:2]
    img = tmp_path / "view.png"
    assert _run("render", SCENE, "--proxy", "mesh", "--from-view", names[0], "--hold-out", "--out", img) == 0
    assert Image.open(img).size == (96, 72)
    frames = tmp_path / "fly"
    assert _run("render", SCENE, "--proxy", "mesh", "--method", "lightfield", "--path", *names,
                "--frames", 2, "--out", frames, "--save", tmp_path / "fly.rrd") == 0
    assert sorted(p.name for p in frames.glob("*.png")) == ["frame_0000.png", "frame_0001.png", "frame_0002.png"]
    assert (tmp_path / "fly.rrd").stat().st_size > 0


def test_bad_inputs_are_named(tmp_path):
    with pytest.raises(InputError, match="no view"):
        _run("render", SCENE, "--proxy", "mesh", "--from-view", "nope", "--out", tmp_path / "x.png")
    with pytest.raises(InputError, match="camera file not found"):
        _run("render", SCENE, "--proxy", "mesh", "--camera", tmp_path / "missing.camera", "--out", tmp_path / "x.png")
    bad_camera = tmp_path / "bad.camera"
    bad_camera.write_text("1 2 3\n")
    with pytest.raises(InputError, match="bad.camera"):
        _run("render", SCENE, "--proxy", "mesh", "--camera", bad_camera, "--out", tmp_path / "x.png")


@pytest.mark.parametrize("argv, message", [
    (("--k", 0), "--k 0"),
    (("--scale", -1), "--scale -1"),
    (("--out", "{tmp}/x.txt"), "unknown image type"),
    (("--out", "{tmp}/missing/x.png"), "does not exist"),
    (("--out", "{tmp}"), "is a folder"),
])
def test_bad_render_arguments_fail_before_any_work(tmp_path, argv, message):
    argv = [str(a).format(tmp=tmp_path) for a in argv]
    base = {"--out": str(tmp_path / "x.png")}
    for flag, value in zip(argv[::2], argv[1::2]):
        base[flag] = value
    extra = [a for kv in base.items() for a in kv]
    with pytest.raises(InputError, match=message):
        _run("render", "/nonexistent/scene", "--from-view", "v", *extra)


def test_bad_eval_arguments_fail_before_any_work(tmp_path):
    with pytest.raises(InputError, match="--json"):
        _run("eval-ibr", "/nonexistent/scene", "--json", tmp_path / "missing" / "e.json")
    with pytest.raises(InputError, match="--frames 0"):
        _run("render", "/nonexistent/scene", "--path", "a", "b", "--frames", 0, "--out", tmp_path / "f")


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
    from ibr.eval_ibr import EvalConfig, evaluate_scene
    from ibr.scene import load_scene

    scene = load_scene(SCENE)
    full, half = (evaluate_scene(scene, EvalConfig(methods=("ulr",), proxy="mesh", max_views=1, scale=s))
                  for s in (1.0, 0.5))
    f, h = full["methods"]["ulr"], half["methods"]["ulr"]
    assert abs(f["coverage_mean"] - h["coverage_mean"]) < 0.05 and h["psnr_mean"] > 12.0
    with pytest.raises(InputError, match="--scale 0"):
        _run("eval-ibr", SCENE, "--json", "/tmp/unused.json", "--scale", 0)
