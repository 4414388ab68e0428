"""`ibrnav eval-track`: render-likelihood particle-filter tracking in any synthetic world
(office, courtyard, apartment) along the world's tour, with global localisation and a
kidnapping, over seeded trials (JSON out, rerun for trial 0)."""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np

from ibrnav import jsonout, recording
from robot.eval_track import TrackConfig

log = logging.getLogger(__name__)


def _logger(world):
    import rerun as rr

    from localization import viz
    from robot import viz as robot_viz
    from robot.protocol import robot_camera

    def on_step(step, report, robot, photo, mcl):
        rr.set_time("step", sequence=step)
        rr.set_time("sensor_time", duration=photo.time_s)
        robot_viz.log_robot_pose(robot.true_pose)
        viz.log_particles(mcl.pf.particles, mcl.pf.weights)
        viz.log_estimate(report.estimate)
        viz.log_estimate_error(report.estimate, robot.true_pose)
        cam = robot_camera(report.estimate, robot.intrinsics, robot.image_size, robot.cam_from_robot)
        viz.log_observed_vs_rendered(photo.image, world.photograph(cam))
        rr.log("plots/particles", rr.Scalars(report.n_particles))
        rr.log("plots/converged_mass", rr.Scalars(report.mass))
    return on_step


def run(args: argparse.Namespace) -> int:
    from ibr import viz as ibr_viz
    from ibr.progress import progress
    from ibr.scene import parse_scene_spec
    from ibr.synthetic import make_world
    from robot.eval_track import run_tracking

    spec = parse_scene_spec(args.scene, synthetic_only=True, allowed=("seed",))
    world = make_world(spec.world, spec.seed(args.world_seed))
    config = TrackConfig(steps=args.steps, kidnap_step=None if args.kidnap_step < 0 else args.kidnap_step,
                         global_init=not args.known_start, n_particles=args.particles,
                         search=not args.uniform_prior)
    recording.rerun_setup(args, "ibrnav_eval_track", "eval_track.rrd")
    ibr_viz.log_mesh("world/map/mesh", world.mesh)
    trials = []
    for i in progress(range(args.trials), desc="trials", logger=log):
        t = time.perf_counter()
        res = run_tracking(world, args.seed + i, config, _logger(world) if i == 0 else None)
        res["seconds"] = time.perf_counter() - t
        trials.append(res)
        log.info(f"trial {i + 1}/{args.trials}: converged after {res['steps_to_converge']} steps, "
                 f"recovered after {res['steps_to_recover']} steps, {res['converged_wrong_steps']} "
                 f"steps claimed converged on a wrong pose, {res['seconds']:.0f} s")
    recording.rerun_teardown(args)
    summary = _summary(trials, config)
    out = {"scene": args.scene, "world_seed": world.seed, "config": dict(vars(config)), **summary, "trials": trials}
    if args.json:
        jsonout.write(args.json, out)
    print(jsonout.dumps(summary))
    return 0


def _summary(trials: list[dict], config: TrackConfig) -> dict:
    conv = [t["steps_to_converge"] for t in trials]
    rec = [t["steps_to_recover"] for t in trials]
    track = [t["median_tracking_error_m"] for t in trials if t["median_tracking_error_m"] is not None]
    summary = {"trials": len(trials),
               "converged_rate": float(np.mean([c is not None for c in conv])),
               "median_steps_to_converge": float(np.median([c for c in conv if c is not None])) if any(
                   c is not None for c in conv) else None,
               "converged_wrong_trials": int(sum(t["converged_wrong_steps"] > 0 for t in trials)),
               "median_tracking_error_m": float(np.median(track)) if track else None,
               "worst_tracking_error_m": float(np.max(track)) if track else None,
               "settings": trials[0]["settings"] if trials else None}
    if config.kidnap_step is not None:
        summary["recovered_rate"] = float(np.mean([r is not None for r in rec]))
        done = [r for r in rec if r is not None]
        summary["median_steps_to_recover"] = float(np.median(done)) if done else None
    return summary


def register(subparsers) -> None:
    p = subparsers.add_parser("eval-track", help="particle-filter tracking + kidnapping in a synthetic world")
    p.add_argument("scene", nargs="?", default="synthetic:office",
                   help="synthetic:NAME[?seed=N] (the seed defaults to --world-seed)")
    p.add_argument("--trials", type=int, default=20, help="tracking runs (one seed each)")
    d = TrackConfig()
    p.add_argument("--steps", type=int, default=d.steps, help="legs (photos) per trial")
    p.add_argument("--kidnap-step", type=int, default=d.kidnap_step, help="teleport before this step (-1: never)")
    p.add_argument("--particles", type=int, default=d.n_particles,
                   help="global particle count (default: from the world's free area and the "
                        "measured likelihood basin)")
    p.add_argument("--known-start", action="store_true", help="start from the true pose, not a uniform prior")
    p.add_argument("--uniform-prior", action="store_true",
                   help="global (re-)initialisations from uniform particles, not from the photo's "
                        "best poses over the map's panoramas")
    p.add_argument("--seed", type=int, default=0, help="seed of trial 0 (trial i uses seed + i)")
    p.add_argument("--world-seed", type=int, default=0, help="seed of the synthetic world")
    p.add_argument("--json", help="write per-trial results and the summary here")
    recording.add_rerun_args(p)
    p.set_defaults(func=run)
