"""`ibrnav explore SCENE --strategy adaptive|random --photos N --seed S --json OUT`: the capture
mission (`robot.mission`, or random exploration only) with a photo budget in a synthetic world,
scored by surface coverage of the true mesh (`robot.mission.coverage`), for comparing
strategies at equal photo budgets."""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np

from ibrnav import jsonout, recording
from ibrnav.args import add_mission_args, mission_config, random_config

START_HEADING = 0.0


def run(args: argparse.Namespace) -> int:
    from ibr.progress import counter
    from ibr.scene import parse_scene_spec
    from ibr.synthetic import loop_route, make_world
    from robot.mission.coverage import CoverageConfig, CoverageTracker
    from robot.mission.mission import run_mission, run_random_only
    from robot.mission.recorder import RecordingObserver
    from robot.sim_robot import SimRobot

    t0 = time.perf_counter()
    spec = parse_scene_spec(args.scene, synthetic_only=True, allowed=("seed",))
    world = make_world(spec.world, spec.seed(args.seed))
    config = mission_config(args)  # a bad flag fails before the robot moves
    if world.name == "office":
        start = np.array([*loop_route(world)[0], START_HEADING])
    else:
        start = world.start_pose(np.random.default_rng(args.seed))
    robot = SimRobot(world, rng=np.random.default_rng(args.seed), start_pose=start)
    log = recording.recording_requested(args)  # record only when asked
    if log:
        recording.rerun_setup(args, f"ibrnav_explore_{args.strategy}", None)
    obs = RecordingObserver(robot, None, log, CoverageTracker(world.mesh, CoverageConfig()))
    obs.progress = counter(args.photos, "photos", logging.getLogger(__name__))
    rng = np.random.default_rng(args.seed)
    if args.strategy == "random":
        result = run_random_only(robot, start, args.photos, rng, obs, random_config(args))
    else:
        result = run_mission(robot, start, min(args.random_photos, args.photos), args.photos,
                             config, rng, obs, random_config(args))
    obs.progress.close()
    seconds = time.perf_counter() - t0
    if args.strategy == "random" and args.eval_poses > 0:  # a model of the random photos, for eval_capture
        from robot.mission.evaluation import model_of_photos

        result.robot_map = model_of_photos(result.photos, robot, config.map)
    if log:
        recording.rerun_teardown(args)
    report = {"scene": args.scene, "strategy": args.strategy, "seed": args.seed,
              "coverage": obs.coverage_curve[-1][1] if obs.coverage_curve else 0.0,
              "photos": len(result.model_photos), "localisation_photos": len(result.photos) - len(result.model_photos),
              "random_photos": sum(p.stage == "random" for p in result.photos),
              "path_length_m": result.path_m, "coverage_curve": [list(p) for p in obs.coverage_curve],
              "rounds": result.rounds, "goals_reached": len(result.goals), "goals_given_up": result.given_up,
              "obstacles_met": result.obstacles_met,
              "pnp_fixes": result.fixes, "pnp_tilted_fixes": result.tilted_fixes,
              "pnp_weak_fixes": result.weak_fixes, "pnp_failures": result.failed_fixes,
              "pnp_failure_reasons": result.failure_reasons,
              "stopped_because": result.stopped_because, "stop_reason": result.stop_reason,
              "localised_at_end": result.localised, "final_spread_m": result.final_spread_m,
              "start_anchored": result.start_anchored,
              **_truth_report(world, robot, result), "position_errors": obs.error_summary(),
              "seconds": seconds}
    report["eval_capture"] = _eval_capture(world, robot, result, args.eval_poses, args.seed)
    report["achievable_coverage"] = _achievable(world, robot, args.achievable_poses)
    if args.json:
        jsonout.write(args.json, report, indent=1)
    print(f"{args.strategy}: coverage {report['coverage']:.3f} with {report['photos']} photos, "
          f"path {report['path_length_m']:.1f} m ({report['seconds']:.0f} s)")
    return 0


