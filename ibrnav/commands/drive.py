"""`ibrnav drive`: a robot drives a loop through synthetic:office while its camera images,
sensor readings, pose (true, for a simulated robot), pose estimate and the map stream to
rerun. `--robot sim` (default) simulates it; `--robot nxt:PORT` drives a LEGO NXT on a
serial port (`nxt:emulator`: the built-in NXT emulator). `--session DIR` writes every
photo, reading and estimate to a capture session as it happens and resumes an
interrupted one from where it stopped (`robot.drive`)."""

from __future__ import annotations

import argparse
import contextlib
import logging
import time

import numpy as np

from ibrnav import recording
from ibrnav.args import add_robot_args, open_robot

log = logging.getLogger(__name__)


def run(args: argparse.Namespace) -> int:
    import rerun as rr

    from explore import viz as explore_viz
    from ibr import viz as ibr_viz
    from ibr.progress import progress
    from ibr.synthetic import loop_route, make_world
    from localization import viz as loc_viz
    from robot import viz as robot_viz
    from robot.drive import run_drive
    from robot.session import CaptureSession
    from robot.sim_robot import SimRobot
    from robot.waypoint_follower import FollowerConfig, follow_waypoints

    world = make_world("office", args.seed)
    route = loop_route(world)
    start = np.array([*route[0], 0.0])
    waypoints = np.tile(route, (args.laps, 1))
    with open_robot(args, world, start) as robot, contextlib.ExitStack() as stack:
        sim = isinstance(robot, SimRobot)
        follower = FollowerConfig(max_legs=args.max_legs)
        if args.session:
            session = stack.enter_context(CaptureSession.open_or_create(
                args.session, robot.intrinsics, robot.image_size, robot.cam_from_robot,
                meta={"command": "drive", "world": "office", "seed": args.seed, "laps": args.laps,
                      "robot": "sim" if sim else "nxt"}, rollback=True))
            if session.last_commit is not None:
                print(f"resuming {args.session} after leg {session.last_commit['step'] + 1} "
                      f"({len(session.photos)} photos kept; repaired: {session.recovery or 'nothing'})")
            legs = ((m.leg, m.photo) for m in run_drive(robot, session, waypoints, start, args.seed, follower))
        else:
            legs = ((leg, robot.capture()) for leg in follow_waypoints(
                robot, waypoints, start, follower, np.random.default_rng(args.seed + 1)))
        recording.rerun_setup(args, "ibrnav_drive", "ibrnav_drive.rrd")
        ibr_viz.log_mesh("world/map/mesh", world.mesh)
        explore_viz.log_floor_plan(world.free_space)
        explore_viz.log_path(route, static=True)
        robot_viz.log_robot_body(getattr(getattr(robot, "config", None), "radius_m", 0.15))
        t0 = time.perf_counter()
        n_bumps, n_legs, leg, photo = 0, 0, None, None
        for leg, photo in progress(legs, desc="legs", logger=log):
            rr.set_time("step", sequence=leg.index)
            rr.set_time("sensor_time", duration=photo.time_s)
            robot_viz.log_robot_pose(robot.true_pose if sim else leg.estimate)
            robot_viz.log_photo(photo, robot.intrinsics, robot.image_size, robot.cam_from_robot)
            robot_viz.log_sensors(photo)
            loc_viz.log_estimate(leg.estimate)
            if sim:
                loc_viz.log_estimate_error(leg.estimate, robot.true_pose)
            n_bumps += leg.motion.blocked
            n_legs += 1
            if leg.index % 10 == 0:
                log.info(f"leg {leg.index + 1}: heading for waypoint {leg.waypoint + 1}/{len(waypoints)}, "
                         f"{photo.index + 1} photos, {time.perf_counter() - t0:.0f} s")
        recording.rerun_teardown(args)
    if leg is None:
        print("nothing left to do: the mission had already finished")
        return 0
    err = f"; final estimate error {np.hypot(*(leg.estimate[:2] - robot.true_pose[:2])):.2f} m" if sim else ""
    print(f"drove {n_legs} legs (to leg {leg.index + 1}), {photo.index + 1} photos, {n_bumps} collisions{err}")
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("drive", help="a robot drives a loop in synthetic:office, recorded to rerun")
    p.add_argument("--seed", type=int, default=0, help="world and noise seed")
    p.add_argument("--laps", type=int, default=1, help="times round the loop")
    p.add_argument("--max-legs", type=int, default=400, help="stop after this many legs")
    add_robot_args(p)
    p.add_argument("--session", default=None, help="capture-session folder: every photo, reading and estimate "
                   "is written there as it happens; an interrupted session resumes")
    recording.add_rerun_args(p)
    p.set_defaults(func=run)
