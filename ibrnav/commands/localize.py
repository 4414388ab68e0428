"""`ibrnav localize SCENE --query PHOTO`: localise one photo against a posed scene with PnP,
the rendered-view localiser, or the hybrid; the pose and the verdict are printed as JSON.
A query that is not localised prints its reason (and only a best guess, not a pose) and
exits with status 1."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np

from ibr.errors import InputError
from ibrnav import jsonout, recording
from ibrnav.commands.scene import SCENE_HELP
from localization.localize import METHODS, MODELS

log = logging.getLogger(__name__)


def parse_floats(text: str, n: int, flag: str) -> np.ndarray:
    """'a,b,c' -> (n,) floats, or an InputError naming the flag."""
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        v = np.zeros(0)
    if len(v) != n or not np.all(np.isfinite(v)):
        raise InputError(f"{flag} {text!r}: expected {n} comma-separated numbers")
    return v


def query_camera(scene, image: np.ndarray, name: str | None, path: str):
    """Intrinsics for the query: the named view's, else the first view's (same size needed)."""
    cam = scene.view(name).camera if name else scene.views[0].camera
    if (image.shape[1], image.shape[0]) != (cam.width, cam.height):
        raise InputError(f"{path}: image is {image.shape[1]}x{image.shape[0]} but the scene's camera "
                         f"is {cam.width}x{cam.height}; pass --intrinsics-of a view of that size")
    return cam


def run(args: argparse.Namespace) -> int:
    import rerun as rr
    from scipy.spatial.transform import Rotation

    from ibr import viz as ibr_viz
    from ibr.progress import counter
    from ibr.scene import load_scene, read_image
    from localization import viz
    from localization.localize import LocConfig, SceneLocalizer
    from localization.pose6_filter import cam_from_world_of, camera_at

    image = read_image(args.query)
    prior = None
    if args.prior:
        p = parse_floats(args.prior, 6, "--prior")
        p[3:] = np.radians(p[3:])
        prior = cam_from_world_of(p[None])[0]
    spread_m, spread_deg = parse_floats(args.spread, 2, "--spread")
    scene = load_scene(args.scene)
    camera = query_camera(scene, image, args.intrinsics_of, args.query)
    query = Path(args.query).resolve()  # one of the scene's own photos is left out of its map
    same = [v.name for v in scene.views if v.name == query.name or (v.path is not None and v.path.resolve() == query)]
    mapped = scene.without(same[0]) if same else scene
    log.info(f"building the {args.method} map from {len(mapped)} photos")
    loc = SceneLocalizer(mapped, args.method, LocConfig(model=args.model))
    recording.rerun_setup(args, "ibrnav_localize", "localize.rrd")
    if loc.model is not None:
        ibr_viz.log_mesh("world/map/mesh", loc.model.fine.mesh)  # what the filter renders
    steps = counter(loc.config.render.filter.steps, "filter steps", log)

    def on_step(k, particles, weights):
        rr.set_time("step", sequence=k)
        viz.log_pose6_particles(particles[:, :3], weights)
        steps.update()
    res = loc.localize(image, camera, prior, spread_m, spread_deg, np.random.default_rng(args.seed), on_step)
    steps.close()
    out = {"query": args.query, "method": args.method, "seconds": round(res.seconds, 3),
           **res.verdict.as_dict(), "source": res.source, "n_inliers": res.n_inliers}
    if res.cam_from_world is not None:
        est = camera_at(camera, res.cam_from_world)
        viz.log_camera_pose("world/estimate", est, image)
        if loc.model is not None:
            viz.log_observed_vs_rendered(image, loc.model.fine.renderer.render(est).color)
        rv = Rotation.from_matrix(est.world_from_cam[:3, :3]).as_rotvec()
        out.update({"center_m": est.center.round(4).tolist(), "rotvec_deg": np.degrees(rv).round(3).tolist(),
                    "cam_from_world": est.cam_from_world.round(6).tolist()})
    recording.rerun_teardown(args)
    if not res.localized:  # a best guess is not a pose: say so instead of printing one
        out.pop("center_m", None), out.pop("rotvec_deg", None)
        out["best_guess_cam_from_world"] = out.pop("cam_from_world", None)
        log.warning(f"{args.query}: not localised: {res.verdict.reason}")
    print(jsonout.dumps(out))
    return 0 if res.localized else 1


def add_model_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--model", choices=MODELS, default="proxy",
                        help="what the rendered-view localiser renders: the proxy from the photos, "
                        "textured from them with a per-face trust (proxy), its vertex colours only "
                        "(proxy-colors), or the scene's own mesh (mesh, e.g. a synthetic world's true "
                        "mesh) (default: %(default)s)")


def register(subparsers) -> None:
    p = subparsers.add_parser("localize", help="localise one photo against a posed scene (pnp, pf, hybrid)")
    p.add_argument("scene", help=SCENE_HELP)
    p.add_argument("--query", required=True, help="the photo to localise")
    p.add_argument("--method", choices=METHODS, default="hybrid",
                   help="feature PnP, rendered-view particle filter, or PnP then the filter")
    p.add_argument("--intrinsics-of", help="scene view whose intrinsics the query shares (default: the first)")
    p.add_argument("--prior", help="x,y,z,rx,ry,rz: camera centre (m) and rotation vector of "
                   "world_from_cam (deg), e.g. --prior=-7,-7,0.2,-90,20,0; default: around every map photo")
    p.add_argument("--spread", default="1.0,30", help="M,DEG: prior spread")
    p.add_argument("--seed", type=int, default=0, help="seed of the particle filter")
    add_model_arg(p)
    recording.add_rerun_args(p)
    p.set_defaults(func=run)
