"""The mission's product: a virtual tour of the captured place, rendered by unstructured
lumigraph rendering (`ibr.render.ulr`, as Foster, Wang & Grupen render theirs) from the posed photos
over the final map's Poisson mesh. The tour flies a camera at the robot's camera height
along a smooth closed curve through the places the robot photographed from.
Frames: world metres; cameras are `ibr.camera.Camera`.
"""

from __future__ import annotations

import numpy as np
import trimesh

from ibr.camera import Camera
from ibr.scene import Scene, View
from robot.protocol import robot_camera


def tour_poses(xy: np.ndarray, n_frames: int) -> np.ndarray:
    """(n_frames, 3) SE(2) poses along the closed polyline through `xy` (M, 2) in the order
    given, heading along the curve, equally spaced by arc length (metres, radians)."""
    pts = np.vstack([xy, xy[:1]])
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    s = np.r_[0, np.cumsum(seg)]
    t = np.linspace(0, s[-1], n_frames, endpoint=False)
    x, y = np.interp(t, s, pts[:, 0]), np.interp(t, s, pts[:, 1])
    ahead = (t + 0.3) % max(s[-1], 1e-9)
    hx, hy = np.interp(ahead, s, pts[:, 0]), np.interp(ahead, s, pts[:, 1])
    return np.c_[x, y, np.arctan2(hy - y, hx - x)]


def tour_route(centres_xy: np.ndarray, n_stops: int = 8) -> np.ndarray:
    """(<= n_stops, 2) stops around the photographed area: the photo positions' convex-hull
    corners shrunk 30% towards their centroid, in angular order."""
    c = centres_xy.mean(0)
    ang = np.arctan2(*(centres_xy - c).T[::-1])
    bins = np.linspace(-np.pi, np.pi, n_stops + 1)
    stops = []
    for a, b in zip(bins[:-1], bins[1:]):
        sel = centres_xy[(ang >= a) & (ang < b)]
        if len(sel):
            far = sel[np.argmax(np.linalg.norm(sel - c, axis=1))]
            stops.append(c + 0.7 * (far - c))
    return np.array(stops).reshape(-1, 2)


def render_tour(cameras: list[Camera], images: list[np.ndarray], mesh: trimesh.Trimesh, poses: np.ndarray,
                size: tuple[int, int], cam_from_robot: np.ndarray, ctx=None) -> list[tuple[Camera, np.ndarray]]:
    """ULR frames (camera, (H, W, 3) uint8) of the robot camera at SE(2) `poses` (N, 3), at
    `size` (w, h) with the sources' field of view, from the posed photos."""
    from ibr.render.ulr import UlrRenderer

    scene = Scene("mission", [View(c, im) for c, im in zip(cameras, images)])
    s = size[0] / cameras[0].width
    K = cameras[0].scaled(s).K if abs(size[1] / cameras[0].height - s) < 1e-6 else cameras[0].K
    ulr = UlrRenderer(scene, mesh, ctx)
    try:
        out = []
        for i, p in enumerate(poses):
            cam = robot_camera(p, K, size, cam_from_robot, name=f"tour_{i:03d}")
            out.append((cam, ulr.render(cam)[0]))
        return out
    finally:
        ulr.release()
