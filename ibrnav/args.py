"""Flags that several commands share, defined once so they have one name and one meaning:
the robot (`--robot sim|nxt:PORT`, its camera size, where an NXT's photos come from) for
`drive` and `demo`, and the capture mission's budget and thresholds for `demo` and `explore`."""

from __future__ import annotations

import argparse
import contextlib
import tempfile

import numpy as np

from ibr.errors import InputError


def add_robot_args(p: argparse.ArgumentParser) -> None:
    """--robot, --width, --height, --photo-dir, --camera."""
    p.add_argument("--robot", default="sim", help="'sim', or 'nxt:PORT' for a LEGO NXT on a serial port "
                   "(nxt:emulator: the built-in emulated brick)")
    p.add_argument("--width", type=int, default=320, help="camera image width (px)")
    p.add_argument("--height", type=int, default=240, help="camera image height (px)")
    p.add_argument("--photo-dir", default=None, help="with nxt: the folder the camera's photos arrive in")
    p.add_argument("--camera", default=None, help="with nxt: an OpenCV capture device (index, file or pattern)")


@contextlib.contextmanager
def open_robot(args: argparse.Namespace, world, start: np.ndarray):
    """The robot `--robot` names, placed at `start`; closed (motors stopped) on exit."""
    from robot.sim_robot import SimRobot, SimRobotConfig

    if args.robot == "sim":
        config = SimRobotConfig(image_size=(args.width, args.height))
        yield SimRobot(world, config, np.random.default_rng(args.seed), start_pose=start)
        return
    if not args.robot.startswith("nxt:") or args.robot == "nxt:":
        raise InputError(f"--robot {args.robot!r}: use 'sim' or 'nxt:PORT' (e.g. nxt:/dev/rfcomm0, nxt:emulator)")
    from robot.nxt.driver import NXTRobot, NXTRobotConfig
    from robot.photo_source import FolderPhotoSource, OpenCVPhotoSource

    port = args.robot[4:]
    with contextlib.ExitStack() as stack:
        photos_dir = args.photo_dir
        if port == "emulator":
            from robot.nxt.emulator import EmulatorConfig, NXTEmulator

            photos_dir = photos_dir or stack.enter_context(tempfile.TemporaryDirectory(prefix="nxt_card_"))
            x0, y0, x1, y1 = world.free_space.bounds
            emu = stack.enter_context(NXTEmulator(
                EmulatorConfig(time_scale=8.0, room_half_size_m=((x1 - x0) / 2, (y1 - y0) / 2),
                               image_size=(args.width, args.height)), camera_dir=photos_dir, pose=tuple(start)))
            port = emu.port
        if args.camera is not None:
            source = OpenCVPhotoSource(int(args.camera) if args.camera.isdigit() else args.camera)
        elif photos_dir:
            source = FolderPhotoSource(photos_dir)
        else:
            raise InputError("--robot nxt:PORT needs --photo-dir DIR (the camera card's folder) or --camera DEVICE")
        yield stack.enter_context(NXTRobot(port, NXTRobotConfig(image_size=(args.width, args.height)), source))


