"""Motion models for SE(2) robot poses (x, y, theta): metres, radians, world or odometry frame.

The odometry motion model is Thrun, Burgard & Fox, *Probabilistic Robotics* (2005),
Table 5.6 `sample_motion_model_odometry`: a motion between two odometry poses is split
into a first rotation, a translation and a second rotation, and each is perturbed with
zero-mean Gaussian noise whose variance grows with the motion, weighted by alpha1..4:

    var(rot1)  = alpha1 rot1^2 + alpha2 trans^2
    var(trans) = alpha3 trans^2 + alpha4 (rot1^2 + rot2^2)
    var(rot2)  = alpha1 rot2^2 + alpha2 trans^2

The same function drives the simulator's noisy odometry and the particle filter's
prediction step, so the filter's noise model is the simulator's, by construction.
"""

from __future__ import annotations

import numpy as np


def wrap_angle(a):
    """Angles wrapped to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def odometry_decomposition(pose_a: np.ndarray, pose_b: np.ndarray) -> np.ndarray:
    """(rot1, trans, rot2) taking SE(2) pose_a to pose_b. A backward move keeps rot1 small
    and gives a negative trans, so reversing does not read as two half turns."""
    dx, dy = pose_b[0] - pose_a[0], pose_b[1] - pose_a[1]
    trans = np.hypot(dx, dy)
    if trans < 1e-9:
        return np.array([0.0, 0.0, float(wrap_angle(pose_b[2] - pose_a[2]))])
    rot1 = wrap_angle(np.arctan2(dy, dx) - pose_a[2])
    if abs(rot1) > np.pi / 2:  # driving backwards
        rot1, trans = wrap_angle(rot1 + np.pi), -trans
    rot2 = wrap_angle(pose_b[2] - pose_a[2] - rot1)
    return np.array([float(rot1), float(trans), float(rot2)])


def turn_in_place(pose_a: np.ndarray, pose_b: np.ndarray) -> np.ndarray:
    """(rot, 0, 0): the motion of a commanded turn in place between odometry poses pose_a and
    pose_b, the heading change alone. The translation the odometry reads during such a turn
    is wheel slip (Thrun's trans-from-rot term, alpha4), not a distance driven: a
    differential drive turning in place keeps its centre, so the reading carries no
    information about where the robot went and is left to the motion noise."""
    return np.array([float(wrap_angle(pose_b[2] - pose_a[2])), 0.0, 0.0])


def apply_odometry(poses: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Compose SE(2) poses (N, 3) with motions u = (rot1, trans, rot2), (3,) or (N, 3)."""
    poses = np.atleast_2d(poses).astype(np.float64)
    u = np.broadcast_to(u, poses.shape)
    th = poses[:, 2] + u[:, 0]
    out = np.empty_like(poses)
    out[:, 0] = poses[:, 0] + u[:, 1] * np.cos(th)
    out[:, 1] = poses[:, 1] + u[:, 1] * np.sin(th)
    out[:, 2] = wrap_angle(th + u[:, 2])
    return out


def sample_odometry_noise(u: np.ndarray, alphas, n: int, rng: np.random.Generator) -> np.ndarray:
    """n noisy versions (n, 3) of the motion u = (rot1, trans, rot2) (Table 5.6)."""
    rot1, trans, rot2 = u
    a1, a2, a3, a4 = alphas
    sd = np.sqrt([a1 * rot1**2 + a2 * trans**2,
                  a3 * trans**2 + a4 * (rot1**2 + rot2**2),
                  a1 * rot2**2 + a2 * trans**2])
    return np.asarray(u) + rng.normal(size=(n, 3)) * sd


def sample_motion_model_odometry(poses: np.ndarray, odom_a: np.ndarray, odom_b: np.ndarray,
                                 alphas, rng: np.random.Generator, in_place: bool = False,
                                 in_place_alpha4: float = 0.0) -> np.ndarray:
    """Thrun's sample_motion_model_odometry for N poses at once: poses (N, 3) moved by the
    motion the odometry reports between odometry poses odom_a and odom_b, with noise;
    `in_place`: a commanded turn in place, of which only the heading change is motion
    (`turn_in_place`), its centre's slip drawn with `in_place_alpha4` (trans-from-rot, m^2
    per rad^2) in place of alpha4: alpha4 is the noise of the translation the odometry
    *reads*, and that reading is discarded."""
    if in_place:
        u, alphas = turn_in_place(odom_a, odom_b), (*tuple(alphas)[:3], in_place_alpha4)
    else:
        u = odometry_decomposition(odom_a, odom_b)
    return apply_odometry(poses, sample_odometry_noise(u, alphas, len(np.atleast_2d(poses)), rng))


def sample_motion_model_random_walk(poses: np.ndarray, std: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Random-walk motion for when there is no odometry (a hand-held camera, Loc-NeRF's
    prediction): every pose (N, 3) moves by zero-mean Gaussian noise with per-axis
    standard deviation `std` (3,) = (m, m, rad) in the world frame; heading wrapped."""
    poses = np.atleast_2d(poses).astype(np.float64)
    out = poses + rng.normal(size=poses.shape) * np.asarray(std, dtype=np.float64)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def se2_backward(poses: np.ndarray, odom_then: np.ndarray, odom_now: np.ndarray) -> np.ndarray:
    """(N, 3) poses at the time of `odom_then` of robots now at `poses` (N, 3), moved back
    by the odometry's relative motion from `odom_then` to `odom_now` (without noise)."""
    c, s = np.cos(odom_then[2]), np.sin(odom_then[2])
    dx, dy = odom_now[:2] - odom_then[:2]
    d = np.array([c * dx + s * dy, -s * dx + c * dy])  # in the robot's frame then
    th = wrap_angle(poses[:, 2] - (odom_now[2] - odom_then[2]))
    ct, st = np.cos(th), np.sin(th)
    return np.c_[poses[:, 0] - (ct * d[0] - st * d[1]), poses[:, 1] - (st * d[0] + ct * d[1]), th]
