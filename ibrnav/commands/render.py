"""`ibrnav render` (novel views and fly-throughs), `ibrnav eval-ibr` (leave-one-out) and
`ibrnav sfm` (poses for unposed photos)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from PIL import Image
from scipy.spatial.transform import Rotation, Slerp

from ibr import viz
from ibr.camera import Camera, rigid
from ibr.errors import InputError
from ibr.eval_ibr import METHODS, EvalConfig, evaluate_scene, make_renderers, proxy_mesh, stderr_progress
from ibr.scene import Scene, load_scene
from ibr.ulr import MAX_K

CLI_METHODS = ("ulr", "nearest", "lightfield", "lightfield-local")


class RenderArgsError(InputError):
    """Bad `ibrnav render` arguments (camera file, path, output)."""


def interpolate_cameras(a: Camera, b: Camera, n: int) -> list[Camera]:
    """n cameras from a to b (b excluded): centres linear, rotations slerped, a's intrinsics."""
    R = Rotation.from_matrix(np.stack([a.world_from_cam[:3, :3], b.world_from_cam[:3, :3]]))
    slerp = Slerp([0.0, 1.0], R)
    cams = []
    for t in np.arange(n) / n:
        world_from_cam = rigid(slerp([t]).as_matrix()[0], (1 - t) * a.center + t * b.center)
        cams.append(a.with_pose(np.linalg.inv(world_from_cam), name=f"{a.name}->{b.name}@{t:.2f}"))
    return cams


def fly_through(scene: Scene, names: list[str], frames_per_segment: int) -> list[Camera]:
    """Cameras along the named views in order (the last one included)."""
    if len(names) < 2:
        raise RenderArgsError("--path needs at least two view names")
    views = [scene.view(n).camera for n in names]
    cams = [c for a, b in zip(views, views[1:]) for c in interpolate_cameras(a, b, frames_per_segment)]
    return cams + [views[-1]]


def target_cameras(args, scene: Scene) -> list[Camera]:
    if args.camera:
        path = Path(args.camera)
        if not path.is_file():
            raise RenderArgsError(f"{path}: camera file not found")
        return [Camera.from_strecha_file(path, name=path.stem)]
    if args.from_view:
        return [scene.view(args.from_view).camera]
    return fly_through(scene, args.path, args.frames)


IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")


def check_render_args(args: argparse.Namespace) -> None:
    """Reject bad numbers and unwritable outputs before any heavy work (one clear line)."""
    if not 1 <= args.k <= MAX_K:
        raise RenderArgsError(f"--k {args.k}: must be in 1..{MAX_K}")
    if not args.scale > 0:
        raise RenderArgsError(f"--scale {args.scale}: must be > 0")
    if args.frames < 1:
        raise RenderArgsError(f"--frames {args.frames}: must be at least 1")
    out = Path(args.out)
    if args.path:
        if out.exists() and not out.is_dir():
            raise RenderArgsError(f"--out {out}: with --path this is a folder of frames, but a file is there")
        if not out.parent.is_dir():
            raise RenderArgsError(f"--out {out}: parent folder {out.parent} does not exist")
        return
    if out.is_dir():
        raise RenderArgsError(f"--out {out}: is a folder; give an image file name (.png, .jpg, ...)")
    if out.suffix.lower() not in IMAGE_SUFFIXES:
        raise RenderArgsError(f"--out {out}: unknown image type; use one of {', '.join(IMAGE_SUFFIXES)}")
    if not out.parent.is_dir():
        raise RenderArgsError(f"--out {out}: folder {out.parent} does not exist")


def render(args: argparse.Namespace) -> int:
    check_render_args(args)
    scene = load_scene(args.scene)
    cams = target_cameras(args, scene)
    sources = scene
    if args.hold_out and args.from_view:
        sources = scene.without(args.from_view)
    if args.proxy != "mesh":
        print(f"{scene.name}: proxy geometry from {len(sources)} photos (cached beside the scene after the "
              f"first run)", file=sys.stderr, flush=True)
    mesh = proxy_mesh(sources, args.proxy)
    method = args.method.replace("-", "_")
    renderer = make_renderers(sources, mesh, [method], args.k)[method]
    out = Path(args.out)
    if len(cams) > 1:
        out.mkdir(parents=True, exist_ok=True)
        viz.rerun_setup(args, "ibrnav_render", str(out / "render.rrd"))
    for i, cam in enumerate(cams):
        cam = cam.scaled(args.scale) if args.scale != 1 else cam
        image, covered = renderer.render(cam)
        target = out / f"frame_{i:04d}.png" if len(cams) > 1 else out
        Image.fromarray(image).save(target)
        print(f"{target}: {cam.width}x{cam.height}, covered {covered.mean():.3f}", file=sys.stderr)
        if len(cams) > 1:
            from ibr.viz_ibr import log_render
            log_render(cam, image, covered, method, i)
    if len(cams) > 1:
        viz.rerun_teardown(args)
    renderer.release()
    return 0


