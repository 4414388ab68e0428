"""`ibrnav eval-ibr SCENE --json OUT`: leave-one-out PSNR / SSIM / coverage of the
image-based renderers (`ibr.render.eval`); the per-method means are printed."""

from __future__ import annotations

import argparse
from pathlib import Path


from ibr.render.renderers import METHODS, PROXIES
from ibrnav import jsonout
from ibrnav.commands.render import RenderArgsError
from ibrnav.commands.scene import SCENE_HELP


def run(args: argparse.Namespace) -> int:
    from ibr.render.eval import EvalConfig, evaluate_scene
    from ibr.render.ulr import MAX_K
    from ibr.scene import load_scene

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
    result = evaluate_scene(scene, cfg)
    jsonout.write(args.json, result)
    for m, r in result["methods"].items():
        print(f"{m:17s} PSNR {r['psnr_mean']:6.2f} dB  SSIM {r['ssim_mean']:.3f}  coverage {r['coverage_mean']:.3f}"
              f"  PSNR on common pixels {r['psnr_common_mean']:6.2f} dB, exposure-matched {r['psnr_exposure_mean']:6.2f} dB")
    return 0


def register(subparsers) -> None:
    e = subparsers.add_parser("eval-ibr", help="leave-one-out PSNR/SSIM/coverage of the renderers")
    e.add_argument("scene", help=SCENE_HELP)
    e.add_argument("--json", required=True, help="write the results here")
    e.add_argument("--methods", nargs="+", choices=list(dict.fromkeys([m.replace("_", "-") for m in METHODS] + list(METHODS))),
                   default=list(METHODS), help="the renderers to evaluate")
    e.add_argument("--proxy", choices=PROXIES, default="photos",
                   help="proxy from the other photos, plus plane-sweep points, or the scene's mesh")
    e.add_argument("--max-views", type=int, default=0, help="evaluate only the first N views (0 = all)")
    e.add_argument("--k", type=int, default=4, help="sources blended per pixel by ULR")
    e.add_argument("--scale", type=float, default=1.0,
                   help="render and compare at this fraction of the photos' resolution")
    e.set_defaults(func=run)
