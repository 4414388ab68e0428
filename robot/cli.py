"""`ibrnav demo`: a simulated robot drives a loop through a synthetic world while its
camera images, sensor readings, true pose, pose estimate and the map stream to rerun."""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import rerun as rr

from explore import viz as explore_viz
from ibr import viz as ibr_viz
from ibr.synthetic import loop_route, make_world
from localization import viz as loc_viz
from robot import viz as robot_viz
from robot.sim_robot import SimRobot, SimRobotConfig
from robot.waypoint_follower import FollowerConfig, follow_waypoints


def demo(args: argparse.Namespace) -> int:
    world = make_world("office", args.seed)
    route = loop_route(world)
    start = np.array([*route[0], 0.0])
    config = SimRobotConfig(image_size=(args.width, args.height))
    robot = SimRobot(world, config, np.random.default_rng(args.seed), start_pose=start)
    ibr_viz.rerun_setup(args, "ibrnav_demo", "ibrnav_demo.rrd")
    ibr_viz.log_mesh("world/map/mesh", world.mesh)
    explore_viz.log_floor_plan(world.free_space)
    explore_viz.log_path(route, static=True)
    robot_viz.log_robot_body(config.radius_m)
    t0 = time.perf_counter()
    legs = follow_waypoints(robot, np.tile(route, (args.laps, 1)), start,
                            FollowerConfig(max_legs=args.max_legs), np.random.default_rng(args.seed + 1))
    n_bumps = 0
    for leg in legs:
        photo = robot.capture()
        rr.set_time("step", sequence=leg.index)
        rr.set_time("sensor_time", duration=photo.time_s)
        robot_viz.log_robot_pose(robot.true_pose)
        robot_viz.log_photo(photo, robot.intrinsics, robot.image_size, robot.cam_from_robot)
        robot_viz.log_sensors(photo)
        loc_viz.log_estimate(leg.estimate)
        loc_viz.log_estimate_error(leg.estimate, robot.true_pose)
        n_bumps += leg.motion.blocked
        if leg.index % 10 == 0:
            print(f"[demo] leg {leg.index + 1}: heading for waypoint {leg.waypoint + 1}/"
                  f"{len(route) * args.laps}, {photo.index + 1} photos, "
                  f"{time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    ibr_viz.rerun_teardown(args)
    err = np.hypot(*(leg.estimate[:2] - robot.true_pose[:2]))
    print(f"drove {leg.index + 1} legs, {photo.index + 1} photos, {n_bumps} collisions; "
          f"final estimate error {err:.2f} m")
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("demo", help="a simulated robot drives a loop in synthetic:office, recorded to rerun")
    p.add_argument("--seed", type=int, default=0, help="world and noise seed")
    p.add_argument("--laps", type=int, default=1, help="times round the loop")
    p.add_argument("--max-legs", type=int, default=400, help="stop after this many legs")
    p.add_argument("--width", type=int, default=320, help="camera image width (px)")
    p.add_argument("--height", type=int, default=240, help="camera image height (px)")
    ibr_viz.add_rerun_args(p)
    p.set_defaults(func=demo)
