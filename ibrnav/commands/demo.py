"""`ibrnav demo`: the autonomous scene-capture mission of Foster, Wang & Grupen in a
synthetic apartment (`--world office` for the office; `robot.mission`): random exploration,
the initial map (SfM), adaptive
exploration with the rendering-quality heuristic until the gain runs out, the final model and
a virtual tour (ULR fly-through). Path following runs on an SE(2) particle filter. Every photo,
pose estimate and map event goes to a capture session folder as it happens, with a commit per
step, so `ibrnav demo --session DIR` on the folder of a killed mission resumes it
(`robot.mission.journal`); everything goes to rerun (`--save`, default ibrnav_demo.rrd),
particles at world/particles."""

from __future__ import annotations

import argparse
import contextlib
import logging
import time
from pathlib import Path

import numpy as np

from ibrnav import recording
from ibrnav.args import add_mission_args, add_robot_args, mission_config, open_robot, random_config

START_HEADING = 0.0
log = logging.getLogger(__name__)


def _new_session_dir(base: str) -> Path:
    p, k = Path(base), 2
    while (p / "session.json").exists():
        p, k = Path(f"{base}_{k}"), k + 1
    return p


def _demo_meta(args: argparse.Namespace, sim: bool) -> dict:
    """What a session folder's mission was run with: resuming needs the same."""
    return {"command": "demo", "world": args.world, "seed": args.seed, "robot": "sim" if sim else "nxt",
            **{k: getattr(args, k) for k in ("photos", "random_photos", "circle_step_deg", "max_rounds",
                                              "goals_per_round", "min_gain_deg")}}


def demo_world(name: str, seed: int):
    """(world, start pose (3,)): the office starts on its demo loop facing east; any other
    world (an apartment by default) at `world.start_pose`, a random room drawn from the seed."""
    from ibr.synthetic import loop_route, make_world

    world = make_world(name, seed)
    if name == "office":
        return world, np.array([*loop_route(world)[0], START_HEADING])
    return world, world.start_pose(np.random.default_rng(seed))


