"""The mission's recorder: a `MissionObserver` that writes what the capture mission does to
its capture session folder (photos, estimates, map events, goals, paths, and, on a
simulator, ground truth for evaluation) and, when asked, to rerun (`robot.viz`,
`robot.mission.viz`, `localization.viz`, `explore.viz`); on a simulator it also tracks the
surface coverage of the true mesh (`robot.mission.coverage`) and the position errors of the
filter and of dead reckoning. Frames: world SE(2) poses (x, y, theta), metres, radians."""

from __future__ import annotations

import numpy as np

from explore import viz as explore_viz
from localization import viz as loc_viz
from localization.particle_filter import weighted_estimate
from robot import viz as robot_viz
from robot.mission import viz as mission_viz
from robot.mission.coverage import CoverageTracker
from robot.mission.observer import MissionObserver, MissionPhoto
from robot.protocol import robot_camera
from robot.session import CaptureSession
from robot.sim_robot import SimRobot


class RecordingObserver(MissionObserver):
    """Writes the mission to the capture session and to rerun; tracks coverage (simulator)."""

    def __init__(self, robot, session: CaptureSession | None, log: bool, coverage: CoverageTracker | None):
        self.robot, self.session, self.log = robot, session, log
        self.cov, self.n_model, self.step = coverage, 0, 0
        self.sim = isinstance(robot, SimRobot)
        self.coverage_curve: list[tuple[int, float]] = []
        self.errors: list[tuple[float, float]] = []  # (filter, dead reckoning) position errors (m)
        self.progress = None  # a bar (ibr.progress.counter) advanced by each model photo

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
                                   localised=mp.camera is not None and mp.stage != "random", fixed=mp.fixed)
        truth = self._truth(mp.photo.index)
        if mp.stage != "localise":
            self.n_model += 1
            if self.progress is not None:
                self.progress.update()
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
        robot_viz.set_time(self.step, mp.photo.time_s)
        robot_viz.log_robot_pose(truth if truth is not None else mp.estimate)
        robot_viz.log_photo(mp.photo, self.robot.intrinsics, self.robot.image_size, self.robot.cam_from_robot)
        robot_viz.log_sensors(mp.photo)
        loc_viz.log_estimate(mp.estimate)
        if truth is not None:
            loc_viz.log_estimate_error(mp.estimate, truth)
            if mp.dead_reckoning is not None:
                mission_viz.log_dead_reckoning_error(mp.dead_reckoning, truth)
        if self.coverage_curve and mp.stage != "localise":
            mission_viz.log_coverage(*self.coverage_curve[-1])

    def estimate(self, pose, source: str) -> None:
        if self.session is not None:
            self.session.append("estimate", pose=pose, source=source)
        if self.log:
            loc_viz.log_estimate(pose)

    def particles(self, particles, weights) -> None:
        if self.log:
            loc_viz.log_particles(particles, weights)
            loc_viz.log_particle_count(len(particles))
            if self.sim:
                loc_viz.log_estimate_error(self._filter_mean(particles, weights), self.robot.true_pose)

    @staticmethod
    def _filter_mean(particles, weights):
        return weighted_estimate(particles, np.log(np.maximum(weights, 1e-300)))[0]

    def map(self, robot_map, free_space) -> None:
        if self.session is not None:
            self.session.append("map", points=len(robot_map.points), faces=len(robot_map.mesh.faces),
                                cameras={str(i): c.cam_from_world for i, c in robot_map.cameras.items()})
        if self.log:
            mission_viz.log_robot_map(robot_map.points, robot_map.colors, robot_map.mesh)
            for cam in robot_map.cameras.values():
                mission_viz.log_posed_photo(cam)
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

    def sonar(self, grid) -> None:
        if self.log:
            explore_viz.log_sonar_grid(grid)

    def path(self, xy) -> None:
        if self.session is not None:
            self.session.append("path", waypoints=xy)
        if self.log:
            explore_viz.log_path(xy)

    def error_summary(self) -> dict | None:
        """Mean and max position error (m) of the filter and of dead reckoning at the photos
        (simulator truth); None without truth."""
        if not self.errors:
            return None
        e = np.array(self.errors)
        return {"photos": len(e), "filter_mean": float(e[:, 0].mean()), "filter_max": float(e[:, 0].max()),
                "dead_reckoning_mean": float(e[:, 1].mean()), "dead_reckoning_max": float(e[:, 1].max())}