def json_safe(x):
    """The result with NaN/inf floats (a method that covered nothing) written as null."""
    if isinstance(x, dict):
        return {k: json_safe(v) for k, v in x.items()}
    if isinstance(x, list):
        return [json_safe(v) for v in x]
    return None if isinstance(x, float) and not np.isfinite(x) else x


def eval_ibr(args: argparse.Namespace) -> int:
    if not 1 <= args.k <= MAX_K:
        raise RenderArgsError(f"--k {args.k}: must be in 1..{MAX_K}")
    if args.max_views < 0:
        raise RenderArgsError(f"--max-views {args.max_views}: must be >= 0")
    if not 0 < args.scale <= 1:
        raise RenderArgsError(f"--scale {args.scale}: must be in (0, 1]")
    out = Path(args.json)
    if out.is_dir() or not out.parent.is_dir():
        raise RenderArgsError(f"--json {out}: not a writable file path (folder missing or a folder given)")
    scene = load_scene(args.scene)
    cfg = EvalConfig(methods=tuple(m.replace("-", "_") for m in args.methods), proxy=args.proxy,
                     max_views=args.max_views, k=args.k, scale=args.scale)
    result = evaluate_scene(scene, cfg, stderr_progress)
    text = json.dumps(json_safe(result), indent=2, allow_nan=False)
    Path(args.json).write_text(text)
    for m, r in result["methods"].items():
        print(f"{m:17s} PSNR {r['psnr_mean']:6.2f} dB  SSIM {r['ssim_mean']:.3f}  coverage {r['coverage_mean']:.3f}"
              f"  PSNR on common pixels {r['psnr_common_mean']:6.2f} dB, exposure-matched {r['psnr_exposure_mean']:6.2f} dB")
    return 0


def sfm(args: argparse.Namespace) -> int:
    from ibr.sfm import load_unposed

    scene = load_unposed(args.folder)
    print(f"{args.folder}: {len(scene)} photos posed, {0 if scene.points is None else len(scene.points)} points "
          f"-> {Path(args.folder) / 'sparse' / '0'}")
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("render", help="render novel views of a scene (ULR, light field, nearest view)")
    p.add_argument("scene", help="a Strecha folder, a COLMAP model folder or synthetic:NAME[?...]")
    p.add_argument("--method", choices=CLI_METHODS, default="ulr")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--camera", help="a Strecha .camera file of the virtual camera")
    where.add_argument("--from-view", help="render at this view's camera")
    where.add_argument("--path", nargs="+", metavar="VIEW", help="fly through these views (PNG frames + rerun)")
    p.add_argument("--out", required=True, help="output image (or folder of frames with --path)")
    p.add_argument("--frames", type=int, default=10, help="frames per path segment (default 10)")
    p.add_argument("--hold-out", action="store_true", help="with --from-view: leave that photo out of the sources")
    p.add_argument("--scale", type=float, default=1.0, help="output resolution factor (default 1)")
    p.add_argument("--proxy", choices=("photos", "dense", "mesh"), default="photos",
                   help="proxy triangulated from the photos (default), plus plane-sweep points "
                        "(dense), or the scene's own mesh (synthetic scenes)")
    p.add_argument("--k", type=int, default=4, help="sources blended per pixel by ULR (default 4)")
    viz.add_rerun_args(p)
    p.set_defaults(func=render)

    e = subparsers.add_parser("eval-ibr", help="leave-one-out PSNR/SSIM/coverage of the renderers")
    e.add_argument("scene", help="a Strecha folder, a COLMAP model folder or synthetic:NAME[?...]")
    e.add_argument("--json", required=True, help="write the results here")
    e.add_argument("--methods", nargs="+", choices=list(dict.fromkeys([m.replace("_", "-") for m in METHODS] + list(METHODS))),
                   default=list(METHODS))
    e.add_argument("--proxy", choices=("photos", "dense", "mesh"), default="photos",
                   help="proxy from the other photos (default), plus plane-sweep points, or the scene's mesh")
    e.add_argument("--max-views", type=int, default=0, help="evaluate only the first N views (0 = all)")
    e.add_argument("--k", type=int, default=4, help="sources blended per pixel by ULR (default 4)")
    e.add_argument("--scale", type=float, default=1.0,
                   help="render and compare at this fraction of the photos' resolution (default 1)")
    e.set_defaults(func=eval_ibr)

    f = subparsers.add_parser("sfm", help="pose unposed photos (FOLDER/images) with COLMAP via pycolmap")
    f.add_argument("folder", help="a folder with images/; the model is written to FOLDER/sparse/0")
    f.set_defaults(func=sfm)
