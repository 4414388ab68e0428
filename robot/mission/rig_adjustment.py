"""Bundle adjustment of the random stage's photos on the robot's own rig.

Incremental SfM poses each photo with six free degrees, but the robot took a circle of
photos turning in place (Foster, Wang & Grupen, section IV-A): every photo of a circle stands
on one axle position, level, the camera `mount` (5 cm) ahead of it. Inside a circle the
only parallax is that swing of the mount, and at 1-3 m depth a sideways step of the camera
looks almost like a turn; SfM takes part of each step for turn. Measured on the random
stages of apartments 6 and 7: SfM's circles had radii of 1.0-4.2 cm instead of 5, their
photos' yaw ramped by +0.3 degrees per 10 degree step (the same over-turn `turn_gains`
measures in `complete_circles`' chains), 3.6 degrees at a model's ends, and a model levelled
1.7 degrees off tilted its points alike.

`adjust_on_rig` refines the photos and the models' points with the robot's geometry built in
(Triggs et al., "Bundle adjustment: a modern synthesis", 2000, with the camera pose
parameterised by the rig): each circle's robot position stays where `circles.place_models`
put it (that placement holds the map's scale, from the ultrasonic and the floors, and its
place, from the known start: the images alone hold neither, and a free adjustment drifted
5 % in scale on apartment 6, 17 % on apartment 5), but the placement may turn as a whole
about the start onto the compass (one angle: each model's heading was a compromise of its
own SfM yaws, and apartment 8's map was 3.3 degrees off); the unknowns are that angle, one
robot heading per photo, held to its compass reading, and every point; the camera is where
the mount puts it, at its known height and tilt. Where the floor measured the lengths
between stops (`RigObservations.spans`, `floor_scale.stop_spans`), the stops move too, held
to the placement by a few centimetres and to those lengths: they hold the scale, and the
photos straighten a model SfM stretched unevenly (apartment 14's first map: 4.5 % off in
scale, 0.02 % so; `MapConfig.floor_spans`). Photos of the circles that no model posed (they
face bare walls) join through their verified matches with posed photos' points, starting
at their compass reading. The points start triangulated (DLT) from the cameras on the
rig; reprojection errors are made robust by iteratively reweighted least squares (Huber
weights, `huber_px`), each round solved by scipy's sparse trust-region least squares.
On apartment 6's random stage (85 photos, 13,000 observations) the photos' yaw errors went
from 1.31 / 2.74 / 4.86 degrees (median / p90 / max) to 0.09 / 0.28 / 0.45, and the
reprojection from 0.32 px (SfM's own, six free degrees a photo) to 0.20 px; the truth on
the rig gives 0.14 px.
Frames: world metres, z up, floor z = 0; SE(2) robot poses (x, y, theta); pixels with
ibrnav's convention (pixel centres at integers).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix

from robot.mission.circles import rot2d


@dataclass(frozen=True)
class RigAdjustmentConfig:
    """Settings of `adjust_on_rig`."""

    huber_px: float = 2.0
    """Reprojection error (px) beyond which an observation's weight falls as 1 / error
    (Huber): SIFT's keypoints are good to about a pixel, a wrong match is off by tens."""
    compass_sigma_rad: float = np.radians(2.0)
    """The compass's noise per reading (rad; the robot's sensor, `CircleConfig.compass_sigma_rad`)."""
    max_start_error_px: float = 40.0
    """An observation further than this from its point triangulated on the rig before any
    adjustment is left out: SfM's poses put on the rig move a camera by up to the mount's
    5 cm and turn it by about a degree, 5-15 px at the robot's 1-3 m; a point further off
    is one SfM triangulated a few centimetres from a camera, between two photos of one
    circle whose nearly parallel rays fix no depth. In pixels of the robot's 320 x 240
    photos (focal length 277 px): a camera of another resolution would scale it with its
    focal length (about 8 degrees)."""
    max_error_px: float = 4.0
    """An observation further than this from its adjusted point is an outlier; a point left
    with fewer than two observations is dropped from the map."""
    rounds: int = 2
    """Reweighting rounds (on apartment 6 the second brought the worst photo from 0.80 to 0.45
    degrees off)."""
    max_evaluations: int = 30
    """Least-squares evaluations per round."""
    min_joining_points: int = 15
    """Fewest points a photo no SfM model posed must see, once adjusted, to join the map
    (COLMAP's `abs_pose_min_num_inliers` is 30 for six unknowns; the rig leaves one)."""
    stop_sigma_m: float | None = 0.05
    """When the observations name each photo's stop (`RigObservations.stop`; the map names
    them only with the floor's spans, which hold the scale), the stops' robot positions are
    unknowns too, each held to the placement's by this (m; None: held fixed): the placement
    takes its lengths between stops from SfM's models, whose photos had six free degrees,
    and a model can be stretched unevenly (apartment 14: one model's 1.8 m from its second
    to its third stop read 5.6 % shorter, against its 0.6 m from the first to the second,
    than the truth; the stop 8 cm off). The few centimetres a placement's stop is off: an
    error of the placement (SfM's 1 cm photos, the odometry between stops), not a length of
    any scene; the scale is the spans' to hold, and a stop in a larger room is no less sure."""
    start_sigma_m: float = 0.005
    """... and the first stop (`RigObservations.pivot`, the known start) by this (m): the
    odometry's noise at the start (`CircleConfig.odometry_sigma_m`)."""


