"""Resuming the scene-capture mission (`robot.mission.mission.run_mission`) from its
capture session folder (`robot.session`): a mission killed at any moment goes on from its
last committed state with nothing lost and no photo taken twice.

What is committed (a `commit` record; `CaptureSession.open(..., rollback=True)` drops what
came after the last one, photos included, so an unfinished step is redone, not duplicated):
- random exploration: every photo (with its estimate and evaluation records). The stage is
  deterministic given the seed, so a simulated robot *replays* it from the start, checking
  that each replayed photo's odometry, compass and time equal the logged ones (the photos
  are not written again), and goes on past the last logged photo exactly as an
  uninterrupted run would. A real robot cannot replay: it takes the remaining photos from
  where it is, starting at its last logged estimate.
- adaptive exploration: the state after the initial map (round 0) and after every round:
  the map (`maps/round_NN.npz`: points, colours, normals, Poisson mesh, every posed photo's
  camera; written atomically before the commit), the particle filter's particles and
  log-weights, the dead-reckoning pose, the distance driven, the counters, the mission's
  random generator and, for a `SimRobot`, its simulator state and noise generator.
  A resumed run is *not* identical to an uninterrupted one from the first adaptive round
  on, even from the same state: COLMAP's multi-threaded SfM and the map rebuilds are not
  bit-reproducible, and the localiser's tracks are re-triangulated from the restored
  cameras. It takes the same photo budget and writes every record once.
Poses: world SE(2) (x, y, theta), metres, radians.
"""

from __future__ import annotations

import io

import numpy as np
import trimesh

from ibr.camera import Camera
from robot.protocol import Photo
from robot.session import CaptureSession, SessionError, write_atomic


class MissionJournal:
    """No session: nothing to resume, nothing saved (what `run_mission` uses by default)."""

    replayable = True

    def resumed_photos(self, stage_of) -> list:
        """The logged photos (`stage_of(record, photo)` -> MissionPhoto), oldest first."""
        return []

    def last_state(self) -> dict | None:
        return None

    def check_replay(self, logged, shot) -> None: ...
    def random_photo_done(self, body) -> None: ...
    def adaptive_state(self) -> dict | None:
        return None

    def round_done(self, mission, result) -> None: ...


def _camera_arrays(cameras: dict[int, Camera]) -> dict[str, np.ndarray]:
    idx = np.array(sorted(cameras), dtype=np.int64)
    return {"cam_index": idx, "cam_K": np.array([cameras[i].K for i in idx]).reshape(-1, 3, 3),
            "cam_T": np.array([cameras[i].cam_from_world for i in idx]).reshape(-1, 4, 4),
            "cam_size": np.array([(cameras[i].width, cameras[i].height) for i in idx]).reshape(-1, 2)}


def _cameras_from(data, prefix: str = "cam") -> dict[int, Camera]:
    return {int(i): Camera(K, int(s[0]), int(s[1]), T, name=f"photo_{int(i):05d}")
            for i, K, T, s in zip(data[f"{prefix}_index"], data[f"{prefix}_K"], data[f"{prefix}_T"],
                                  data[f"{prefix}_size"])}