def add_mission_args(p: argparse.ArgumentParser, photos_default: int) -> None:
    """--seed, --photos (the budget), --random-photos, --circle-step-deg, --max-rounds,
    --goals-per-round, --min-gain-deg, --far-goals, --retry-tilts / --no-retry-tilts,
    --bundle-adjust, --sweep-frontiers, --keep-off-surfaces, --floor-spans, --look-occlusion,
    --precise-seeds."""
    p.add_argument("--seed", type=int, default=0, help="world, noise and planner seed")
    p.add_argument("--photos", type=int, default=photos_default, help="photo budget of the model")
    p.add_argument("--random-photos", type=int, default=100, help="photos of the random-exploration stage")
    p.add_argument("--circle-step-deg", type=float, default=10.0,
                   help="turn between the photos of a random-exploration circle (deg)")
    p.add_argument("--max-rounds", type=int, default=None, help="most adaptive rounds (map rebuilds; default: no "
                   "limit, the mission stops when complete, at the photo budget or with no reachable goal)")
    p.add_argument("--goals-per-round", type=int, default=6, help="goals visited between map rebuilds")
    p.add_argument("--min-gain-deg", type=float, default=3.0,
                   help="stop when the best candidate's heuristic score (mean angle, deg) is below this")
    p.add_argument("--far-goals", type=int, default=0,
                   help="of each round's goals, this many look the farthest across open space (the upper walls "
                   "and ceiling a level camera sees only from afar); off by default: one a round raised coverage "
                   "on 10 of 16 worlds, but not the held-out median")
    p.add_argument("--retry-tilts", action=argparse.BooleanOptionalAction, default=True,
                   help="a photo plain SIFT cannot localise is described again at simulated tilts (ASIFT-style) "
                   "and tried once more (on by default; --no-retry-tilts: plain SIFT only)")
    p.add_argument("--bundle-adjust", action="store_true",
                   help="at each map rebuild, bundle-adjust the photos posed since the first map with their "
                   "tracks, the first map's photos held (off by default: on 15 worlds the p95 fell on 10 and "
                   "the goal photos' error on 10, but rooms, goals given up and seconds missed their rule)")
    p.add_argument("--sweep-frontiers", action="store_true",
                   help="at a frontier goal the robot turns a full circle reading the ultrasonic before its "
                   "photos, so the frontier moves on past the walls a single reading meets (off by default: "
                   "it goes on into rooms it missed, but is lost more often there: the p95 rose on 7 of 8 "
                   "apartments)")
    p.add_argument("--keep-off-surfaces", action="store_true",
                   help="keep the robot off the surfaces its ultrasonic met on its paths, side steps and "
                   "recoveries, not only at its goals (off by default: it took one apartment's bumps from 85 "
                   "to 25, but over 15 worlds the goals given up were 76 against main's 56 and 74)")
    p.add_argument("--look-occlusion", action="store_true",
                   help="before a localise photo, and for its retry after a failed fix, the robot faces the most "
                   "map points its map's own mesh does not hide, not the most points through walls (off by "
                   "default: over two sweep draws no fewer photos lost beyond 15 cm, and no more fixes in the second)")
    p.add_argument("--precise-seeds", action="store_true",
                   help="a vision fix poses its photo, whose points then join the map, only when a pixel of error "
                   "shared by its map points would move it by at most 7.5 cm (far points in a narrow patch do not "
                   "pin it); a weaker fix still moves the filter (off by default: on 10 apartments the p95 fell on 7 "
                   "and the photos lost beyond 15 cm from 1242 to 988, but on the 8 it was not chosen on the "
                   "coverage's median fell from 0.451 to 0.388)")
    p.add_argument("--floor-spans", action="store_true",
                   help="the first map is placed by the floor's measure of each distance between two stops, its "
                   "stops free on the rig, not scaled by one floor factor (off by default: first maps within 1 %% "
                   "of scale on 14 of 16 worlds against 12, but the missions did not pass their rule)")


def mission_config(args: argparse.Namespace):
    """The `AdaptiveConfig` of the mission flags."""
    from robot.mission.adaptive import ASIFT_TILTS, PRECISE_SEEDS_M_PER_PX, AdaptiveConfig
    from robot.mission.bundle import BundleConfig
    from robot.mission.look_heading import LookConfig
    from robot.mission.map_building import MapConfig

    if not 0 <= args.far_goals <= args.goals_per_round:
        raise InputError(f"--far-goals {args.far_goals}: must be between 0 and --goals-per-round "
                         f"({args.goals_per_round})")
    return AdaptiveConfig(max_rounds=args.max_rounds, goals_per_round=args.goals_per_round,
                          min_gain_rad=np.radians(args.min_gain_deg), far_goals_per_round=args.far_goals,
                          retry_tilts=ASIFT_TILTS if args.retry_tilts else (), sweep_frontiers=args.sweep_frontiers,
                          keep_off_surfaces=args.keep_off_surfaces,
                          look=LookConfig(occlude=args.look_occlusion),
                          max_seed_m_per_px=PRECISE_SEEDS_M_PER_PX if args.precise_seeds else None,
                          bundle=BundleConfig() if args.bundle_adjust else None,
                          map=MapConfig(floor_spans=args.floor_spans))


def random_config(args: argparse.Namespace):
    """The `RandomExplorationConfig` of the mission flags."""
    from robot.mission.random_stage import RandomExplorationConfig

    return RandomExplorationConfig(circle_step_rad=np.radians(args.circle_step_deg))