@dataclass
class RigObservations:
    """What `adjust_on_rig` fits: `photo` (M,) and `point` (M,) indices of each observation
    into `photos` and `points`, `uv` (M, 2) its pixel; `photos` (n,) photo numbers, `xy`
    (n, 2) the robot position of each (its circle's, m), `heading` (n,) its robot heading
    (rad), `compass` (n,) its compass reading (rad); `points` (P, 3) world metres, `colors`
    (P, 3) uint8."""

    photo: np.ndarray
    point: np.ndarray
    uv: np.ndarray
    photos: np.ndarray
    xy: np.ndarray
    heading: np.ndarray
    compass: np.ndarray
    points: np.ndarray
    colors: np.ndarray
    pivot: np.ndarray
    """(2,) m: the first circle's centre, the known start, about which the placement may turn
    as a whole (`turned`)."""
    joining: np.ndarray
    """(n,) bool: photos no SfM model posed, joining by their matches with posed photos'
    points; their `heading` is their compass reading."""
    stop: np.ndarray | None = None
    """(n,) each photo's stop (its circle's number), whose robot position `xy` all its photos
    share: the stops move in the adjustment (`RigAdjustmentConfig.stop_sigma_m`; None: the
    positions are held)."""
    spans: dict = field(default_factory=dict)
    """{(a, b): (m, relative sigma)} the floor's measures of the distances between stops a
    and b (`floor_scale.stop_spans`), which hold the adjusted stops' scale."""


def turned(xy: np.ndarray, alpha: float, pivot: np.ndarray) -> np.ndarray:
    """Positions `xy` (n, 2) m turned by `alpha` rad about `pivot` (2,) m."""
    return (np.asarray(xy) - pivot) @ rot2d(alpha).T + pivot


