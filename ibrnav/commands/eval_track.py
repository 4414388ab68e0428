"""`ibrnav eval-track`: render-likelihood particle-filter tracking in a synthetic world,
with global localisation and a kidnapping, over seeded trials (JSON out, rerun for trial 0)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import rerun as rr

from ibr import viz as ibr_viz
from ibr.errors import InputError
from ibr.synthetic import make_world
from localization import viz
from robot.eval_track import TrackConfig, run_tracking
from robot import viz as robot_viz
from robot.protocol import robot_camera


def _logger(world):
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
    return on_step


def eval_track(args: argparse.Namespace) -> int:
    if not args.scene.startswith("synthetic:"):
        raise InputError(f"{args.scene}: eval-track needs a synthetic world (synthetic:office)")
    world = make_world(args.scene.split(":", 1)[1].partition("?")[0], args.world_seed)
    config = TrackConfig(steps=args.steps, kidnap_step=None if args.kidnap_step < 0 else args.kidnap_step,
                         global_init=not args.known_start, n_particles=args.particles,
                         n_max=args.max_particles)
    ibr_viz.rerun_setup(args, "ibrnav_eval_track", "eval_track.rrd")
    ibr_viz.log_mesh("world/map/mesh", world.mesh)
    trials = []
    for i in range(args.trials):
        t = time.perf_counter()
        res = run_tracking(world, args.seed + i, config, _logger(world) if i == 0 else None)
        res["seconds"] = time.perf_counter() - t
        trials.append(res)
        print(f"[eval-track] trial {i + 1}/{args.trials}: converged after {res['steps_to_converge']} steps, "
              f"recovered after {res['steps_to_recover']} steps, {res['seconds']:.0f} s",
              file=sys.stderr, flush=True)
    ibr_viz.rerun_teardown(args)
    summary = _summary(trials, config)
    out = {"scene": args.scene, "config": {k: v for k, v in vars(config).items()}, **summary, "trials": trials}
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(summary, indent=2))
    return 0


def _summary(trials: list[dict], config: TrackConfig) -> dict:
    conv = [t["steps_to_converge"] for t in trials]
    rec = [t["steps_to_recover"] for t in trials]
    track = [t["median_tracking_error_m"] for t in trials if t["median_tracking_error_m"] is not None]
    summary = {"trials": len(trials),
               "converged_rate": float(np.mean([c is not None for c in conv])),
               "median_steps_to_converge": float(np.median([c for c in conv if c is not None])) if any(
                   c is not None for c in conv) else None,
               "median_tracking_error_m": float(np.median(track)) if track else None}
    if config.kidnap_step is not None:
        summary["recovered_rate"] = float(np.mean([r is not None for r in rec]))
        done = [r for r in rec if r is not None]
        summary["median_steps_to_recover"] = float(np.median(done)) if done else None
    return summary


def register(subparsers) -> None:
    p = subparsers.add_parser("eval-track", help="particle-filter tracking + kidnapping in a synthetic world")
    p.add_argument("scene", nargs="?", default="synthetic:office", help="synthetic:NAME (default office)")
    p.add_argument("--trials", type=int, default=20)
    d = TrackConfig()
    p.add_argument("--steps", type=int, default=d.steps, help="legs (photos) per trial")
    p.add_argument("--kidnap-step", type=int, default=d.kidnap_step, help="teleport before this step (-1: never)")
    p.add_argument("--particles", type=int, default=d.n_particles,
                   help="initial particle count (and of a global re-initialisation)")
    p.add_argument("--max-particles", type=int, default=d.n_max, help="KLD-sampling's ceiling")
    p.add_argument("--known-start", action="store_true", help="start from the true pose, not a uniform prior")
    p.add_argument("--seed", type=int, default=0, help="seed of trial 0 (trial i uses seed + i)")
    p.add_argument("--world-seed", type=int, default=0)
    p.add_argument("--json", help="write per-trial results and the summary here")
    ibr_viz.add_rerun_args(p)
    p.set_defaults(func=eval_track)
