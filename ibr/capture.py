"""A robot's capture-session folder read as a `Scene` (the read side of `robot.session`,
which writes it; nothing here writes or repairs the folder).

Layout (`robot.session` and the capture mission write it):

    session.json              camera: intrinsics (3, 3), image_size (w, h), cam_from_robot (4, 4); meta
    log.jsonl                 one JSON record per line: `photo` records (file, odometry, compass,
                              range, `pose`: the filter's SE(2) estimate), estimates, maps, commits
    photos/photo_NNNNN.png    the photos, lossless
    maps/round_NN.npz         the mission's map after each round (points, colours, Poisson mesh,
                              SfM cameras of the photos it registered)
    model/                    the final model, when the mission finished: a COLMAP model
                              (cameras.bin, images.bin, points3D.bin; images in ../photos) and
                              mesh.ply (`ibr.export.write_model`)

`ibr.scene.load_capture` (what `load_scene` calls on such a folder) prefers `model/`;
without it the views are the photos at the filter's logged poses (world SE(2) (x, y, theta),
metres and radians, mounted through `cam_from_robot`), with the last map's mesh and points
when the mission wrote one. Views are named after their photo file's stem (`photo_00012`),
whichever way they were posed. This module knows the layout; `ibr.scene` builds the Scene.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from ibr.camera import Camera, CameraError
from ibr.errors import InputError

META, LOG, PHOTOS, MAPS, MODEL = "session.json", "log.jsonl", "photos", "maps", "model"


class CaptureError(InputError):
    """A capture folder that cannot be read; the message names the folder or file."""


def is_capture_folder(folder: str | Path) -> bool:
    """Whether `folder` holds a capture session (its `session.json`)."""
    return (Path(folder) / META).is_file()


@dataclass
class CaptureFolder:
    """A session folder as written. intrinsics (3, 3) pixels (pixel centres at integers);
    image_size (w, h); cam_from_robot (4, 4); meta: what the mission was run with; records:
    the log (a torn last line, which a killed writer can leave, is skipped)."""

    folder: Path
    intrinsics: np.ndarray
    image_size: tuple[int, int]
    cam_from_robot: np.ndarray
    meta: dict
    records: list[dict]

    @property
    def photos(self) -> list[dict]:
        return [r for r in self.records if r["kind"] == "photo"]

    @property
    def maps(self) -> list[Path]:
        """The mission's map files, oldest round first."""
        return sorted((self.folder / MAPS).glob("round_*.npz"))

    @property
    def model(self) -> Path | None:
        """The final model's COLMAP folder, None when the mission wrote none."""
        m = self.folder / MODEL
        return m if (m / "cameras.bin").is_file() or (m / "cameras.txt").is_file() else None

    def photo_cameras(self) -> list[Camera]:
        """The camera of every photo at its logged pose (`photo_camera`), in log order."""
        cams = []
        for r in self.photos:
            try:
                cams.append(self.photo_camera(r))
            except (CameraError, KeyError, TypeError, ValueError) as e:
                raise CaptureError(f"{self.folder / LOG}: photo record {r.get('seq')} has no usable pose "
                                   f"({e!r})") from None
        if not cams:
            raise CaptureError(f"{self.folder}: the capture session has no photos yet")
        return cams

    def last_map(self) -> tuple[trimesh.Trimesh, np.ndarray, np.ndarray] | None:
        """The mission's last map: (mesh (world metres, vertex colours), points (N, 3),
        colours (N, 3) uint8), None when it wrote none."""
        if not self.maps:
            return None
        try:
            with np.load(self.maps[-1]) as d:
                mesh = trimesh.Trimesh(d["vertices"], d["faces"], process=False,
                                       vertex_colors=d["vertex_colors"] if "vertex_colors" in d else None)
                return mesh, d["points"], d["colors"]
        except (OSError, ValueError, KeyError) as e:
            raise CaptureError(f"{self.maps[-1]}: the mission's map cannot be read ({e})") from None

    def photo_camera(self, record: dict) -> Camera:
        """The camera of a `photo` record at its logged world pose (the odometry pose when the
        robot logged no estimate), named after its file."""
        pose = record.get("pose") if record.get("pose") is not None else record["odometry"]
        x, y, th = np.asarray(pose, dtype=np.float64)
        c, s = np.cos(th), np.sin(th)
        world_from_robot = np.array([[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, 0], [0, 0, 0, 1.0]])
        return Camera(self.intrinsics, *self.image_size, self.cam_from_robot @ np.linalg.inv(world_from_robot),
                      Path(record["file"]).stem)


def read_capture(folder: str | Path) -> CaptureFolder:
    """Read a session folder (no repair: that is `robot.session.CaptureSession.open`'s job).
    Raises CaptureError naming the folder or file."""
    folder = Path(folder)
    try:
        info = json.loads((folder / META).read_text())
        K, size, mount = info["intrinsics"], tuple(int(v) for v in info["image_size"]), info["cam_from_robot"]
    except FileNotFoundError:
        raise CaptureError(f"{folder}: not a capture session (no {META})") from None
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError, ValueError) as e:
        raise CaptureError(f"{folder / META}: corrupt session description ({e!r})") from None
    records = []
    path = folder / LOG
    lines = path.read_bytes().split(b"\n") if path.is_file() else []
    for i, raw in enumerate(lines[:-1]):  # complete lines end with "\n"; a torn tail does not
        try:
            records.append(json.loads(raw))
        except (json.JSONDecodeError, UnicodeDecodeError):
            if i < len(lines) - 2:
                raise CaptureError(f"{path}: line {i + 1} is corrupt") from None
    try:
        return CaptureFolder(folder, np.asarray(K, np.float64).reshape(3, 3), size,
                             np.asarray(mount, np.float64).reshape(4, 4), info.get("meta", {}), records)
    except ValueError as e:
        raise CaptureError(f"{folder / META}: bad camera ({e})") from None
