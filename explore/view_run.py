"""How far a level camera looks across open space: the free run ahead of a pose.

Why the capture mission needs it: a camera at height h with vertical field of view v, looking
level, sees a surface at height z only from (z - h) / tan(v / 2) or farther away. The robot's
camera stands 0.4 m above the floor with v = 46.8 degrees, so a wall above 1.5 m is seen only
from 2.5 m away and a 2.6 m ceiling from 5.1 m. Foster, Wang & Grupen's heuristic favours
close, oblique views (their rays differ most from the photos' rays), and the missions'
adaptive photos faced a surface a median 1.0-1.1 m ahead (apartment 0, office 0), while the
poses of a dense set that see the upper surfaces the missions missed faced one 3.8-4.6 m
ahead; those surfaces were 59-94 % of the missions' coverage gap where every room was
photographed. The free run ranks candidate poses for the views that see the upper walls
and ceiling across a room (`robot.mission.adaptive.AdaptiveMission.far_goals`, an option:
one such goal a round raised coverage on 10 of 16 worlds, but not the held-out median).

Frames: world metres, SE(2) poses (x, y, theta), free space a shapely (Multi)Polygon in xy.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import shapely


def view_runs(poses: np.ndarray, free: shapely.Geometry, step_m: float,
              blocked: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
    """(N,) distance (m) from each SE(2) pose (N, 3) along its heading to where the ray first
    leaves `free` or reaches a point `blocked` says a surface stands at (blocked(xy (K, 2)) ->
    (K,) bool, e.g. the ultrasonic's occupied cells, which know the plain walls a map of
    SIFT points lacks). The ray is sampled every `step_m` (the resolution of the answer);
    it runs at most the diagonal of `free`'s bounds. 0 for a pose outside `free`."""
    poses = np.asarray(poses, float).reshape(-1, 3)
    if len(poses) == 0 or free.is_empty:
        return np.zeros(len(poses))
    x0, y0, x1, y1 = free.bounds
    t = np.arange(0.0, np.hypot(x1 - x0, y1 - y0) + step_m, step_m)
    dirs = np.c_[np.cos(poses[:, 2]), np.sin(poses[:, 2])]
    xy = poses[:, None, :2] + t[None, :, None] * dirs[:, None, :]  # (N, T, 2)
    open_ = shapely.contains_xy(free, xy[..., 0], xy[..., 1])
    if blocked is not None:
        open_ &= ~blocked(xy.reshape(-1, 2)).reshape(open_.shape)
    closed = ~open_
    first = np.where(closed.any(axis=1), closed.argmax(axis=1), len(t))
    return np.maximum(first - 1, 0) * step_m
