"""`ibrnav scenic`: run the Scenic Route Planner (or a PRM / RRT* baseline) with one or two
simulated cameras in a synthetic world, reporting the reconstruction's coverage, outlier
ratio and mean inlier error per frame (Mendez et al., Figure 5)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time

import numpy as np
import rerun as rr

from explore import viz_scenic
from explore.scenic_baselines import PRMConfig, RRTStarConfig
from explore.scenic_cost import NBVConfig
from explore.scenic_map import MapConfig
from explore.scenic_planner import PlannerConfig
from explore.scenic_pose import CameraModel
from explore.scenic_reconstruction import StereoConfig
from explore.scenic_session import PLANNERS, ScenicSession, SessionConfig
from explore.scenic_smc import SMCConfig
from ibr import viz as ibr_viz
from ibr.errors import InputError
from ibr.synthetic import WORLDS, make_world


class ScenicInputError(InputError):
    """A bad argument of `ibrnav scenic`."""


def parse_scene(spec: str) -> str:
    """The synthetic world name of SCENE = synthetic:NAME."""
    kind, _, name = spec.partition(":")
    if kind != "synthetic" or name not in WORLDS:
        raise ScenicInputError(f"SCENE must be synthetic:NAME with NAME in {sorted(WORLDS)}, got {spec!r}")
    return name


def session_config(args: argparse.Namespace) -> SessionConfig:
    if args.agents not in (1, 2):
        raise ScenicInputError(f"--agents must be 1 or 2, got {args.agents}")
    if not 0.0 <= args.gamma <= 1.0:
        raise ScenicInputError(f"--gamma must be in [0, 1], got {args.gamma}")
    if args.frames < 0 or args.particles < 10 or args.nodes < 2:
        raise ScenicInputError("--frames must be >= 0, --particles >= 10, --nodes >= 2")
    return SessionConfig(
        agents=args.agents, planner=args.planner, inlier_m=args.inlier_distance,
        gt_samples=args.gt_samples,
        camera=CameraModel(args.width, args.height, args.fov),
        map=MapConfig(voxel_m=args.voxel),
        nbv=NBVConfig(gamma=args.gamma),
        smc=SMCConfig(n_particles=args.particles),
        plan=dataclasses.replace(PlannerConfig(), max_nodes=args.nodes),
        prm=PRMConfig(n_samples=args.nodes), rrt=RRTStarConfig(max_nodes=args.nodes),
        stereo=StereoConfig(matcher=args.matcher))


def scenic(args: argparse.Namespace) -> int:
    config = session_config(args)
    world = make_world(parse_scene(args.scene), args.seed)
    ibr_viz.rerun_setup(args, "ibrnav_scenic", "scenic.rrd")
    ibr_viz.log_mesh("world/map/mesh", world.mesh)
    t0 = time.perf_counter()
    session = ScenicSession(world, config, np.random.default_rng(args.seed))
    reports = [session.report()]
    _log(session, reports[-1])
    for _ in range(args.frames):
        reports.append(session.step())
        _log(session, reports[-1])
        m = reports[-1].metrics
        print(f"[scenic] frame {reports[-1].frame}/{args.frames} ({reports[-1].mode}): coverage "
              f"{m['coverage']:.4f}, outliers {m['outlier_ratio']:.3f}, error "
              f"{m['mean_error_m'] * 100:.2f} cm, {reports[-1].n_points} points, "
              f"{time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    ibr_viz.rerun_teardown(args)
    per_frame = [{"frame": r.frame, **r.metrics} for r in reports]
    result = {"per_frame": per_frame, "final": dict(per_frame[-1])}
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)
    print(json.dumps(result["final"]))
    return 0


def _log(session: ScenicSession, report) -> None:
    rr.set_time("step", sequence=report.frame)
    viz_scenic.log_map(session.map)
    viz_scenic.log_particles(session.space.particles, session.space.w)
    plans = report.plans
    if plans:
        viz_scenic.log_plans(plans, min(plans, key=lambda k: plans[k].cost))
    viz_scenic.log_agents(session.poses, session.images, session.config.camera)
    viz_scenic.log_metrics(report.metrics)


def register(subparsers) -> None:
    p = subparsers.add_parser("scenic", help="scenic route planning with one or two collaborating "
                              "cameras in a synthetic world (Mendez et al.)")
    p.add_argument("scene", help="synthetic:office or synthetic:courtyard")
    p.add_argument("--agents", type=int, default=2, help="number of cameras, 1 or 2")
    p.add_argument("--frames", type=int, default=30, help="planning iterations after the first pair")
    p.add_argument("--gamma", type=float, default=0.7, help="NBV cost of rays seeing nothing: "
                   "0 explores, 1 refines")
    p.add_argument("--planner", choices=PLANNERS, default="scenic")
    p.add_argument("--seed", type=int, default=0, help="world and planner seed")
    p.add_argument("--json", help="write per-frame metrics to this JSON file")
    p.add_argument("--width", type=int, default=320, help="image width (pixels)")
    p.add_argument("--height", type=int, default=240, help="image height (pixels)")
    p.add_argument("--fov", type=float, default=60.0, help="horizontal field of view (degrees)")
    p.add_argument("--voxel", type=float, default=0.1, help="voxel edge (metres)")
    p.add_argument("--particles", type=int, default=300, help="SMC particles")
    p.add_argument("--nodes", type=int, default=250, help="tree / roadmap size limit")
    p.add_argument("--matcher", choices=("dense", "sift"), default="dense",
                   help="stereo matches: dense bidirectional flow or sparse SIFT")
    p.add_argument("--inlier-distance", type=float, default=0.05, help="d_i of the metrics (metres)")
    p.add_argument("--gt-samples", type=int, default=20000, help="ground-truth surface samples")
    ibr_viz.add_rerun_args(p)
    p.set_defaults(func=scenic)


def main(argv: list[str] | None = None) -> int:
    """Run `scenic` without the `ibrnav` console script (tests, python -m)."""
    parser = argparse.ArgumentParser(prog="ibrnav")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["scenic", *(sys.argv[1:] if argv is None else argv)])
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
