"""Capture sessions: a robot's photos, pose estimates and sensor readings, written to a
folder as they happen, so a mission killed at any moment loses nothing.

Layout of a session folder:

    session.json        camera: intrinsics (3, 3), image_size (w, h), cam_from_robot (4, 4); meta
    log.jsonl           one JSON record per line, appended, flushed and fsynced per record
    photos/photo_NNNNN.png   lossless images, written to a temp file then os.replace'd
    model/              the final model (COLMAP model + mesh.ply), written at the end

A photo's image is on disk (renamed and the folder fsynced) before its log record is
appended, so a record never points at a missing file. Reopening repairs what a kill can
leave: a torn last log line (dropped), temp files (deleted), photos with no record
(deleted: their step is redone). Missions that must redo whole steps mark each finished
step with a `commit` record carrying the state to resume from; `open(..., rollback=True)`
drops records (and photos) after the last commit, so a resumed step is not duplicated.
`load_session_scene` turns a folder into an `ibr.scene.Scene` (`ibr.capture` reads the
layout; `ibr.scene.load_scene` takes the folder too); `write_model` adds the final model.
Poses are SE(2) (x, y, theta), metres and radians.
"""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ibr.errors import InputError
from robot.protocol import Photo

LOG, META, PHOTOS = "log.jsonl", "session.json", "photos"
if TYPE_CHECKING:
    from ibr.scene import Scene

KILL_ENV = "IBRNAV_SESSION_KILL_AT"  # fault injection for tests: "SEQ:STAGE"


class SessionError(InputError):
    """A session folder that cannot be opened or used; names the folder or file."""


def _jsonable(x):
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    return x