def _truth_report(world, robot, result) -> dict:
    """The mission against the simulator's truth (`robot.mission.evaluation`)."""
    from robot.mission.evaluation import (facing_distances, localisation_errors, localisation_errors_by_fix,
                                          localisation_errors_by_region, lost_episodes, map_scale_error,
                                          rooms_visited, true_poses)

    truth = true_poses(robot.truth)
    loc = localisation_errors(result.photos, truth)
    visited, rooms = rooms_visited(world, result.model_photos, truth)
    model = None if loc is None else loc["model"]
    by_region = localisation_errors_by_region(world, result.photos, truth)
    by_fix = localisation_errors_by_fix(result.photos, truth)
    return {"localization_error_m": _position_error(loc), "heading_error_deg": _heading_error(loc),
            "localization_error_by_region_m": None if by_region is None else
            {k: _position_error(v) for k, v in by_region.items()},
            "localization_error_by_fix_m": None if by_fix is None else
            {**{k: _position_error(by_fix[k]) for k in ("fixed", "unfixed")}, "lost_unfixed": by_fix["lost_unfixed"]},
            "lost_photos": lost_episodes(result.photos, truth),
            "model_photos_error": None if model is None else {"position_m": _position_error(model),
                                                              "heading_deg": _heading_error(model)},
            "map_scale_error": map_scale_error(result.robot_map, truth, robot.cam_from_robot, result.photos),
            "first_map_scale_error": None if result.first_map_photos is None else
            map_scale_error(result.robot_map, truth, robot.cam_from_robot, result.photos, result.first_map_photos),
            "rooms_visited": visited, "rooms": rooms,
            "facing_distance_m": facing_distances(world.mesh, result.model_photos, truth,
                                                  float(np.linalg.inv(robot.cam_from_robot)[2, 3]))}


def _position_error(errors: dict | None) -> dict | None:
    """{median, p95, max (m), photos} of a `localisation_errors` figure (None: none)."""
    return None if errors is None else {k: errors[k] for k in ("median", "p95", "max", "photos")}


def _heading_error(errors: dict | None) -> dict | None:
    """{median, p95} (deg) of a `localisation_errors` figure (None: none)."""
    return None if errors is None else {"median": errors["heading_median_deg"], "p95": errors["heading_p95_deg"]}


def _eval_capture(world, robot, result, n_poses: int, seed: int) -> dict | None:
    """ULR of the captured model at `n_poses` random free-space poses against the world's
    true renders (`robot.mission.evaluation.eval_capture`), at half the photos' size (the
    random strategy's model: SfM of its photos, `model_of_photos`); None without a model
    (too few photos posed) or with --eval-poses 0."""
    from robot.mission.evaluation import eval_capture

    posed = [p for p in result.model_photos if p.camera is not None]
    if n_poses <= 0 or result.robot_map is None or not posed:
        return None
    half = posed[0].camera.scaled(0.5)
    return eval_capture(world, [p.camera for p in posed], [p.photo.image for p in posed], result.robot_map.mesh,
                        n_poses, np.random.default_rng(seed + 1), half.K, (half.width, half.height),
                        robot.cam_from_robot)


def _achievable(world, robot, n_poses: int) -> float | None:
    """`robot.mission.coverage.achievable_coverage` of the world with the robot's camera
    (None with --achievable-poses 0)."""
    from robot.mission.coverage import CoverageConfig, achievable_coverage
    from robot.protocol import robot_camera

    if n_poses <= 0:
        return None
    at = lambda poses: (robot_camera(p, robot.intrinsics, robot.image_size, robot.cam_from_robot)  # noqa: E731
                        for p in poses)
    return achievable_coverage(world.mesh, world.free_space, at, n_poses, config=CoverageConfig())


def register(subparsers) -> None:
    e = subparsers.add_parser("explore", help="run a capture strategy in a synthetic scene with a photo "
                              "budget and report surface coverage")
    e.add_argument("scene", help="synthetic:NAME[?seed=N] (office, apartment or courtyard; the world seed defaults "
                   "to --seed)")
    e.add_argument("--strategy", choices=("adaptive", "random"), default="adaptive",
                   help="adaptive (next-best views on the map) or random exploration alone")
    add_mission_args(e, 136)
    e.add_argument("--json", default=None, help="write the report here")
    e.add_argument("--achievable-poses", type=int, default=2000, help="poses of the dense capture whose coverage "
                   "is reported as achievable_coverage (0: none)")
    e.add_argument("--eval-poses", type=int, default=50, help="random free-space poses at which ULR renders of the "
                   "captured model are compared with the world's true renders (0: none; the random strategy's "
                   "model is an SfM map of its photos)")
    recording.add_rerun_args(e)
    e.set_defaults(func=run)
