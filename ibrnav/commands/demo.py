"""`ibrnav demo`: the autonomous scene-capture mission of Foster, Wang & Grupen in
synthetic:office: random exploration, the initial map (SfM), adaptive exploration with the
rendering-quality heuristic until the gain runs out, the final model and a virtual tour
(ULR fly-through). Path following runs on an SE(2) particle filter (`robot.mission_localizer`).
Every photo, pose estimate and map event goes to a capture session folder as it happens,
with a commit per step, so `ibrnav demo --session DIR` on the folder of a killed mission
resumes it (`robot.mission_journal`); everything goes to rerun (`--save`, default
ibrnav_demo.rrd), particles at world/particles.

`ibrnav explore SCENE --strategy adaptive|random --photos N --seed S --json OUT`: the same
mission (or random exploration only) with a photo budget, scored by surface coverage of the
true mesh (`robot.coverage`), for comparing strategies at equal photo budgets.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from pathlib import Path

import numpy as np
import rerun as rr

from explore import viz as explore_viz
from ibr import viz as ibr_viz
from ibr.errors import InputError
from ibr.synthetic import loop_route, make_world
from localization import viz as loc_viz
from robot import viz as robot_viz
from robot.adaptive_exploration import (
    AdaptiveConfig,
    MissionObserver,
    MissionPhoto,
    MissionResult,
    run_mission,
    run_random_only,
)
from robot.coverage import CoverageConfig, CoverageTracker
from robot.mission_journal import SessionJournal
from robot.protocol import robot_camera
from robot.random_exploration import RandomExplorationConfig
from robot.session import CaptureSession
from robot.sim_robot import SimRobot

START_HEADING = 0.0


class Progress:
    """Progress lines on stderr with the elapsed time."""

    def __init__(self, tag: str):
        self.tag, self.t0 = tag, time.perf_counter()

    def __call__(self, text: str) -> None:
        print(f"[{self.tag} {time.perf_counter() - self.t0:5.0f} s] {text}", file=sys.stderr, flush=True)


class RecordingObserver(MissionObserver):
    """Writes the mission to the capture session and to rerun; tracks coverage (simulator)."""

    def __init__(self, robot, session: CaptureSession | None, progress: Progress, log: bool,
                 coverage: CoverageTracker | None):
        self.robot, self.session, self.log = robot, session, log
        self.progress = progress  # the observer's progress hook: a line on stderr
        self.cov, self.n_model, self.step = coverage, 0, 0
        self.sim = isinstance(robot, SimRobot)
        self.coverage_curve: list[tuple[int, float]] = []
        self.errors: list[tuple[float, float]] = []  # (filter, dead reckoning) position errors (m)

    def restore(self, records: list[dict]) -> None:
        """Counts and coverage of the photos a resumed session already holds (its records)."""
        stage = None
        for r in records:
            if r["kind"] == "photo":
                stage = r["stage"]
                self.n_model += stage != "localise"
            elif r["kind"] == "evaluation" and stage != "localise" and self.cov is not None:
                cam = robot_camera(np.asarray(r["true_pose"], float), self.robot.intrinsics, self.robot.image_size,
                                   self.robot.cam_from_robot)
                self.coverage_curve.append((r["model_photos"], self.cov.add(cam)))

    def _truth(self, photo_index: int):
        """The simulator's true pose when photo `photo_index` was just taken (evaluation only)."""
        return self.robot.true_pose.copy() if self.sim else None

    def photo(self, mp: MissionPhoto) -> None:
        if self.session is not None:
            self.session.add_photo(mp.photo, pose=mp.estimate, stage=mp.stage,
                                   localised=mp.camera is not None and mp.stage != "random")
        truth = self._truth(mp.photo.index)
        if mp.stage != "localise":
            self.n_model += 1
            if self.cov is not None:
                cam = robot_camera(truth, self.robot.intrinsics, self.robot.image_size, self.robot.cam_from_robot)
                self.coverage_curve.append((self.n_model, self.cov.add(cam)))
        if truth is not None and mp.dead_reckoning is not None:
            self.errors.append((float(np.hypot(*(mp.estimate[:2] - truth[:2]))),
                                float(np.hypot(*(mp.dead_reckoning[:2] - truth[:2])))))
        if truth is not None and self.session is not None:  # simulator only: ground truth, for evaluation
            self.session.append("evaluation", time_s=mp.photo.time_s, true_pose=truth, estimate=mp.estimate,
                                dead_reckoning=mp.dead_reckoning,
                                model_photos=self.n_model,
                                coverage=self.coverage_curve[-1][1] if self.coverage_curve else None)
        if not self.log:
            return
        self.step += 1
        rr.set_time("step", sequence=self.step)
        rr.set_time("sensor_time", duration=mp.photo.time_s)
        robot_viz.log_robot_pose(truth if truth is not None else mp.estimate)
        robot_viz.log_photo(mp.photo, self.robot.intrinsics, self.robot.image_size, self.robot.cam_from_robot)
        robot_viz.log_sensors(mp.photo)
        loc_viz.log_estimate(mp.estimate)
        if truth is not None:
            loc_viz.log_estimate_error(mp.estimate, truth)
            if mp.dead_reckoning is not None:
                robot_viz.log_dead_reckoning_error(mp.dead_reckoning, truth)
        if self.coverage_curve and mp.stage != "localise":
            robot_viz.log_coverage(*self.coverage_curve[-1])

    def estimate(self, pose, source: str) -> None:
        if self.session is not None:
            self.session.append("estimate", pose=pose, source=source)
        if self.log:
            loc_viz.log_estimate(pose)

    def particles(self, particles, weights) -> None:
        if self.log:
            loc_viz.log_particles(particles, weights)
            if self.sim:
                loc_viz.log_estimate_error(self._filter_mean(particles, weights), self.robot.true_pose)

    @staticmethod
    def _filter_mean(particles, weights):
        from localization.particle_filter import weighted_estimate

        return weighted_estimate(particles, np.log(np.maximum(weights, 1e-300)))[0]

    def map(self, robot_map, free_space) -> None:
        if self.session is not None:
            self.session.append("map", points=len(robot_map.points), faces=len(robot_map.mesh.faces),
                                cameras={str(i): c.cam_from_world for i, c in robot_map.cameras.items()})
        if self.log:
            robot_viz.log_robot_map(robot_map.points, robot_map.colors, robot_map.mesh)
            for cam in robot_map.cameras.values():
                robot_viz.log_posed_photo(cam)
            explore_viz.log_floor_plan(free_space, path="world/map/free_space")

    def candidates(self, poses, scores, goals) -> None:
        if self.session is not None:
            self.session.append("goals", goals=goals, best_score=float(scores.max(initial=0)))
        if self.log:
            explore_viz.log_candidates(poses, scores)
            explore_viz.log_candidates(goals, np.ones(len(goals)), path="world/nbv/goals", arrow_m=0.5)

    def grid(self, grid) -> None:
        if self.log:
            explore_viz.log_nav_grid(grid)

    def path(self, xy) -> None:
        if self.session is not None:
            self.session.append("path", waypoints=xy)
        if self.log:
            explore_viz.log_path(xy)


