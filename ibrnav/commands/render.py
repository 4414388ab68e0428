"""`ibrnav render SCENE`: novel views of a scene (ULR, light field, nearest view) at a camera
file, at a view's camera, or along a fly-through of views (PNG frames and a rerun recording)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from ibr.errors import InputError
from ibrnav import recording
from ibrnav.commands.scene import SCENE_HELP

CLI_METHODS = ("ulr", "ulr-pixel", "nearest", "lightfield", "lightfield-local")
log = logging.getLogger(__name__)


class RenderArgsError(InputError):
    """Bad `ibrnav render` arguments (camera file, path, output)."""


def target_cameras(args, scene) -> list:
    from ibr.camera import Camera
    from ibr.render.camera_paths import fly_through

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
    from ibr.render.ulr import MAX_K

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


def run(args: argparse.Namespace) -> int:
    from PIL import Image

    from ibr.render.renderers import make_renderers, proxy_mesh
    from ibr.progress import progress
    from ibr.render.viz import log_render
    from ibr.scene import load_scene

    check_render_args(args)
    scene = load_scene(args.scene)
    cams = target_cameras(args, scene)
    sources = scene
    if args.hold_out and args.from_view:
        sources = scene.without(args.from_view)
    if args.proxy != "mesh":
        log.info(f"{scene.name}: proxy geometry from {len(sources)} photos (cached beside the scene after the "
                 "first run)")
    mesh = proxy_mesh(sources, args.proxy)
    method = args.method.replace("-", "_")
    renderer = make_renderers(sources, mesh, [method], args.k)[method]
    out = Path(args.out)
    if len(cams) > 1:
        out.mkdir(parents=True, exist_ok=True)
        recording.rerun_setup(args, "ibrnav_render", str(out / "render.rrd"))
    for i, cam in enumerate(progress(cams, desc="frames", logger=log)):
        cam = cam.scaled(args.scale) if args.scale != 1 else cam
        image, covered = renderer.render(cam)
        target = out / f"frame_{i:04d}.png" if len(cams) > 1 else out
        Image.fromarray(image).save(target)
        log.info(f"{target}: {cam.width}x{cam.height}, covered {covered.mean():.3f}")
        if len(cams) > 1:
            log_render(cam, image, covered, method, i)
    if len(cams) > 1:
        recording.rerun_teardown(args)
    renderer.release()
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("render", help="render novel views of a scene (ULR, light field, nearest view)")
    p.add_argument("scene", help=SCENE_HELP)
    p.add_argument("--method", choices=CLI_METHODS, default="ulr",
                   help="the renderer (ulr: Buehler's blending field; ulr-pixel: its weights at every pixel)")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--camera", help="a Strecha .camera file of the virtual camera")
    where.add_argument("--from-view", help="render at this view's camera")
    where.add_argument("--path", nargs="+", metavar="VIEW", help="fly through these views (PNG frames + rerun)")
    p.add_argument("--out", required=True, help="output image (or folder of frames with --path)")
    p.add_argument("--frames", type=int, default=10, help="frames per path segment")
    p.add_argument("--hold-out", action="store_true", help="with --from-view: leave that photo out of the sources")
    p.add_argument("--scale", type=float, default=1.0, help="output resolution factor")
    p.add_argument("--proxy", choices=("photos", "dense", "mesh"), default="photos",
                   help="proxy triangulated from the photos, plus plane-sweep points "
                        "(dense), or the scene's own mesh (synthetic scenes)")
    p.add_argument("--k", type=int, default=4, help="sources blended per pixel by ULR")
    recording.add_rerun_args(p)
    p.set_defaults(func=run)
