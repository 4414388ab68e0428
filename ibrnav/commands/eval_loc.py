"""`ibrnav eval-loc SCENE`: leave-one-out localisation of a scene's photos (`localization.eval`);
the summary is printed as JSON, per-trial rows go to --json."""

from __future__ import annotations

import argparse
import logging

from ibrnav import jsonout, recording
from ibrnav.commands.localize import add_model_arg
from ibrnav.commands.scene import SCENE_HELP
from localization.localize import METHODS

log = logging.getLogger(__name__)


def run(args: argparse.Namespace) -> int:
    import rerun as rr

    from ibr.scene import load_scene
    from localization import viz
    from localization.eval import evaluate_localization, prior_spread_m
    from localization.localize import LocConfig
    from localization.pose6_filter import camera_at

    scene = load_scene(args.scene)
    spread_m = prior_spread_m(args.spread_m, scene)
    log.info(f"prior: +-{spread_m:.3f} m per axis, +-{args.spread_deg} deg")
    recording.rerun_setup(args, "ibrnav_eval_loc", "eval_loc.rrd")

    def on_trial(i, held, res, row):
        rr.set_time("step", sequence=i)
        viz.log_camera_pose("world/truth", held.camera, held.image)
        if res.cam_from_world is not None:
            viz.log_camera_pose("world/estimate", camera_at(held.camera, res.cam_from_world))
        if res.particles is not None:
            viz.log_pose6_particles(res.particles[:, :3], res.weights)
        if row["position_m"] is not None:
            rr.log("plots/position_error_m", rr.Scalars(min(row["position_m"], 10.0)))
            rr.log("plots/rotation_error_deg", rr.Scalars(min(row["rotation_deg"], 180.0)))
        rr.log("plots/confidence", rr.Scalars(row["confidence"]))

    out = evaluate_localization(scene, args.method, args.trials or len(scene), spread_m, args.spread_deg,
                                args.seed, LocConfig(model=args.model), on_trial=on_trial,
                                queries=args.queries)
    recording.rerun_teardown(args)
    if args.json:
        jsonout.write(args.json, out)
    print(jsonout.dumps({k: v for k, v in out.items() if k != "per_trial"}))
    return 0


def register(subparsers) -> None:
    e = subparsers.add_parser("eval-loc", help="leave-one-out localisation of a scene's photos")
    e.add_argument("scene", help=SCENE_HELP)
    e.add_argument("--method", choices=METHODS, default="hybrid",
                   help="feature PnP, rendered-view particle filter, or PnP then the filter")
    e.add_argument("--trials", type=int, default=0, help="queries (cycling over the photos; 0: one per photo)")
    e.add_argument("--spread-m", default="1.0",
                   help="prior position spread per axis: metres (1.0) or a share of the scene's depth, "
                   "the median depth of its triangulated points (10%%) (default: %(default)s)")
    e.add_argument("--spread-deg", type=float, default=30.0, help="prior rotation spread (deg)")
    e.add_argument("--seed", type=int, default=0, help="seed of the priors and the filter")
    e.add_argument("--queries", choices=("held-out", "novel"), default="held-out",
                   help="held-out: each query is one of the scene's photos, mapped without it; novel "
                   "(synthetic scenes): new photos of the world near the map's, against one map of all")
    e.add_argument("--json", help="write per-trial results and the summary here")
    add_model_arg(e)
    recording.add_rerun_args(e)
    e.set_defaults(func=run)
