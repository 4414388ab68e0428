"""How far a map error moves a vision fix: the robot's position error per pixel of error
shared by the fix's map points.

A PnP fix fits the map's points, so it inherits their errors. Independent pixel noise
averages out over tens of inliers; an error the points share does not: points triangulated
on one wrong camera, or far points whose depth the stereo baseline barely fixes, are off
together, and the fix moves with them. How far depends on the geometry alone. Near points
spread over the image pin the camera; far points in a narrow patch leave it free to slide
along the view. On apartment 2 (traced, main's code) nine accepted fixes 11-16 cm off were
fitted to within 0.3-1.4 px by inliers 4-7.5 m away, while the true camera reprojected the
same points at only 1.1-2.9 px. The first goal photo such a fix posed (13.6 cm off) seeded
points that put the next fixes 9-20 cm off, and a whole room was mapped 17 cm off.

`bias_sensitivity` is the size of that slide: the largest robot displacement on the floor
(m) per pixel of error shared by all the inliers. It is the least-squares response of the
robot's pose (x, y, theta) to a shift of every inlier's projection,
sqrt(lambda_max((J^T J / N)^-1)) over the (x, y) block, where J (2N, 3) is the Jacobian
of the inliers' projections with respect to the pose (Hartley & Zisserman, "Multiple View
Geometry", 2nd ed., section 5.2: the covariance of an estimate from the Jacobian of its
measurements; here per unit of a shared, not an independent, error).

The mission uses it with `explore --precise-seeds` (`AdaptiveConfig.max_seed_m_per_px`): a
fix poses its photo only when it is pinned, a weaker one only moves the filter. Off by default:
on 10 apartments (stop of 2026-12-02, thirteenth, beside main) the p95 fell on 7 of them and
the photos lost beyond 15 cm from 1242 to 988, but on the 8 it was not chosen on the coverage's
median fell from 0.451 to 0.388 (lower on 4, higher on 3), the maps ending with fewer points
(fewer re-posings); why that costs coverage is not traced.

Frames: world metres, robot pose (x, y m, theta rad) on the floor; pixels of the camera `K`.
"""

from __future__ import annotations

import numpy as np

from ibr.camera import Camera
from localization.pose_views import se2_matrix


def bias_sensitivity(camera: Camera, xyz: np.ndarray, cam_from_robot: np.ndarray) -> float:
    """Metres of robot displacement on the floor per pixel of error shared by the inlier
    points `xyz` (N, 3) (world m) of a fix's `camera` (at the fix's pose) on the robot's
    mount `cam_from_robot` (4, 4) (module docstring). inf when the points do not fix the
    pose (fewer than 2, or degenerate)."""
    xyz = np.asarray(xyz, float).reshape(-1, 3)
    if len(xyz) < 2:
        return float("inf")
    world_from_robot = camera.world_from_cam @ cam_from_robot
    robot_from_cam = np.linalg.inv(cam_from_robot)
    uv = camera.project(xyz)[0].ravel()
    J = np.empty((len(uv), 3))
    for k, h in enumerate((1e-4, 1e-4, 1e-5)):  # m, m, rad: far below any fix's error
        dx, dy, dtheta = np.eye(3)[k] * h  # moved on the floor (world frame), turned about its own axis
        moved = se2_matrix((dx, dy, 0.0)) @ world_from_robot @ se2_matrix((0.0, 0.0, dtheta)) @ robot_from_cam
        J[:, k] = (camera.with_pose(np.linalg.inv(moved)).project(xyz)[0].ravel() - uv) / h
    normal = J.T @ J / len(xyz)
    if np.linalg.cond(normal) > 1e12:
        return float("inf")
    return float(np.sqrt(np.linalg.eigvalsh(np.linalg.inv(normal)[:2, :2]).max()))