def _observer(robot, session, progress, log, coverage) -> RecordingObserver:
    return RecordingObserver(robot, session, progress, log, coverage)


def _sim_world(scene: str, seed: int):
    if not scene.startswith("synthetic:"):
        raise InputError(f"{scene!r}: the mission runs in a synthetic world (synthetic:office, synthetic:courtyard)")
    return make_world(scene.split(":", 1)[1], seed)


def mission_config(args: argparse.Namespace) -> AdaptiveConfig:
    return AdaptiveConfig(max_rounds=args.max_rounds, goals_per_round=args.goals_per_round,
                          min_gain_rad=np.radians(args.min_gain_deg))


def random_config(args: argparse.Namespace) -> RandomExplorationConfig:
    return RandomExplorationConfig(circle_step_rad=np.radians(args.circle_step_deg))


def _new_session_dir(base: str) -> Path:
    p, k = Path(base), 2
    while (p / "session.json").exists():
        p, k = Path(f"{base}_{k}"), k + 1
    return p


def _demo_meta(args: argparse.Namespace, sim: bool) -> dict:
    """What a session folder's mission was run with: resuming needs the same."""
    return {"command": "demo", "world": "office", "seed": args.seed, "robot": "sim" if sim else "nxt",
            **{k: getattr(args, k) for k in ("photos", "random_photos", "circle_step_deg", "max_rounds",
                                              "goals_per_round", "min_gain_deg")}}


