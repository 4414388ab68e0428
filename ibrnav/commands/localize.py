"""`ibrnav localize` (one photo against a posed scene) and `ibrnav eval-loc` (leave-one-out
over a scene's photos): PnP, the 6-DoF rendered-view particle filter, or the hybrid."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import rerun as rr
from scipy.spatial.transform import Rotation

from ibr import viz as ibr_viz
from ibr.camera import Camera
from ibr.errors import InputError
from ibr.scene import load_scene, read_image
from localization import viz
from localization.eval_loc import METHODS, MODELS, LocConfig, SceneLocalizer, evaluate_localization
from localization.pose6_filter import cam_from_world_of, camera_at


def say(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def parse_floats(text: str, n: int, flag: str) -> np.ndarray:
    """'a,b,c' -> (n,) floats, or an InputError naming the flag."""
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        v = np.zeros(0)
    if len(v) != n or not np.all(np.isfinite(v)):
        raise InputError(f"{flag} {text!r}: expected {n} comma-separated numbers")
    return v


def query_camera(scene, image: np.ndarray, name: str | None, path: str) -> Camera:
    """Intrinsics for the query: the named view's, else the first view's (same size needed)."""
    cam = scene.view(name).camera if name else scene.views[0].camera
    if (image.shape[1], image.shape[0]) != (cam.width, cam.height):
        raise InputError(f"{path}: image is {image.shape[1]}x{image.shape[0]} but the scene's camera "
                         f"is {cam.width}x{cam.height}; pass --intrinsics-of a view of that size")
    return cam


def localize(args: argparse.Namespace) -> int:
    image = read_image(args.query)
    prior = None
    if args.prior:
        p = parse_floats(args.prior, 6, "--prior")
        p[3:] = np.radians(p[3:])
        prior = cam_from_world_of(p[None])[0]
    spread_m, spread_deg = parse_floats(args.spread, 2, "--spread")
    scene = load_scene(args.scene)
    camera = query_camera(scene, image, args.intrinsics_of, args.query)
    name = Path(args.query).name
    mapped = scene.without(name) if any(v.name == name for v in scene.views) else scene
    say(f"building the {args.method} map from {len(mapped)} photos")
    loc = SceneLocalizer(mapped, args.method, LocConfig(model=args.model))
    ibr_viz.rerun_setup(args, "ibrnav_localize", "localize.rrd")
    if loc.likelihood is not None:
        ibr_viz.log_mesh("world/map/mesh", loc.mesh)  # what the filter renders
    def on_step(k, particles, weights):
        rr.set_time("step", sequence=k)
        viz.log_pose6_particles(particles[:, :3], weights)
        if k % 5 == 0:
            say(f"  step {k}")
    res = loc.localize(image, camera, prior, spread_m, spread_deg, np.random.default_rng(args.seed), on_step)
    if res.cam_from_world is None:
        raise InputError(f"{args.query}: no pose found (too few feature inliers for PnP)")
    est = camera_at(camera, res.cam_from_world)
    viz.log_camera_pose("world/estimate", est, image)
    if loc.likelihood is not None:
        viz.log_observed_vs_rendered(image, loc.likelihood.model.render(est).color)
    ibr_viz.rerun_teardown(args)
    rv = Rotation.from_matrix(est.world_from_cam[:3, :3]).as_rotvec()
    print(json.dumps({"query": args.query, "method": args.method, "seconds": round(res.seconds, 3),
                      "center_m": est.center.round(4).tolist(), "rotvec_deg": np.degrees(rv).round(3).tolist(),
                      "cam_from_world": est.cam_from_world.round(6).tolist(), "n_inliers": res.n_inliers}, indent=2))
    return 0


def eval_loc(args: argparse.Namespace) -> int:
    scene = load_scene(args.scene)
    ibr_viz.rerun_setup(args, "ibrnav_eval_loc", "eval_loc.rrd")

    def on_trial(i, held, res, row):
        rr.set_time("step", sequence=i)
        viz.log_camera_pose("world/truth", held.camera, held.image)
        if res.cam_from_world is not None:
            viz.log_camera_pose("world/estimate", camera_at(held.camera, res.cam_from_world))
        if res.particles is not None:
            viz.log_pose6_particles(res.particles[:, :3], res.weights)
        rr.log("plots/position_error_m", rr.Scalars(min(row["position_m"], 10.0)))
        rr.log("plots/rotation_error_deg", rr.Scalars(min(row["rotation_deg"], 180.0)))

    out = evaluate_localization(scene, args.method, args.trials or len(scene), args.spread_m, args.spread_deg,
                                args.seed, LocConfig(model=args.model), say, on_trial)
    ibr_viz.rerun_teardown(args)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps({k: v for k, v in out.items() if k != "per_trial"}, indent=2))
    return 0


def add_model_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--model", choices=MODELS, default="auto",
                        help="what the particle filter renders: the proxy textured from the photos "
                        "(proxy), its vertex colours only (proxy-colors), the scene's own mesh (mesh); "
                        "auto: the mesh when the scene has one, else proxy")


def register(subparsers) -> None:
    p = subparsers.add_parser("localize", help="localise one photo against a posed scene (pnp, pf, hybrid)")
    p.add_argument("scene", help="Strecha/COLMAP folder or synthetic:NAME")
    p.add_argument("--query", required=True, help="the photo to localise")
    p.add_argument("--method", choices=METHODS, default="hybrid")
    p.add_argument("--intrinsics-of", help="scene view whose intrinsics the query shares (default: the first)")
    p.add_argument("--prior", help="x,y,z,rx,ry,rz: camera centre (m) and rotation vector of "
                   "world_from_cam (deg), e.g. --prior=-7,-7,0.2,-90,20,0; default: around every map photo")
    p.add_argument("--spread", default="1.0,30", help="M,DEG: prior spread (default 1.0,30)")
    p.add_argument("--seed", type=int, default=0)
    add_model_arg(p)
    ibr_viz.add_rerun_args(p)
    p.set_defaults(func=localize)

    e = subparsers.add_parser("eval-loc", help="leave-one-out localisation of a scene's photos")
    e.add_argument("scene", help="Strecha/COLMAP folder or synthetic:NAME")
    e.add_argument("--method", choices=METHODS, default="hybrid")
    e.add_argument("--trials", type=int, default=0, help="queries (cycling over the photos; 0: one per photo)")
    e.add_argument("--spread-m", type=float, default=1.0, help="prior position spread (m, per axis)")
    e.add_argument("--spread-deg", type=float, default=30.0, help="prior rotation spread (deg)")
    e.add_argument("--seed", type=int, default=0)
    e.add_argument("--json", help="write per-trial results and the summary here")
    add_model_arg(e)
    ibr_viz.add_rerun_args(e)
    e.set_defaults(func=eval_loc)