def run(args: argparse.Namespace) -> int:
    """The mission into a capture session folder; an existing folder's mission is resumed
    from its last commit (`robot.mission.journal`), a finished one left as it is."""
    import rerun as rr

    from robot import viz as robot_viz
    from ibr.progress import counter
    from robot.mission import viz as mission_viz
    from robot.mission.coverage import CoverageConfig, CoverageTracker
    from robot.mission.journal import SessionJournal
    from robot.mission.mission import run_mission
    from robot.mission.recorder import RecordingObserver
    from robot.mission.virtual_tour import render_tour, tour_poses, tour_route
    from robot.session import CaptureSession
    from robot.sim_robot import SimRobot

    t0 = time.perf_counter()
    world, start = demo_world(args.world, args.seed)
    folder = Path(args.session) if args.session else _new_session_dir("ibrnav_demo_capture")
    with open_robot(args, world, start) as robot, contextlib.ExitStack() as stack:
        sim = isinstance(robot, SimRobot)
        resuming = (folder / "session.json").exists()
        session = stack.enter_context(CaptureSession.open_or_create(
            folder, robot.intrinsics, robot.image_size, robot.cam_from_robot, meta=_demo_meta(args, sim),
            rollback=True))
        if (session.last_commit or {}).get("state", {}).get("stage") == "finished":
            print(f"{folder}: the mission is already finished ({len(session.photos)} photos)")
            return 0
        if resuming:
            print(f"resuming the mission in {folder}: {len(session.photos)} photos and {len(session.records)} "
                  f"records kept (repaired: {session.recovery or 'nothing'})")
        recording.rerun_setup(args, "ibrnav_demo", "ibrnav_demo.rrd")
        robot_viz.log_robot_body(getattr(getattr(robot, "config", None), "radius_m", 0.15))
        coverage = CoverageTracker(world.mesh, CoverageConfig()) if sim else None
        obs = RecordingObserver(robot, session, True, coverage)
        obs.restore(session.records)
        obs.progress = counter(args.photos, "photos", log, initial=obs.n_model)
        if not any(r["kind"] == "start" for r in session.records):
            session.append("start", start_pose=start, seed=args.seed)
        result = run_mission(robot, start, min(args.random_photos, args.photos), args.photos,
                             mission_config(args), np.random.default_rng(args.seed), obs, random_config(args),
                             SessionJournal(session, robot, replayable=sim))
        obs.progress.close()
        final = result.robot_map
        session.write_model([final.cameras[i] for i in sorted(final.cameras)], final.mesh, final.points, final.colors)
        session.commit(sum(r["kind"] == "commit" for r in session.records),
                       {"stage": "finished", "stopped_because": result.stopped_because,
                        "stop_reason": result.stop_reason, "path_m": result.path_m,
                        "localised": result.localised, "final_spread_m": result.final_spread_m})
        log.info(f"mission finished: {result.stopped_because} ({result.stop_reason}); final model: {len(result.robot_map.points)} points, "
                 f"{len(result.robot_map.mesh.faces)} faces")
        mission_viz.log_robot_map(result.robot_map.points, result.robot_map.colors, result.robot_map.mesh)
        if args.tour_frames > 0:
            posed = [p for p in result.model_photos if p.camera is not None]
            xy = np.array([p.camera.center[:2] for p in posed])
            poses = tour_poses(tour_route(xy), args.tour_frames)
            log.info(f"virtual tour: {len(poses)} ULR frames from {len(posed)} photos")
            frames = render_tour([p.camera for p in posed], [p.photo.image for p in posed], result.robot_map.mesh,
                                 poses, (args.tour_width, args.tour_width * 3 // 4), robot.cam_from_robot)
            for k, (cam, image) in enumerate(frames):
                rr.set_time("tour_frame", sequence=k)
                mission_viz.log_tour_frame(cam, image)
        recording.rerun_teardown(args)
    cov = f", surface coverage {obs.coverage_curve[-1][1]:.3f}" if obs.coverage_curve else ""
    err = obs.error_summary()
    if err:
        cov += (f", mean position error {err['filter_mean']:.2f} m (particle filter) vs "
                f"{err['dead_reckoning_mean']:.2f} m (dead reckoning)")
    print(f"captured {len(result.model_photos)} photos ({len(result.photos) - len(result.model_photos)} more to "
          f"localise) in {result.rounds} adaptive round{'s' if result.rounds != 1 else ''}, {len(result.goals)} goals reached, {result.given_up} "
          f"given up, drove {result.path_m:.1f} m{cov}; stopped: {result.stopped_because}{_lost(result)}; "
          f"capture folder {folder}; "
          f"{time.perf_counter() - t0:.0f} s")
    return 0


def _lost(result) -> str:
    """", ROBOT LOST (...)" when the mission ended without knowing where the robot is."""
    if result.localised is False:
        return f", ROBOT LOST at the end (filter spread {result.final_spread_m:.2f} m)"
    return ""


def register(subparsers) -> None:
    p = subparsers.add_parser("demo", help="the autonomous scene-capture mission in a synthetic apartment "
                              "(random + adaptive exploration, map, virtual tour), recorded to rerun")
    add_mission_args(p, 136)
    p.add_argument("--world", choices=("apartment", "office"), default="apartment",
                   help="the synthetic world (built from --seed; the robot starts in a random room of an apartment)")
    add_robot_args(p)
    p.add_argument("--session", default=None, help="capture-session folder to write, or to resume the mission of (default: a new "
                   "ibrnav_demo_capture[_N] folder)")
    p.add_argument("--tour-frames", type=int, default=12, help="frames of the virtual tour (0: none)")
    p.add_argument("--tour-width", type=int, default=160, help="width of the tour frames (px)")
    recording.add_rerun_args(p)
    p.set_defaults(func=run)