def demo(args: argparse.Namespace) -> int:
    """The mission into a capture session folder; an existing folder's mission is resumed
    from its last commit (`robot.mission_journal`), a finished one left as it is."""
    from robot.cli import open_robot
    from robot.virtual_tour import render_tour, tour_poses, tour_route

    progress = Progress("demo")
    world = make_world("office", args.seed)
    start = np.array([*loop_route(world)[0], START_HEADING])
    folder = Path(args.session) if args.session else _new_session_dir("ibrnav_demo_capture")
    robot_args = argparse.Namespace(**{**vars(args), "photos": args.photo_dir})
    with open_robot(robot_args, world, start) as robot, contextlib.ExitStack() as stack:
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
        ibr_viz.rerun_setup(args, "ibrnav_demo", "ibrnav_demo.rrd")
        robot_viz.log_robot_body(getattr(getattr(robot, "config", None), "radius_m", 0.15))
        coverage = CoverageTracker(world.mesh, CoverageConfig()) if sim else None
        obs = _observer(robot, session, progress, True, coverage)
        obs.restore(session.records)
        if not any(r["kind"] == "start" for r in session.records):
            session.append("start", start_pose=start, seed=args.seed)
        result = run_mission(robot, start, min(args.random_photos, args.photos), args.photos,
                             mission_config(args), np.random.default_rng(args.seed), obs, random_config(args),
                             SessionJournal(session, robot, replayable=sim))
        session.commit(sum(r["kind"] == "commit" for r in session.records),
                       {"stage": "finished", "stop_reason": result.stop_reason, "path_m": result.path_m})
        progress(f"mission finished ({result.stop_reason}); final model: {len(result.robot_map.points)} points, "
                 f"{len(result.robot_map.mesh.faces)} faces")
        robot_viz.log_robot_map(result.robot_map.points, result.robot_map.colors, result.robot_map.mesh)
        if args.tour_frames > 0:
            posed = [p for p in result.model_photos if p.camera is not None]
            xy = np.array([p.camera.center[:2] for p in posed])
            poses = tour_poses(tour_route(xy), args.tour_frames)
            progress(f"virtual tour: {len(poses)} ULR frames from {len(posed)} photos")
            frames = render_tour([p.camera for p in posed], [p.photo.image for p in posed], result.robot_map.mesh,
                                 poses, (args.tour_width, args.tour_width * 3 // 4), robot.cam_from_robot)
            for k, (cam, image) in enumerate(frames):
                rr.set_time("tour_frame", sequence=k)
                robot_viz.log_tour_frame(cam, image)
        ibr_viz.rerun_teardown(args)
    cov = f", surface coverage {obs.coverage_curve[-1][1]:.3f}" if obs.coverage_curve else ""
    err = _error_summary(obs.errors)
    if err:
        cov += (f", mean position error {err['filter_mean']:.2f} m (particle filter) vs "
                f"{err['dead_reckoning_mean']:.2f} m (dead reckoning)")
    print(f"captured {len(result.model_photos)} photos ({len(result.photos) - len(result.model_photos)} more to "
          f"localise) in {result.rounds} adaptive round{'s' if result.rounds != 1 else ''}, {len(result.goals)} goals reached, {result.given_up} "
          f"given up, drove {result.path_m:.1f} m{cov}; capture folder {folder}; "
          f"{time.perf_counter() - progress.t0:.0f} s")
    return 0


def explore_cmd(args: argparse.Namespace) -> int:
    progress = Progress(f"explore {args.strategy}")
    world = _sim_world(args.scene, args.seed)
    route_start = loop_route(world)[0] if world.name == "office" else np.array(world.free_space.centroid.coords[0])
    start = np.array([*route_start, START_HEADING])
    robot = SimRobot(world, rng=np.random.default_rng(args.seed), start_pose=start)
    log = any(getattr(args, f, None) for f in ibr_viz.SINK_FLAGS)  # record only when asked
    if log:
        ibr_viz.rerun_setup(args, f"ibrnav_explore_{args.strategy}", None)
    obs = _observer(robot, None, progress, log, CoverageTracker(world.mesh, CoverageConfig()))
    rng = np.random.default_rng(args.seed)
    if args.strategy == "random":
        result: MissionResult = run_random_only(robot, start, args.photos, rng, obs, random_config(args))
    else:
        result = run_mission(robot, start, min(args.random_photos, args.photos), args.photos,
                             mission_config(args), rng, obs, random_config(args))
    if log:
        ibr_viz.rerun_teardown(args)
    report = {"scene": args.scene, "strategy": args.strategy, "seed": args.seed,
              "coverage": obs.coverage_curve[-1][1] if obs.coverage_curve else 0.0,
              "photos": len(result.model_photos), "localisation_photos": len(result.photos) - len(result.model_photos),
              "path_length_m": result.path_m, "coverage_curve": [list(p) for p in obs.coverage_curve],
              "rounds": result.rounds, "goals_reached": len(result.goals), "goals_given_up": result.given_up,
              "pnp_fixes": result.fixes, "pnp_failures": result.failed_fixes, "stop_reason": result.stop_reason,
              "localisation_error_m": _error_summary(obs.errors),
              "seconds": time.perf_counter() - progress.t0}
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=1))
    print(f"{args.strategy}: coverage {report['coverage']:.3f} with {report['photos']} photos, "
          f"path {report['path_length_m']:.1f} m ({report['seconds']:.0f} s)")
    return 0