def fsync_dir(path: Path) -> None:
    """Make a rename or a new file in folder `path` durable (fsync the folder itself)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def write_atomic(path: Path, data: bytes) -> None:
    """Write `data` to `path` all or nothing: a temp file, fsynced, renamed over `path`."""
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    fsync_dir(path.parent)


class CaptureSession:
    """An open session folder. `records`: the log so far (list of dicts, each with `seq`
    and `kind`); `recovery`: what reopening repaired. Use `create`, `open` or
    `open_or_create`; close with `close()` or a `with` block."""

    def __init__(self, folder: Path, meta: dict, records: list[dict], recovery: dict):
        self.folder, self.meta, self.records, self.recovery = folder, meta, records, recovery
        self.intrinsics = np.asarray(meta["intrinsics"], dtype=np.float64)
        self.image_size = tuple(meta["image_size"])
        self.cam_from_robot = np.asarray(meta["cam_from_robot"], dtype=np.float64)
        self._fd = os.open(folder / LOG, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        kill = os.environ.get(KILL_ENV, "")
        self._kill = (int(kill.split(":")[0]), kill.split(":")[1]) if kill else None

    # --- opening --------------------------------------------------------------------
    @classmethod
    def create(cls, folder: str | Path, intrinsics: np.ndarray, image_size: tuple[int, int],
               cam_from_robot: np.ndarray, meta: dict | None = None) -> "CaptureSession":
        """A new session in `folder` (created; must not already hold a session)."""
        folder = Path(folder)
        if (folder / META).exists():
            raise SessionError(f"{folder}: already holds a capture session (open it to resume)")
        (folder / PHOTOS).mkdir(parents=True, exist_ok=True)
        info = {"version": 1, "intrinsics": intrinsics, "image_size": list(image_size),
                "cam_from_robot": cam_from_robot, "meta": meta or {}}
        write_atomic(folder / META, json.dumps(_jsonable(info), indent=1).encode())
        return cls(folder, json.loads((folder / META).read_text()), [], {})

    @classmethod
    def open(cls, folder: str | Path, rollback: bool = False) -> "CaptureSession":
        """Reopen a session, repairing what a crash left (see the module docstring);
        `rollback`: also drop every record after the last `commit`."""
        folder = Path(folder)
        try:
            meta = json.loads((folder / META).read_text())
        except FileNotFoundError:
            raise SessionError(f"{folder}: not a capture session (no {META})") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise SessionError(f"{folder / META}: corrupt session description ({e})") from None
        (folder / PHOTOS).mkdir(exist_ok=True)
        records, recovery = _read_log(folder)
        if rollback:
            keep = _after_last_commit(records)
            if keep < len(records):
                recovery["rolled_back"] = len(records) - keep
                records = records[:keep]
                write_atomic(folder / LOG, b"".join(_line(r) for r in records))
        recovery.update(_reconcile_photos(folder, records))
        return cls(folder, meta, records, recovery)

    @classmethod
    def open_or_create(cls, folder: str | Path, intrinsics: np.ndarray, image_size: tuple[int, int],
                       cam_from_robot: np.ndarray, meta: dict | None = None,
                       rollback: bool = False) -> "CaptureSession":
        """Resume the session in `folder`, or start one; a resumed session must have been
        made with the same camera and `meta`."""
        if not (Path(folder) / META).exists():
            return cls.create(folder, intrinsics, image_size, cam_from_robot, meta)
        s = cls.open(folder, rollback)
        same = (np.allclose(s.intrinsics, intrinsics) and s.image_size == tuple(image_size)
                and np.allclose(s.cam_from_robot, cam_from_robot) and s.meta.get("meta") == _jsonable(meta or {}))
        if not same:
            s.close()
            raise SessionError(f"{folder}: holds a session made with another camera or settings "
                               f"({s.meta.get('meta')}); use a new folder")
        return s

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> "CaptureSession":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --- writing ----------------------------------------------------------------------
    def append(self, kind: str, **fields) -> dict:
        """Append one record (`kind` plus JSON-able fields; arrays become lists); it is on
        disk (fsynced) when this returns."""
        record = _jsonable({"seq": len(self.records), "kind": kind, **fields})
        line = _line(record)
        if self._dies_at("log"):
            os.write(self._fd, line[:len(line) // 2])
            os.fsync(self._fd)
            os.kill(os.getpid(), signal.SIGKILL)
        os.write(self._fd, line)
        os.fsync(self._fd)
        self.records.append(record)
        return record

    def add_photo(self, photo: Photo, pose: np.ndarray | None = None, **fields) -> dict:
        """Store a photo (atomically) and then its record: the robot's readings with it,
        `pose` (3,) the world pose estimate the camera is placed at, and `fields`."""
        h, w = photo.image.shape[:2]
        if (w, h) != self.image_size:
            raise SessionError(f"{self.folder}: photo of {w}x{h} px, the session's camera is "
                               f"{self.image_size[0]}x{self.image_size[1]}")
        index = len(self.photos)
        name = f"{PHOTOS}/photo_{index:05d}.png"
        self._write_image(self.folder / name, photo.image)
        return self.append("photo", index=index, file=name, time_s=photo.time_s, odometry=photo.odometry,
                           compass_rad=photo.compass_rad, range_m=photo.range_m, robot_index=photo.index,
                           pose=pose, **fields)

    def _write_image(self, path: Path, image: np.ndarray) -> None:
        import cv2

        ok, png = cv2.imencode(".png", np.ascontiguousarray(image[..., ::-1]))
        if not ok:
            raise SessionError(f"{path}: could not encode the photo")
        tmp = path.with_name(f".{path.name}.tmp")
        with open(tmp, "wb") as f:
            f.write(png.tobytes())
            f.flush()
            os.fsync(f.fileno())
        if self._dies_at("image"):
            os.kill(os.getpid(), signal.SIGKILL)
        os.replace(tmp, path)
        fsync_dir(path.parent)
        if self._dies_at("photo"):
            os.kill(os.getpid(), signal.SIGKILL)

    def write_model(self, cameras: list, mesh, points: np.ndarray | None = None,
                    colors: np.ndarray | None = None) -> Path:
        """Write the final model into `model/` (`ibr.export.write_model`: a COLMAP model of
        `cameras`, named after their photos, with `points` (N, 3) and `colors`, and the mesh),
        so that `load_scene` on this folder gives it."""
        from ibr.export import write_model

        return write_model(self.folder, cameras, mesh, points, colors)

    def commit(self, step: int, state: dict) -> dict:
        """Mark mission step `step` finished; `state` is what resuming after it needs."""
        return self.append("commit", step=step, state=state)

    def _dies_at(self, stage: str) -> bool:
        return self._kill is not None and self._kill == (len(self.records), stage)

    # --- reading ----------------------------------------------------------------------
    @property
    def photos(self) -> list[dict]:
        return [r for r in self.records if r["kind"] == "photo"]

    @property
    def last_commit(self) -> dict | None:
        return next((r for r in reversed(self.records) if r["kind"] == "commit"), None)


def _line(record: dict) -> bytes:
    return (json.dumps(record, separators=(",", ":")) + "\n").encode()


def _read_log(folder: Path) -> tuple[list[dict], dict]:
    """Records of the log; a torn or unparsable last line is cut off the file."""
    path, recovery = folder / LOG, {}
    data = path.read_bytes() if path.exists() else b""
    lines = data.split(b"\n")
    records, good = [], 0
    for i, raw in enumerate(lines[:-1]):  # complete lines end with "\n"
        try:
            records.append(json.loads(raw))
        except (json.JSONDecodeError, UnicodeDecodeError):
            if i < len(lines) - 2:
                raise SessionError(f"{path}: line {i + 1} is corrupt (not the last line, so not a torn write)") \
                    from None
            break
        good += len(raw) + 1
    if good < len(data):
        recovery["torn_bytes"] = len(data) - good
        with open(path, "r+b") as f:
            f.truncate(good)
            os.fsync(f.fileno())
    for i, r in enumerate(records):
        if r.get("seq") != i:
            raise SessionError(f"{path}: record {i} has seq {r.get('seq')}; the log was edited")
    return records, recovery


def _after_last_commit(records: list[dict]) -> int:
    for i in range(len(records) - 1, -1, -1):
        if records[i]["kind"] == "commit":
            return i + 1
    return 0


def _reconcile_photos(folder: Path, records: list[dict]) -> dict:
    """Delete temp files and photos no record names; fail on a record whose photo is gone."""
    logged = {r["file"] for r in records if r["kind"] == "photo"}
    temps, orphans = [], []
    for p in sorted((folder / PHOTOS).iterdir()):
        rel = f"{PHOTOS}/{p.name}"
        if p.name.startswith(".") and p.name.endswith(".tmp"):
            temps.append(rel)
            p.unlink()
        elif rel not in logged:
            orphans.append(rel)
            p.unlink()
    for t in folder.glob(".*.tmp"):
        temps.append(t.name)
        t.unlink()
    missing = sorted(f for f in logged if not (folder / f).is_file())
    if missing:
        raise SessionError(f"{folder}: logged photos are missing on disk: {', '.join(missing[:5])}")
    fsync_dir(folder / PHOTOS)
    return {k: v for k, v in (("temp_files", temps), ("orphan_photos", orphans)) if v}


def load_session_scene(folder: str | Path, refine: bool = False) -> "Scene":
    """The session as a `Scene` of every photo at its logged world `pose` (the odometry pose
    when none was logged; `ibr.scene.load_capture` without the final model, which
    `load_scene` prefers), after repairing the folder as `CaptureSession.open` does."""
    from ibr.scene import load_capture  # (trimesh is slow to import; writers don't need it)

    CaptureSession.open(folder).close()
    return load_capture(folder, refine, use_model=False)
