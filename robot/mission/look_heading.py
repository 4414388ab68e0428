"""Where to look before a localise photo: the heading from which the most of PnP's map
points should be seen *and matched* (the mission's own addition; the paper's robot
localised by the map's photos without choosing where it looked).

Why: a localise photo faces wherever the path left the robot. On apartment 0's mission
(stop 37), 480 of 935 PnP attempts found no pose, and 260 of those saw fewer than 100 of the
map's points: close or plain surfaces, or places the map had not reached. Turning in place
first costs no travel, and the compass keeps the heading.

A map point counts from a heading when it projects into the image and SIFT can be expected to
match it against the photo it was triangulated from (`Tracks.seen_from`): the two viewing
rays differ by at most `max_view_angle_deg`, and the two distances by at most the factor
`max_scale_ratio`. Both are properties of the SIFT descriptor, not of a scene. A point seen
from the other side of a wall fails the angle test. Occlusion by the map's own mesh is not
tested: on the first maps of apartments 0-4, a ray cast against it raised the trials whose
chosen heading PnP fixed from 73 to 78 %; on the held-out 5-9 it lowered them from 54 to
50 % (on apartment 5's wrong map, 16 to 4 %)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from localization.pose_views import robot_camera


@dataclass(frozen=True)
class LookConfig:
    """How a localise photo's heading is chosen (`look_heading`)."""

    n_headings: int = 16
    """Headings tried, evenly spaced from the current one (22.5 degrees apart, under half
    of the camera's 60-degree field of view, so no direction falls between two views)."""
    max_view_angle_deg: float = 30.0
    """A point counts only when the ray to it from the robot and from the camera that
    triangulated it differ by at most this (degrees): SIFT's matches thin out beyond about
    30 degrees of viewpoint change on any surface (its descriptor is not affine-invariant),
    whatever the scene."""
    max_scale_ratio: float = 2.0
    """... and when their lengths differ by at most this factor (one octave of SIFT's scale
    space each way; farther, the feature is detected at another scale with fewer pixels)."""
    min_gain: float = 1.5
    """Turn only when the best heading sees more than this many times the points of the
    current heading: a turn adds odometry noise for a small gain. A ratio of counts, so the
    same in any scene; set before the first run, not tuned."""


def matchable(points: np.ndarray, seen_from: np.ndarray, centre: np.ndarray, config: LookConfig) -> np.ndarray:
    """(N,) bool: map `points` (N, 3) whose triangulating camera centres `seen_from` (N, 3)
    looked at them within `config`'s angle and scale of a camera at `centre` (3,), world
    frame, metres. The heading does not enter."""
    to_q = points - centre
    to_s = points - seen_from
    dq, ds = np.linalg.norm(to_q, axis=1), np.linalg.norm(to_s, axis=1)
    ok = (dq > 0) & (ds > 0)
    cos = np.einsum("ij,ij->i", to_q, to_s) / np.where(ok, dq * ds, 1.0)
    ratio = np.where(ok, dq / np.where(ok, ds, 1.0), np.inf)
    return (ok & (cos >= np.cos(np.radians(config.max_view_angle_deg)))
            & (ratio <= config.max_scale_ratio) & (ratio >= 1.0 / config.max_scale_ratio))


def heading_counts(pose: np.ndarray, points: np.ndarray, seen_from: np.ndarray, K: np.ndarray,
                   size: tuple[int, int], cam_from_robot: np.ndarray,
                   config: LookConfig = LookConfig()) -> tuple[np.ndarray, np.ndarray]:
    """(headings (H,) rad, counts (H,)) of the `matchable` map points in view of a robot at
    SE(2) `pose` (x, y, theta; world frame, m, rad) turned to each heading; heading 0 is
    `pose`'s own. K, size, cam_from_robot: the robot's camera and its mount."""
    headings = pose[2] + 2 * np.pi * np.arange(config.n_headings) / config.n_headings
    if len(points) == 0:
        return headings, np.zeros(len(headings), int)
    centre = robot_camera(pose, K, size, cam_from_robot).center
    keep = matchable(points, seen_from, centre, config)
    pts = points[keep]
    cams = [robot_camera(np.r_[pose[:2], h], K, size, cam_from_robot) for h in headings]
    counts = np.array([int(cam.in_image(*cam.project(pts)).sum()) for cam in cams])
    return headings, counts


def look_heading(pose: np.ndarray, points: np.ndarray, seen_from: np.ndarray, K: np.ndarray,
                 size: tuple[int, int], cam_from_robot: np.ndarray, min_points: int,
                 config: LookConfig = LookConfig()) -> float | None:
    """The heading (rad) to turn to before a localise photo at `pose` (`heading_counts`), or
    None to keep the current one: it already sees at least 1/`min_gain` of the best, or no
    heading sees `min_points` (PnP's minimum inliers) matchable points."""
    headings, counts = heading_counts(pose, points, seen_from, K, size, cam_from_robot, config)
    best = int(np.argmax(counts))
    if counts[best] < min_points or counts[best] <= config.min_gain * counts[0]:
        return None
    return float(headings[best])