def _error_summary(errors: list[tuple[float, float]]) -> dict | None:
    """Mean and max position error (m) of the filter and of dead reckoning at the adaptive
    stage's photos (simulator truth)."""
    if not errors:
        return None
    e = np.array(errors)
    return {"photos": len(e), "filter_mean": float(e[:, 0].mean()), "filter_max": float(e[:, 0].max()),
            "dead_reckoning_mean": float(e[:, 1].mean()), "dead_reckoning_max": float(e[:, 1].max())}


def _mission_args(p: argparse.ArgumentParser, photos_default: int) -> None:
    p.add_argument("--seed", type=int, default=0, help="world, noise and planner seed")
    p.add_argument("--photos", type=int, default=photos_default, help="photo budget of the model")
    p.add_argument("--random-photos", type=int, default=100, help="photos of the random-exploration stage")
    p.add_argument("--circle-step-deg", type=float, default=10.0,
                   help="turn between the photos of a random-exploration circle (deg)")
    p.add_argument("--max-rounds", type=int, default=6, help="most adaptive rounds (map rebuilds)")
    p.add_argument("--goals-per-round", type=int, default=6, help="goals visited between map rebuilds")
    p.add_argument("--min-gain-deg", type=float, default=3.0,
                   help="stop when the best candidate's heuristic score (mean angle, deg) is below this")


def register(subparsers) -> None:
    p = subparsers.add_parser("demo", help="the autonomous scene-capture mission in synthetic:office "
                              "(random + adaptive exploration, map, virtual tour), recorded to rerun")
    _mission_args(p, 136)
    p.add_argument("--robot", default="sim", help="'sim', or 'nxt:PORT' for a LEGO NXT on a serial port "
                   "(nxt:emulator: the built-in emulated brick)")
    p.add_argument("--width", type=int, default=320, help="camera image width (px)")
    p.add_argument("--height", type=int, default=240, help="camera image height (px)")
    p.add_argument("--photo-dir", default=None, help="with nxt: the folder the camera's photos arrive in")
    p.add_argument("--camera", default=None, help="with nxt: an OpenCV capture device (index, file or pattern)")
    p.add_argument("--session", default=None, help="capture-session folder to write, or to resume the mission of (default: a new "
                   "ibrnav_demo_capture[_N] folder)")
    p.add_argument("--tour-frames", type=int, default=12, help="frames of the virtual tour (0: none)")
    p.add_argument("--tour-width", type=int, default=160, help="width of the tour frames (px)")
    ibr_viz.add_rerun_args(p)
    p.set_defaults(func=demo)

    e = subparsers.add_parser("explore", help="run a capture strategy in a synthetic scene with a photo "
                              "budget and report surface coverage")
    e.add_argument("scene", help="synthetic:office (or another synthetic world)")
    e.add_argument("--strategy", choices=("adaptive", "random"), default="adaptive")
    _mission_args(e, 136)
    e.add_argument("--json", default=None, help="write the report here")
    ibr_viz.add_rerun_args(e)
    e.set_defaults(func=explore_cmd)
