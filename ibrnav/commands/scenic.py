"""`ibrnav scenic`: run the Scenic Route Planner (or a PRM / RRT* baseline) with one or two
simulated cameras in a synthetic world, reporting the reconstruction's coverage, outlier
ratio and mean inlier error per frame (Mendez et al., Figure 5)."""

from __future__ import annotations

import argparse
import dataclasses
import logging
import time

import numpy as np

from explore.scenic.session import PLANNERS
from ibr.errors import InputError
from ibrnav import jsonout, recording

log = logging.getLogger(__name__)


class ScenicInputError(InputError):
    """A bad argument of `ibrnav scenic`."""


def session_config(args: argparse.Namespace):
    from explore.scenic.baselines import PRMConfig, RRTStarConfig
    from explore.scenic.cost import NBVConfig
    from explore.scenic.map import MapConfig
    from explore.scenic.planner import PlannerConfig
    from explore.scenic.pose import CameraModel
    from explore.scenic.reconstruction import StereoConfig
    from explore.scenic.session import SessionConfig
    from explore.scenic.smc import SMCConfig

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


def run(args: argparse.Namespace) -> int:
    from explore.scenic import viz as viz_scenic
    from explore.scenic.session import ScenicSession
    from ibr import viz as ibr_viz
    from ibr.scene import parse_scene_spec
    from ibr.synthetic import make_world

    config = session_config(args)
    spec = parse_scene_spec(args.scene, synthetic_only=True, allowed=("seed",))
    world = make_world(spec.world, spec.seed(args.seed))
    recording.rerun_setup(args, "ibrnav_scenic", "scenic.rrd")
    ibr_viz.log_mesh("world/map/mesh", world.mesh)
    t0 = time.perf_counter()
    session = ScenicSession(world, config, np.random.default_rng(args.seed))
    reports = [session.report()]
    viz_scenic.log_report(session, reports[-1])
    for _ in range(args.frames):
        reports.append(session.step())
        viz_scenic.log_report(session, reports[-1])
        m = reports[-1].metrics
        log.info(f"frame {reports[-1].frame}/{args.frames} ({reports[-1].mode}): coverage "
                 f"{m['coverage']:.4f}, outliers {m['outlier_ratio']:.3f}, error "
                 f"{m['mean_error_m'] * 100:.2f} cm, {reports[-1].n_points} points, "
                 f"{time.perf_counter() - t0:.0f} s")
    recording.rerun_teardown(args)
    per_frame = [{"frame": r.frame, **r.metrics} for r in reports]
    result = {"per_frame": per_frame, "final": dict(per_frame[-1])}
    if args.json:
        jsonout.write(args.json, result, indent=1)
    print(jsonout.dumps(result["final"], indent=None))
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("scenic", help="scenic route planning with one or two collaborating "
                              "cameras in a synthetic world (Mendez et al.)")
    p.add_argument("scene", help="synthetic:NAME[?seed=N] (office or courtyard; the seed defaults to --seed)")
    p.add_argument("--agents", type=int, default=2, help="number of cameras, 1 or 2")
    p.add_argument("--frames", type=int, default=30, help="planning iterations after the first pair")
    p.add_argument("--gamma", type=float, default=0.7, help="NBV cost of rays seeing nothing: "
                   "0 explores, 1 refines")
    p.add_argument("--planner", choices=PLANNERS, default="scenic",
                   help="the scenic planner (Mendez et al.) or a PRM / RRT* baseline")
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
    recording.add_rerun_args(p)
    p.set_defaults(func=run)

