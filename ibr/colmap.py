"""Posed views to a `pycolmap.Reconstruction`: cameras, images and points with their tracks.

The one place that builds a COLMAP model from ibrnav `Camera`s (`ibr.export` writes it,
`ibr.proxy.refine` bundle-adjusts it), the switch that quiets COLMAP's log, and the
import that numbers photos in name order before SfM extracts their features (both SfM
paths: `ibr.proxy.sfm` and `robot.mission.map_building`). Intrinsics go through
`Camera.to_pycolmap` (COLMAP's pixel (0, 0) is the top-left pixel's corner, ibrnav's its centre: + 0.5 px), poses as
`cam_from_world`. Views with the same intrinsics and size share one COLMAP camera.
Units: world metres; keypoints in COLMAP pixels.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from ibr.camera import Camera


def _camera_ids(cameras: list[Camera]) -> tuple[list[Camera], list[int]]:
    """Unique intrinsics (first camera of each) and the 1-based id of each camera's."""
    unique, ids = [], []
    for cam in cameras:
        same = next((k for k, u in enumerate(unique) if u.width == cam.width and u.height == cam.height
                     and np.array_equal(u.K, cam.K)), None)
        if same is None:
            unique.append(cam)
            same = len(unique) - 1
        ids.append(same + 1)
    return unique, ids


def observations(cameras: list[Camera], points: np.ndarray, depth_of=None,
                 depth_tolerance: float = 0.02) -> list[np.ndarray]:
    """Per camera, the indexes of `points` (N, 3) it sees: in front, inside the image, and,
    given `depth_of(n)` -> camera n's depth map (H, W) metres (0: nothing there; called once
    per camera, so only one map is held at a time), not behind the surface by more than
    `depth_tolerance` of the depth (a fraction: scale-free)."""
    seen = []
    for n, cam in enumerate(cameras):
        uv, z = cam.project(points)
        ok = (z > 0) & np.all((uv > -0.5) & (uv < [cam.width - 0.5, cam.height - 0.5]), axis=1)
        if depth_of is not None and ok.any():
            idx = np.flatnonzero(ok)
            px = np.clip(np.rint(uv[idx]).astype(int), 0, [cam.width - 1, cam.height - 1])
            d = depth_of(n)[px[:, 1], px[:, 0]]
            ok[idx] = (d <= 0) | (z[idx] <= d * (1 + depth_tolerance))
        seen.append(np.flatnonzero(ok))
    return seen


def to_reconstruction(cameras: list[Camera], names: list[str], points: np.ndarray | None = None,
                      colors: np.ndarray | None = None, seen: list[np.ndarray] | None = None):
    """A `pycolmap.Reconstruction` of `cameras` (image file names `names`), and of `points`
    (N, 3) world metres with `colors` (N, 3) uint8, each point observed (a keypoint at its projection) in the cameras whose
    `seen` (from `observations`) lists it. Image ids are 1..len(cameras) in order."""
    import pycolmap

    rec = pycolmap.Reconstruction()
    unique, cam_ids = _camera_ids(cameras)
    for k, cam in enumerate(unique):
        rec.add_camera_with_trivial_rig(cam.to_pycolmap(k + 1))
    points = np.zeros((0, 3)) if points is None else np.asarray(points, float).reshape(-1, 3)
    seen = seen or [np.zeros(0, int)] * len(cameras)
    tracks: list[list[tuple[int, int]]] = [[] for _ in range(len(points))]
    for i, (cam, name, cid, idx) in enumerate(zip(cameras, names, cam_ids, seen), start=1):
        uv, _ = cam.project(points[idx]) if len(idx) else (np.zeros((0, 2)), None)
        image = pycolmap.Image(name=name, keypoints=uv + 0.5, camera_id=cid, image_id=i)
        rec.add_image_with_trivial_frame(image, pycolmap.Rigid3d(cam.cam_from_world[:3, :]))
        for k, p in enumerate(idx):
            tracks[p].append((i, k))
    colors = np.full((len(points), 3), 128, np.uint8) if colors is None else np.asarray(colors, np.uint8)
    for xyz, col, obs in zip(points, colors, tracks):
        if obs:  # a point no view sees is no COLMAP point
            rec.add_point3D(xyz, pycolmap.Track([pycolmap.TrackElement(i, k) for i, k in obs]), col)
    return rec


@contextlib.contextmanager
def colmap_errors_only():
    """Silence COLMAP's per-image INFO and WARNING log lines (hundreds per run, on stderr,
    where ibrnav prints its own progress) for the duration; errors still show."""
    import pycolmap

    level = pycolmap.logging.minloglevel
    pycolmap.logging.minloglevel = 2  # glog's ERROR
    try:
        yield
    finally:
        pycolmap.logging.minloglevel = level


def import_in_name_order(database: Path, image_dir: Path, camera_mode, names: list[str] | None = None,
                         reader=None) -> None:
    """Add the photos `names` of `image_dir` (None: all of them) to the COLMAP `database`
    (created if missing), numbered in name order, before `pycolmap.extract_features`
    extracts their features. Left to the extraction, its threads number the photos as they
    finish; COLMAP's mapping visits photos by number, so the same photos gave another
    model (108 photos: 1586 or 1584 points). `camera_mode`: a `pycolmap.CameraMode`;
    `reader`: `pycolmap.ImageReaderOptions` (the camera model, or an existing camera)."""
    import pycolmap

    pycolmap.Database.open(database).close()
    pycolmap.import_images(database, image_dir, camera_mode, names or [],
                           reader if reader is not None else pycolmap.ImageReaderOptions())
