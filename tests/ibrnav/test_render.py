"""`ibrnav render` and `ibrnav eval-ibr` end to end on a tiny synthetic scene; bad flags are
named before any heavy work."""

from __future__ import annotations

import json

import pytest
from PIL import Image

from ibr.errors import InputError

SCENE = "synthetic:office?views=16&width=96&height=72"


def test_eval_ibr_writes_leave_one_out_json(ibrnav_command, gl_ctx, tmp_path):
    out = tmp_path / "eval.json"
    assert ibrnav_command("eval-ibr", SCENE, "--json", out, "--proxy", "mesh", "--max-views", 2) == 0
    result = json.loads(out.read_text())
    assert result["scene"] == "synthetic:office"
    assert set(result["methods"]) == {"ulr", "ulr_pixel", "nearest", "lightfield", "lightfield_local"}
    for m, r in result["methods"].items():
        assert len(r["per_view"]) == 2 and 0.0 <= r["coverage_mean"] <= 1.0
        assert all("psnr_common" in row for row in r["per_view"]) and "psnr_common_mean" in r
    for m in ("ulr", "nearest"):  # (the office's outward-looking ring defeats the light field's net)
        r = result["methods"][m]
        assert r["coverage_mean"] > 0.1 and r["psnr_mean"] > 12.0 and 0.0 < r["ssim_mean"] <= 1.0
        assert r["psnr_exposure_mean"] >= r["psnr_mean"] - 0.1   # a fitted gain cannot hurt much
    assert result["methods"]["ulr"]["coverage_mean"] > result["methods"]["nearest"]["coverage_mean"]


def test_render_from_view_and_fly_through(ibrnav_command, gl_ctx, tmp_path):
    from ibr.scene import load_scene

    names = [v.name for v in load_scene(SCENE)][:2]
    img = tmp_path / "view.png"
    assert ibrnav_command("render", SCENE, "--proxy", "mesh", "--from-view", names[0], "--hold-out", "--out", img) == 0
    assert Image.open(img).size == (96, 72)
    frames = tmp_path / "fly"
    assert ibrnav_command("render", SCENE, "--proxy", "mesh", "--method", "lightfield", "--path", *names,
                "--frames", 2, "--out", frames, "--save", tmp_path / "fly.rrd") == 0
    assert sorted(p.name for p in frames.glob("*.png")) == ["frame_0000.png", "frame_0001.png", "frame_0002.png"]
    assert (tmp_path / "fly.rrd").stat().st_size > 0


def test_bad_inputs_are_named(ibrnav_command, tmp_path):
    with pytest.raises(InputError, match="no view"):
        ibrnav_command("render", SCENE, "--proxy", "mesh", "--from-view", "nope", "--out", tmp_path / "x.png")
    with pytest.raises(InputError, match="camera file not found"):
        ibrnav_command("render", SCENE, "--proxy", "mesh", "--camera", tmp_path / "missing.camera", "--out", tmp_path / "x.png")
    bad_camera = tmp_path / "bad.camera"
    bad_camera.write_text("1 2 3\n")
    with pytest.raises(InputError, match="bad.camera"):
        ibrnav_command("render", SCENE, "--proxy", "mesh", "--camera", bad_camera, "--out", tmp_path / "x.png")


@pytest.mark.parametrize("argv, message", [
    (("--k", 0), "--k 0"),
    (("--scale", -1), "--scale -1"),
    (("--out", "{tmp}/x.txt"), "unknown image type"),
    (("--out", "{tmp}/missing/x.png"), "does not exist"),
    (("--out", "{tmp}"), "is a folder"),
])
def test_bad_render_arguments_fail_before_any_work(ibrnav_command, tmp_path, argv, message):
    argv = [str(a).format(tmp=tmp_path) for a in argv]
    base = {"--out": str(tmp_path / "x.png")}
    for flag, value in zip(argv[::2], argv[1::2]):
        base[flag] = value
    extra = [a for kv in base.items() for a in kv]
    with pytest.raises(InputError, match=message):
        ibrnav_command("render", "/nonexistent/scene", "--from-view", "v", *extra)


def test_bad_eval_arguments_fail_before_any_work(ibrnav_command, tmp_path):
    with pytest.raises(InputError, match="--json"):
        ibrnav_command("eval-ibr", "/nonexistent/scene", "--json", tmp_path / "missing" / "e.json")
    with pytest.raises(InputError, match="--frames 0"):
        ibrnav_command("render", "/nonexistent/scene", "--path", "a", "b", "--frames", 0, "--out", tmp_path / "f")


def test_bad_eval_scale_fails_before_any_work(ibrnav_command):
    with pytest.raises(InputError, match="--scale 0"):
        ibrnav_command("eval-ibr", SCENE, "--json", "/tmp/unused.json", "--scale", 0)