class SessionJournal(MissionJournal):
    """The mission's journal in an open `CaptureSession` (opened with rollback=True)."""

    def __init__(self, session: CaptureSession, robot, replayable: bool):
        self.session, self.robot, self.replayable = session, robot, replayable
        self._commits = sum(r["kind"] == "commit" for r in session.records)

    # --- reading what a killed run left ---------------------------------------------------
    def resumed_photos(self, stage_of) -> list:
        from ibr.scene import read_image

        out = []
        for r in self.session.photos:
            image = read_image(self.session.folder / r["file"], self.session.image_size)
            photo = Photo(image, r["time_s"], np.asarray(r["odometry"], float), r["compass_rad"], r["range_m"],
                          r["robot_index"])
            out.append(stage_of(r, photo))
        return out

    def last_state(self) -> dict | None:
        last = self.session.last_commit
        return last["state"] if last else None

    def adaptive_state(self) -> dict | None:
        s = self.last_state()
        return s if s is not None and s.get("stage") == "adaptive" else None

    def check_replay(self, logged, shot) -> None:
        """A replayed random-exploration photo must be the logged one (same readings)."""
        a, b = logged.photo, shot.photo
        if not (np.array_equal(a.odometry, b.odometry) and a.compass_rad == b.compass_rad and a.time_s == b.time_s):
            raise SessionError(f"{self.session.folder}: replaying the random exploration diverged at photo "
                               f"{a.index} (a different seed, world or robot?)")

    # --- committing -----------------------------------------------------------------------
    def _commit(self, state: dict) -> None:
        self.session.commit(self._commits, state)
        self._commits += 1

    def random_photo_done(self, body) -> None:
        self._commit({"stage": "random", "photos": len(self.session.photos), "estimate": body.est.pose,
                      "path_m": body.path_m})

    def round_done(self, mission, result) -> None:
        """Commit the adaptive stage's state after `result.rounds` rounds (0: the initial map)."""
        name = f"maps/round_{result.rounds:02d}.npz"
        self._save_map(name, mission)
        loc = mission.body.est
        state = {"stage": "adaptive", "rounds": result.rounds, "map_file": name, "photos": len(self.session.photos),
                 "particles": loc.pf.particles, "log_w": loc.pf.log_w, "dead_reckoning": loc.dead_reckoning.pose,
                 "path_m": mission.body.path_m, "fixes": mission.fixes, "failed": mission.failed,
                 "failure_reasons": dict(mission.failure_reasons), "tilted_fixes": mission.tilted_fixes,
                 "weak_fixes": mission.weak_fixes,
                 "given_up": mission.given_up, "goals": mission.goals_reached,
                 "given_up_goals": mission.given_up_goals, "bumps": mission.bumps,
                 "obstacles_met": dict(mission.obstacles_met),
                 "unfixed": sorted(mission.unfixed), "failed_at_repose": mission.failed_at_repose,
                 "reposed": sorted(mission.reposed), "stepped_from": mission.stepped_from,
                 "trail": np.array(mission.trail).reshape(-1, 2, 2),
                 "swept": np.array(mission.swept).reshape(-1, 2, 2),
                 "sonar_readings": np.array(mission.sonar_readings).reshape(-1, 4),
                 "rng": mission.rng.bit_generator.state}
        if hasattr(self.robot, "true_pose"):
            state["sim"] = self.robot.state()
            state["sim_rng"] = self.robot.rng.bit_generator.state
        self._commit(state)

    def _save_map(self, name: str, mission) -> None:
        m = mission.map
        cams = {i: p.camera for i, p in enumerate(mission.photos) if p.camera is not None}
        arrays = {"points": m.points, "colors": m.colors, "normals": m.normals, "registered": m.registered,
                  "vertices": m.mesh.vertices, "faces": m.mesh.faces,
                  "map_cameras": np.array(sorted(m.cameras), dtype=np.int64), **_camera_arrays(cams)}
        if m.mesh.visual.kind == "vertex":
            arrays["vertex_colors"] = m.mesh.visual.vertex_colors
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        path = self.session.folder / name
        path.parent.mkdir(exist_ok=True)
        write_atomic(path, buf.getvalue())

    def load_map(self, state: dict):
        """(RobotMap, {photo index: Camera}) of a committed adaptive state."""
        from robot.mission.map_building import RobotMap

        path = self.session.folder / state["map_file"]
        try:
            with np.load(path) as d:
                cams = _cameras_from(d)
                mesh = trimesh.Trimesh(d["vertices"], d["faces"], process=False,
                                       vertex_colors=d.get("vertex_colors"))
                rmap = RobotMap({int(i): cams[int(i)] for i in d["map_cameras"]}, d["points"], d["colors"],
                                d["normals"], mesh, int(d["registered"]))
        except (OSError, ValueError, KeyError) as e:
            raise SessionError(f"{path}: the committed map cannot be read ({e})") from None
        return rmap, cams


def restore_adaptive(journal: SessionJournal, state: dict, robot, mission_rng: np.random.Generator) -> None:
    """Put the robot (a `SimRobot`'s simulator state and noise) and the mission's generator
    back as committed."""
    mission_rng.bit_generator.state = state["rng"]
    if "sim" in state and hasattr(robot, "true_pose"):
        robot.restore(state["sim"])
        robot.rng.bit_generator.state = state["sim_rng"]