def cameras_on_rig(xy: np.ndarray, theta: np.ndarray, cam_from_robot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3, 3) rotations cam_from_world and (n, 3) translations of the cameras of robots
    standing on the floor at positions `xy` (n, 2) m with headings `theta` (n,) rad."""
    c, s = np.cos(theta), np.sin(theta)
    robot_from_world = np.zeros((len(theta), 3, 3))
    robot_from_world[:, 0, 0], robot_from_world[:, 0, 1] = c, s
    robot_from_world[:, 1, 0], robot_from_world[:, 1, 1] = -s, c
    robot_from_world[:, 2, 2] = 1.0
    R = cam_from_robot[:3, :3] @ robot_from_world
    robot_t = -np.einsum("nij,nj->ni", robot_from_world[:, :, :2], xy)
    return R, robot_t @ cam_from_robot[:3, :3].T + cam_from_robot[:3, 3]


def reprojections(theta: np.ndarray, points: np.ndarray, obs: RigObservations, K: np.ndarray,
                  cam_from_robot: np.ndarray) -> np.ndarray:
    """(M, 2) pixel of each observation's point in its photo's camera, the photos at
    headings `theta` (n,) and the points at `points` (P, 3)."""
    R, t = cameras_on_rig(obs.xy, theta, cam_from_robot)
    pc = np.einsum("mij,mj->mi", R[obs.photo], points[obs.point]) + t[obs.photo]
    uvw = pc @ K.T
    return uvw[:, :2] / np.maximum(uvw[:, 2:3], 1e-3)


def triangulate(theta: np.ndarray, obs: RigObservations, K: np.ndarray, cam_from_robot: np.ndarray) -> np.ndarray:
    """(P, 3) the points triangulated (linear, DLT) from their observations in the cameras
    at headings `theta`; a point with one observation keeps its place."""
    R, t = cameras_on_rig(obs.xy, theta, cam_from_robot)
    P = np.einsum("ij,njk->nik", K, np.concatenate([R, t[:, :, None]], axis=2))[obs.photo]
    rows = np.concatenate([obs.uv[:, :1] * P[:, 2] - P[:, 0], obs.uv[:, 1:] * P[:, 2] - P[:, 1]])
    owner = np.r_[obs.point, obs.point]
    order = np.argsort(owner, kind="stable")
    bounds = np.searchsorted(owner[order], np.arange(len(obs.points) + 1))
    out = obs.points.copy()
    for j in np.flatnonzero(np.diff(bounds) >= 4):
        X = np.linalg.svd(rows[order[bounds[j]:bounds[j + 1]]])[2][-1]
        if abs(X[3]) > 1e-12:
            out[j] = X[:3] / X[3]
    return out


def _kept(obs: RigObservations, good: np.ndarray) -> RigObservations:
    """`obs` with only the `good` (M,) observations of points that keep two or more."""
    seen = np.bincount(obs.point[good], minlength=len(obs.points)) >= 2
    good = good & seen[obs.point]
    return replace(obs, photo=obs.photo[good], point=obs.point[good], uv=obs.uv[good])


class _Stops:
    """The stops' robot positions as unknowns of `adjust_on_rig` (`RigObservations.stop`):
    `index` (n,) each photo's stop among the `start` (C, 2) positions (the placement's, m),
    `sigma` (C,) their priors (m; the first stop's, at the known start, tighter) and the
    `spans` [(stop a, stop b, length m, relative sigma)] between them."""

    def __init__(self, obs: RigObservations, config: RigAdjustmentConfig):
        numbers, first, self.index = np.unique(obs.stop, return_index=True, return_inverse=True)
        self.start = obs.xy[first]
        at_start = np.linalg.norm(self.start - obs.pivot, axis=1) < 1e-9
        self.sigma = np.where(at_start, config.start_sigma_m, config.stop_sigma_m)
        slot = {int(k): c for c, k in enumerate(numbers)}
        self.spans = [(slot[a], slot[b], length, sigma) for (a, b), (length, sigma) in obs.spans.items()
                      if a in slot and b in slot]

    def residuals(self, stops: np.ndarray, alpha: float, pivot: np.ndarray) -> np.ndarray:
        """Each stop at the placement's (turned by `alpha` about `pivot`), and each span's length."""
        prior = (stops - turned(self.start, alpha, pivot)) / self.sigma[:, None]
        spans = [(np.linalg.norm(stops[b] - stops[a]) / length - 1.0) / sigma for a, b, length, sigma in self.spans]
        return np.r_[prior.ravel(), spans]


def _sparsity(obs: RigObservations, stops: _Stops | None):
    """Which unknowns (the placement's turn, headings, the stops' positions when they move,
    then points' xyz) each residual (u, v of each observation, each photo's compass, then the
    stops' priors and spans) depends on."""
    n, P, M = len(obs.photos), len(obs.points), len(obs.photo)
    C = 0 if stops is None else len(stops.start)
    rows = 2 * M + n + (0 if stops is None else 2 * C + len(stops.spans))
    S = lil_matrix((rows, 1 + n + 2 * C + 3 * P), dtype=np.uint8)
    for r in (2 * np.arange(M), 2 * np.arange(M) + 1):
        S[r, 0] = 1
        S[r, 1 + obs.photo] = 1
        for d in range(3):
            S[r, 1 + n + 2 * C + 3 * obs.point + d] = 1
        if stops is not None:
            for d in range(2):
                S[r, 1 + n + 2 * stops.index[obs.photo] + d] = 1
    S[2 * M + np.arange(n), 1 + np.arange(n)] = 1
    if stops is not None:
        r0 = 2 * M + n
        for c in range(C):
            S[r0 + 2 * c:r0 + 2 * c + 2, [0, 1 + n + 2 * c, 1 + n + 2 * c + 1]] = 1
        for k, (a, b, _, _) in enumerate(stops.spans):
            S[r0 + 2 * C + k, [1 + n + 2 * a, 1 + n + 2 * a + 1, 1 + n + 2 * b, 1 + n + 2 * b + 1]] = 1
    return S


@dataclass
class RigFit:
    """`adjust_on_rig`'s answer: `alpha` the placement's turn about `RigObservations.pivot`
    (rad, `turned`), `theta` (n,) the photos' headings (rad), `xy` (n, 2) their robot
    positions (m: the placement's turned by `alpha`, or their stops' adjusted), `posed` (n,)
    which photos it poses (those SfM posed, and the joining ones seen by
    `min_joining_points` points within four compass sigmas of their compass), `points`
    (P, 3) m, `kept` (P,) the points seen within `max_error_px` by two photos or more, and
    the median reprojection error (px) of the kept observations before and after (the points
    triangulated on the rig)."""

    alpha: float
    theta: np.ndarray
    xy: np.ndarray
    posed: np.ndarray
    points: np.ndarray
    kept: np.ndarray
    before_px: float
    after_px: float


def adjust_on_rig(obs: RigObservations, K: np.ndarray, cam_from_robot: np.ndarray,
                  config: RigAdjustmentConfig = RigAdjustmentConfig()) -> RigFit:
    """Refine `obs` on the robot's rig (module docstring). The points start triangulated
    from the photos SfM posed; a point left out of the adjustment is triangulated again from
    the adjusted cameras; a photo SfM posed and left with no observation keeps SfM's turn.
    The stops move too when `obs.stop` names them and `config.stop_sigma_m` is set."""
    n = len(obs.photos)
    stops = _Stops(obs, config) if obs.stop is not None and config.stop_sigma_m is not None else None
    C = 0 if stops is None else len(stops.start)

    def unpack(x):
        """(turn, headings (n,), stops (C, 2), points (P, 3)): views of the unknowns `x`."""
        return x[0], x[1:n + 1], x[1 + n:1 + n + 2 * C].reshape(-1, 2), x[1 + n + 2 * C:].reshape(-1, 3)

    def positions(x) -> np.ndarray:
        alpha, _, stop_xy, _ = unpack(x)
        return turned(obs.xy, alpha, obs.pivot) if stops is None else stop_xy[stops.index]

    points = triangulate(obs.heading, _kept(obs, ~obs.joining[obs.photo]), K, cam_from_robot)
    start = np.linalg.norm(reprojections(obs.heading, points, obs, K, cam_from_robot) - obs.uv, axis=1)
    fit = _kept(obs, start <= config.max_start_error_px)
    x = np.r_[0.0, obs.heading, [] if stops is None else stops.start.ravel(), points.ravel()]
    S = _sparsity(fit, stops)
    for _ in range(config.rounds):
        _, theta, _, points = unpack(x)
        err = np.linalg.norm(reprojections(theta, points, replace(fit, xy=positions(x)), K, cam_from_robot) - fit.uv,
                             axis=1)
        w = np.sqrt(np.minimum(1.0, config.huber_px / np.maximum(err, 1e-9)))[:, None]

        def residuals(x):
            alpha, theta, stop_xy, points = unpack(x)
            px = (reprojections(theta, points, replace(fit, xy=positions(x)), K, cam_from_robot) - fit.uv) * w
            out = [px.ravel(), np.angle(np.exp(1j * (theta - fit.compass))) / config.compass_sigma_rad]
            if stops is not None:
                out.append(stops.residuals(stop_xy, alpha, obs.pivot))
            return np.concatenate(out)

        x = least_squares(residuals, x, jac_sparsity=S, method="trf", x_scale="jac",
                          max_nfev=config.max_evaluations).x
    alpha, theta, _, points = unpack(x)
    alpha = float(alpha)
    obs = replace(obs, xy=positions(x))
    unseen = np.bincount(fit.photo, minlength=n) == 0  # only its compass held it: SfM's turn is better
    theta[unseen] = obs.heading[unseen] + alpha
    loose = np.bincount(fit.point, minlength=len(points)) == 0  # left out at the start: triangulated again
    points[loose] = triangulate(theta, _kept(obs, ~obs.joining[obs.photo]), K, cam_from_robot)[loose]
    after = np.linalg.norm(reprojections(theta, points, obs, K, cam_from_robot) - obs.uv, axis=1)
    good = after <= config.max_error_px
    kept = np.bincount(obs.point[good], minlength=len(points)) >= 2
    inliers = good & kept[obs.point]
    seen = np.bincount(obs.photo[inliers], minlength=n)
    agrees = np.abs(np.angle(np.exp(1j * (theta - obs.compass)))) <= 4 * config.compass_sigma_rad
    posed = ~obs.joining | ((seen >= config.min_joining_points) & agrees)

    def median(e):
        return float(np.median(e)) if e.size else float("nan")

    return RigFit(alpha, theta, obs.xy, posed, points, kept, median(start[inliers]), median(after[inliers]))
