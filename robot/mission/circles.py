"""The random stage's circles of photos tie its SfM models together (Foster, Wang & Grupen,
section IV-A: the robot turns in place through a circle of photos, then drives on).

Incremental SfM of a random stage breaks into several models, not one per room but one per
*sector of headings*: a circle's photos are a pure rotation about one centre (the camera
sits `mount` metres off the turning axis, 5 cm), so only the matches *between* circles
give depth, and wherever one circle faces a textureless wall (or a wall close up) no point
is triangulated in that sector, the incremental mapper cannot register the next photo, and
a new model starts (apartment seeds 0-9: 1-5 models; the largest held 19-31 of 108 photos on
4 seeds). Every model spans at least two circles (a model needs a baseline), and all the
photos of a circle were taken from one robot position. So:

- `place_models` puts every model in the floor frame at once: one unknown centre per
  circle, one similarity per model (scale, heading, shift), fitted by least squares to
  the models' camera positions (each camera lies `mount` from its circle's centre), the
  compass (heading), the floor's scale where a model found its floor, the ultrasonic's
  scale (`map_building.sonar_scale`, weighted by its own error), and the dead
  reckoning of the circles' centres (the first circle stands at the known start);
- `complete_circles` poses a photo no model registered from a posed photo of its own
  circle: the rotation between the two from their matched features (a pure rotation: the
  bearings' Procrustes fit), the turn divided by the circle's `turn_gains` (the camera's
  swing about the axle reads as 2-5 % more turn; the compass measures how much), the
  position from the circle's centre.

Frames: world metres, z up, floor z = 0; levelled model frames: z along the cameras' up.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from localization.motion_models import wrap_angle


@dataclass(frozen=True)
class CircleConfig:
    """Settings of `place_models` and `complete_circles`."""

    circle_move_m: float = 0.1
    """Two photos in a row belong to one circle when the dead reckoning moved less than this
    between them (m): a 10 degree turn in place moves it by the odometry's noise (~1 cm),
    a drive between circles by 0.6-2 m (`RandomExplorationConfig`); the robot's, not the scene's."""
    photo_sigma_m: float = 0.01
    """SfM's noise on a camera's position, once in metres (m)."""
    compass_sigma_rad: float = np.radians(2.0)
    """The compass's noise per reading (rad; the robot's sensor)."""
    odometry_sigma_m: float = 0.005
    """Dead reckoning's noise at the known start (m)."""
    odometry_drift: float = 0.15
    """Dead reckoning's noise per metre driven between two circles (the simulated odometry
    is ~14 % off per drive; the robot's, not the scene's)."""
    floor_sigma: float = 0.03
    """Relative noise of a model's scale from a floor plane held by `floor_sure_points` or more
    points (`map_building.floor_depth`) ...: measured against the truth over every saved SfM
    run's models, such floors were 1.4-1.6 % off at the median and 5-8 % at the 90th
    percentile (offices 0-4 and the demo; apartments 0-9), so not the 1 % once assumed.
    Floors from the points two circles saw (as now): of the largest models of one SfM run
    of apartments 0-19 and offices 0-4, the 18 whose floor 50 points or more held were
    0.6 % off at the median and 2.8 % at the 90th percentile, one 10.7 % (apartment 3) ..."""
    floor_unsure_sigma: float = 0.10
    """... and from one held by fewer: 0.9-26 % off at the median (12-49 points: furniture
    tops, stray layers). A share, as the floor's scale is a ratio; the floor plane's, not the
    scene's."""
    sonar_min_sigma: float = 0.01
    """The least relative noise of a model's ultrasonic scale (`map_building.sonar_scale`):
    its 1 cm over ranges of 0.3-2.5 m."""
    floor_trust: float = np.log(1.25)
    """A floor's scale further than this (log) from the odometry's is wrong ..."""
    floor_sure_points: int = 50
    """... unless this many points hold it (then only beyond twice `floor_trust`, as the
    odometry of a drive with bumps and back-ups was 27 % off): a small model's "floor" held
    by fewer was often a furniture top or a stray layer (apartment seeds 1, 3, 6, 9: 12-48
    points, 0.27-2.3 times the true scale), while the floors of 50 points or more were
    within 5 % (seeds 0-9). A count of points, as `floor_depth`'s `min_points`."""
    max_turn_rad: float = np.radians(15.0)
    """A model whose circles lie further than this from the directions the robot drove is
    wrong (rad): the compass-aided odometry's heading (2 degrees) and the mount's bias on a
    circle's mean (5 cm over >= 0.6 m) are well within it; the robot's, not the scene's."""
    max_rms_m: float = 0.05
    """A model whose cameras miss their circles by more than this (RMS, m) is dropped as wrong."""
    max_photo_turn_rad: float = np.radians(10.0)
    """A photo whose SfM yaw, in its model turned onto the compass, lies further than this
    from its compass heading was registered wrong (rad): five compass sigmas. SfM's wrong
    registrations in the apartments' random stages were 12-24 degrees off, its right ones
    within 7 (the robot's compass, not the scene)."""
    max_photo_miss_m: float = 0.15
    """A photo whose robot position (its camera less the mount), once placed, lies further
    than this from the median of its circle's photos in its model was registered wrong (m):
    all the photos of a circle were taken from one point, and SfM's right registrations
    were within 5 cm of it, its wrong ones 0.2-1.2 m off; three times `max_rms_m`."""
    min_matches: int = 15
    """Fewest feature matches to turn a photo by (COLMAP's `min_num_matches`)."""
    max_angle_px: float = 2.0
    """A match further than this from the fitted rotation (pixels) is an outlier."""
    max_gain_sigma: float = 0.01
    """`turn_gains` corrects a circle only where its slope's standard error is within this
    (a ratio): a chain's gain matters at 1 % and more (0.1 degree per 10 degree step)."""


@dataclass
class LevelledModel:
    """One SfM model in its levelled frame (z along the cameras' up): photo indices `idx`
    (n,), camera centres `xy` (n, 2) in model units, camera yaws `yaw` (n,) rad,
    `floor_scale` metres per model unit from its floor plane (None: no floor found) and
    `floor_points` the points that hold that floor; `sonar_scale` from the ultrasonic."""

    idx: np.ndarray
    xy: np.ndarray
    yaw: np.ndarray
    floor_scale: float | None
    floor_points: int = 0
    sonar_scale: float | None = None
    """Metres per model unit from the ultrasonic (`map_building.sonar_scale`; None: none)."""
    sonar_sigma: float = 0.0
    """Its relative standard error."""


@dataclass
class Placement:
    """The floor-frame similarity of each kept model: `models` {model number: (scale m per
    unit, heading rad, shift (2,) m)}, and `centres` {circle: robot position (2,) m}."""

    models: dict[int, tuple[float, float, np.ndarray]]
    centres: dict[int, np.ndarray]
    photos: dict[int, np.ndarray] = field(default_factory=dict)
    """{model number: its photos kept (n,)}: those registered wrong are left out."""


def circle_ids(estimates: np.ndarray, config: CircleConfig = CircleConfig()) -> np.ndarray:
    """(N,) circle number of each photo from the dead-reckoning poses `estimates` (N, 3):
    a new circle starts where the robot moved `circle_move_m` or more since the last photo."""
    step = np.hypot(*np.diff(np.asarray(estimates, float)[:, :2], axis=0).T)
    return np.r_[0, np.cumsum(step >= config.circle_move_m)].astype(int)


def _sure_floor(model: LevelledModel, config: CircleConfig) -> bool:
    """Whether `floor_sure_points` or more points hold the model's floor."""
    return model.floor_points >= config.floor_sure_points


def rot2d(a) -> np.ndarray:
    """2-D rotation matrices (..., 2, 2) of angles `a` (rad)."""
    c, s = np.cos(a), np.sin(a)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


class _Problem:
    """The least-squares problem of `place_models` over the models `keep`. Unknowns: per model
    (log scale, heading rad, shift x, y m), per circle its robot position (x, y m). Residuals,
    each over its sigma: a model's cameras less the mount, averaged per circle, at the
    circle's centre; its cameras' yaws at the compass; its scale at its floor's (`floors`)
    and the ultrasonic's (`sonars`: scale, relative sigma); the first circle at the known
    start and each later one an odometry drive from the last; and the distance between two
    circles' centres at the floor's measure of it (`spans` {(a, b): (m, relative sigma)},
    `floor_scale.stop_spans`)."""

    def __init__(self, models, keep, circle, heading, dr_xy, driven_m, mount_xy, mount_yaw, config, floors,
                 sonars=None, spans=None):
        self.models, self.keep, self.cfg, self.floors, self.sonars = models, keep, config, floors, sonars or {}
        # every circle up to the last a model holds: the dead reckoning chains them from the start
        self.circles = list(range(max(int(circle[i]) for m in keep for i in models[m].idx) + 1))
        self.col = {k: k for k in self.circles}
        self.circle, self.heading, self.mount_xy, self.mount_yaw = circle, heading, mount_xy, mount_yaw
        first = [int(np.flatnonzero(circle == k)[0]) for k in self.circles]
        self.dr = dr_xy[first]
        self.dr_step = np.diff(self.dr, axis=0)
        self.dr_sigma = np.r_[config.odometry_sigma_m, config.odometry_sigma_m
                              + config.odometry_drift * np.diff(np.asarray(driven_m)[first])]
        self.spans = {ab: v for ab, v in (spans or {}).items() if max(ab) < len(self.circles)}

    def unpack(self, x):
        n = 4 * len(self.keep)
        return x[:n].reshape(-1, 4), x[n:].reshape(-1, 2)

    def residuals(self, x) -> np.ndarray:
        sim, centres = self.unpack(x)
        # the start is known; each drive between circles is odometry's, `odometry_drift` of it off
        steps = np.vstack([centres[:1] - self.dr[:1], np.diff(centres, axis=0) - self.dr_step])
        out = [steps.ravel() / np.repeat(self.dr_sigma, 2)]
        for (a, b), (length, sigma) in self.spans.items():
            out.append(np.atleast_1d((np.linalg.norm(centres[b] - centres[a]) / length - 1.0) / sigma))
        for (log_s, a, tx, ty), m in zip(sim, self.keep):
            mod = self.models[m]
            yaw = a + mod.yaw
            cam = np.exp(log_s) * mod.xy @ rot2d(a).T + [tx, ty]
            robot = cam - rot2d(yaw - self.mount_yaw) @ self.mount_xy
            # each circle's cameras, less the mount, meet at its centre; their mean is the
            # measurement (a circle's cameras are only the mount apart, too little to scale by)
            ks = self.circle[mod.idx]
            for k in np.unique(ks):
                on = ks == k
                miss = robot[on].mean(0) - centres[self.col[int(k)]]
                # SfM's noise is in the model's own units: a model shrunk to a point fits no better
                out.append(miss * np.sqrt(on.sum()) * (self.s0[m] / np.exp(log_s)) / self.cfg.photo_sigma_m)
            out.append(wrap_angle(yaw - self.heading[mod.idx]) / self.cfg.compass_sigma_rad)
            if m in self.floors:
                sigma = self.cfg.floor_sigma if _sure_floor(mod, self.cfg) else self.cfg.floor_unsure_sigma
                out.append(np.atleast_1d((log_s - np.log(self.floors[m])) / sigma))
            if m in self.sonars:
                scale, sigma = self.sonars[m]
                out.append(np.atleast_1d((log_s - np.log(scale)) / max(sigma, self.cfg.sonar_min_sigma)))
        return np.concatenate(out)

    def start(self, dr_cam_xy: np.ndarray) -> np.ndarray:
        """Heading from the compass, scale and shift from a 2-D fit onto the dead reckoning."""
        x = []
        for m in self.keep:
            mod = self.models[m]
            a = float(np.angle(np.mean(np.exp(1j * (self.heading[mod.idx] - mod.yaw)))))
            p, q = mod.xy @ rot2d(a).T, dr_cam_xy[mod.idx]
            pc, qc = p - p.mean(0), q - q.mean(0)
            s = mod.floor_scale or mod.sonar_scale or max(float(np.sum(pc * qc) / max(np.sum(pc * pc), 1e-12)), 1e-6)
            x += [np.log(s), a, *(q.mean(0) - s * p.mean(0))]
        return np.r_[x, self.dr.ravel()]

    def solve(self, dr_cam_xy: np.ndarray) -> np.ndarray:
        x0 = self.start(dr_cam_xy)
        self.s0 = dict(zip(self.keep, np.exp(x0[:4 * len(self.keep):4])))
        return least_squares(self.residuals, x0).x

    def robots(self, x) -> dict[int, np.ndarray]:
        """{model: (n, 2) robot positions (m) of its photos, placed: the cameras less the mount}."""
        sim, _ = self.unpack(x)
        out = {}
        for (log_s, a, tx, ty), m in zip(sim, self.keep):
            mod = self.models[m]
            cam = np.exp(log_s) * mod.xy @ rot2d(a).T + [tx, ty]
            out[m] = cam - rot2d(a + mod.yaw - self.mount_yaw) @ self.mount_xy
        return out

    def rms_m(self, x) -> dict[int, float]:
        """Each model's RMS miss (m) of its cameras from their circles."""
        _, centres = self.unpack(x)
        out = {}
        for m, robot in self.robots(x).items():
            c = centres[[self.col[int(k)] for k in self.circle[self.models[m].idx]]]
            out[m] = float(np.sqrt(np.mean(np.sum((robot - c) ** 2, axis=1))))
        return out

    def strays(self, x) -> dict[int, np.ndarray]:
        """{model: (n,) bool} its photos whose robot position lies over `max_photo_miss_m`
        from the median of their circle's in that model (a wrong registration; the median
        because a few wrong ones pull the circle's fitted centre towards them)."""
        out = {}
        for m, robot in self.robots(x).items():
            ks = self.circle[self.models[m].idx]
            miss = np.zeros(len(ks))
            for k in np.unique(ks):
                on = ks == k
                miss[on] = np.linalg.norm(robot[on] - np.median(robot[on], axis=0), axis=1)
            out[m] = miss > self.cfg.max_photo_miss_m
        return out


def _scaled(models: list[LevelledModel], keep: list[int], circle: np.ndarray, floors: dict,
            apart, spans=()) -> set[int]:
    """The models whose scale is known: a floor of their own, two circles the floor measured
    the distance between (`spans`, pairs of circles), or two circles shared with models whose
    scale is known that `apart(k0, k1)` says a drive lies between (two robot
    positions fix a length only when they are apart: apartment 5's robot came back to
    within 5 cm of its first circle, and that "length" scaled a model 2.5 times too small)."""
    held = {m: set(np.unique(circle[models[m].idx]).tolist()) for m in keep}
    known = set(floors) | {m for m in keep if any(a in held[m] and b in held[m] for a, b in spans)}
    grew = True
    while grew:
        grew = False
        known_circles = {int(c) for m in known for c in np.unique(circle[models[m].idx])}
        for m in keep:
            shared = sorted(known_circles & set(np.unique(circle[models[m].idx]).tolist()))
            if m not in known and any(apart(k0, k1) for j, k0 in enumerate(shared) for k1 in shared[j + 1:]):
                known.add(m)
                grew = True
    return known


def _subset(model: LevelledModel, keep: np.ndarray) -> LevelledModel:
    """The model with only its photos `keep` (n,) bool."""
    return replace(model, idx=model.idx[keep], xy=model.xy[keep], yaw=model.yaw[keep])


def facing_compass(model: LevelledModel, heading: np.ndarray, config: CircleConfig = CircleConfig()) -> np.ndarray:
    """(n,) bool: the model's photos whose yaw, turned onto the compass `heading` (N,) rad
    by the model's heading (the circular mean of compass minus yaw, refitted without the
    photos beyond the limit), lies within `max_photo_turn_rad` of their compass heading."""
    d = heading[model.idx] - model.yaw
    ok = np.ones(len(d), bool)
    for _ in range(2):
        a = float(np.angle(np.mean(np.exp(1j * d[ok])))) if ok.any() else 0.0
        ok = np.abs(wrap_angle(d - a)) <= config.max_photo_turn_rad
    return ok


def _circle_means(model: LevelledModel, circle: np.ndarray, heading: np.ndarray) -> dict[int, np.ndarray]:
    """{circle: the mean (2,) of the model's cameras on it}, in model units, turned by the
    compass (the model's heading: the circular mean of compass minus model yaw)."""
    a = float(np.angle(np.mean(np.exp(1j * (heading[model.idx] - model.yaw)))))
    p = model.xy @ rot2d(a).T
    ks = circle[model.idx]
    return {int(k): p[ks == k].mean(0) for k in np.unique(ks)}


def _drive_sigma_m(k0: int, k1: int, circle: np.ndarray, driven_m: np.ndarray, config: CircleConfig) -> float:
    """The odometry's noise (m) on the step from circle k0 to circle k1 (`odometry_drift` of
    the distance driven between their first photos)."""
    first = [int(np.flatnonzero(circle == k)[0]) for k in (k0, k1)]
    return config.odometry_sigma_m + config.odometry_drift * abs(driven_m[first[1]] - driven_m[first[0]])


def _apart(k0: int, k1: int, circle: np.ndarray, dr_xy: np.ndarray, driven_m: np.ndarray,
           config: CircleConfig) -> bool:
    """Whether the odometry's step from circle k0 to k1 is longer than three times its noise:
    only such a step tells a direction and a length."""
    first = [int(np.flatnonzero(circle == k)[0]) for k in (k0, k1)]
    step = np.linalg.norm(dr_xy[first[1]] - dr_xy[first[0]])
    return bool(step > 3 * _drive_sigma_m(k0, k1, circle, driven_m, config))


def _drives(model: LevelledModel, circle: np.ndarray, heading: np.ndarray, dr_xy: np.ndarray,
            driven_m: np.ndarray, config: CircleConfig):
    """(model step (2,), odometry step (2,) m) between each two circles of the model in a row
    that are `_apart`: only those tell a direction and a length."""
    mean = _circle_means(model, circle, heading)
    ks = sorted(mean)
    first = {k: int(np.flatnonzero(circle == k)[0]) for k in ks}
    return [(mean[k1] - mean[k0], dr_xy[first[k1]] - dr_xy[first[k0]]) for k0, k1 in zip(ks[:-1], ks[1:])
            if _apart(k0, k1, circle, dr_xy, driven_m, config)]


def _drives_agree(model: LevelledModel, circle: np.ndarray, heading: np.ndarray, dr_xy: np.ndarray,
                  driven_m: np.ndarray, config: CircleConfig) -> bool:
    """Whether the directions between a model's circles (`_drives`) agree with the
    odometry's within `max_turn_rad` (compass-aided dead reckoning gets a drive's direction
    to a few degrees, its length only to ~15 %)."""
    return all(abs(np.angle(complex(*u) / complex(*v))) <= config.max_turn_rad
               for u, v in _drives(model, circle, heading, dr_xy, driven_m, config))


def _floor_agrees(model: LevelledModel, circle: np.ndarray, heading: np.ndarray, dr_xy: np.ndarray,
                  driven_m: np.ndarray, config: CircleConfig, scale: float | None = None) -> bool:
    """Whether a model's floor scale (or the `scale` given) is within `floor_trust` of the
    odometry's (the length of its drives, `_drives`, over theirs in the model); True when
    no drive tells a length."""
    steps = _drives(model, circle, heading, dr_xy, driven_m, config)
    if not steps:
        return True
    s_dr = sum(np.linalg.norm(v) for _, v in steps) / max(sum(np.linalg.norm(u) for u, _ in steps), 1e-12)
    if scale is not None:
        return abs(np.log(scale / s_dr)) < config.floor_trust
    trust = config.floor_trust * (2 if _sure_floor(model, config) else 1)
    return abs(np.log(model.floor_scale / s_dr)) < trust


def _floor_fits_sonar(floor: float, sonar: float, sonar_sigma: float, config: CircleConfig) -> bool:
    """Whether a model's floor scale lies within `floor_trust` of its ultrasonic scale, widened
    by three of the ultrasonic's sigmas (relative). A gross check, not a weighing: where the
    two differ by more, the floor was a furniture top or a stray layer of points: in the 84
    SfM models of 44 saved SfM runs (apartments 0-9, offices 0-4, the default demo),
    every floor that far from an ultrasonic the odometry accepted was 26 % to 390 times off,
    and that ultrasonic within 8 %. The demo's 13-point "floor" at 6.4 times its scale, in a
    model no drive checks, put the first map 1 m off in 3 of 14 SfM runs."""
    return abs(np.log(floor / sonar)) <= config.floor_trust + 3 * sonar_sigma


def place_models(models: list[LevelledModel], circle: np.ndarray, heading: np.ndarray, dr_xy: np.ndarray,
                 dr_cam_xy: np.ndarray, driven_m: np.ndarray, mount_xy: np.ndarray, mount_yaw: float,
                 config: CircleConfig = CircleConfig(), spans: dict | None = None) -> Placement:
    """Every model of `models` (largest first) in the floor frame (see the module's
    docstring). Per photo: `circle` (N,) its circle, `heading` (N,) its camera's compass yaw
    (rad), `dr_xy` (N, 2) the robot's and `dr_cam_xy` (N, 2) the camera's dead-reckoning
    position (m), `driven_m` (N,) the distance driven before it; `mount_xy` (2,) the camera's
    position on the robot (m) and `mount_yaw` its yaw there (rad); `spans` {(a, b): (m,
    relative sigma)} the floor's measures of the distances between circles' robot positions
    (`floor_scale.stop_spans`; None: none). A model whose scale nothing fixes (no floor or
    ultrasonic scale, no span between two of its circles, fewer than two circles shared with
    models that have one), or
    that misses its circles by over `max_rms_m`, is left out; when no model has a floor,
    the largest is kept with the odometry's scale. A floor that contradicts its model's
    ultrasonic (`_floor_fits_sonar`) is not used. Photos SfM registered wrong are left out
    of their model: those off the compass (`facing_compass`), then, once placed, those off
    their circle (`_Problem.strays`); the placement is solved again without them."""
    models = [_subset(m, _at_least_3(facing_compass(m, heading, config))) for m in models]
    floors = {m: model.floor_scale for m, model in enumerate(models)
              if model.floor_scale and _floor_agrees(model, circle, heading, dr_xy, driven_m, config)}
    sonars = {m: (model.sonar_scale, model.sonar_sigma) for m, model in enumerate(models) if model.sonar_scale
              and _floor_agrees(model, circle, heading, dr_xy, driven_m, config, model.sonar_scale)}
    floors = {m: f for m, f in floors.items() if m not in sonars or _floor_fits_sonar(f, *sonars[m], config)}
    # a model whose circles lie in other directions than the compass-aided odometry drove
    # is wrong (SfM's mirrored or folded solutions of two circles seen down a corridor)
    keep = [m for m in range(len(models)) if _drives_agree(models[m], circle, heading, dr_xy, driven_m, config)] or [0]
    apart = lambda k0, k1: _apart(k0, k1, circle, dr_xy, driven_m, config)  # noqa: E731
    while True:
        floors = {m: f for m, f in floors.items() if m in keep}
        sonars = {m: f for m, f in sonars.items() if m in keep}
        # keep only the models whose scale is known (the largest's, from odometry, when none is)
        known = {**floors, **sonars} or ({} if spans else {keep[0]: None})
        kept = [m for m in keep if m in _scaled(models, keep, circle, known, apart, spans or {})] or [keep[0]]
        prob = _Problem(models, kept, circle, heading, dr_xy, driven_m, mount_xy, mount_yaw, config, floors, sonars,
                        spans)
        x = prob.solve(dr_cam_xy)
        strays = {m: _at_least_3(~out) for m, out in prob.strays(x).items()}
        if not all(ok.all() for ok in strays.values()):
            models = [_subset(mod, strays[m]) if m in strays else mod for m, mod in enumerate(models)]
            keep = kept
            continue
        rms = prob.rms_m(x)
        bad = [m for m in kept if rms[m] > config.max_rms_m]
        if not bad or len(kept) == 1:
            break
        keep = [m for m in kept if m != max(bad, key=rms.get)]
    sim, centres = prob.unpack(x)
    held = {int(k) for m in kept for k in circle[models[m].idx]}
    return Placement({m: (float(np.exp(v[0])), float(v[1]), v[2:].copy()) for m, v in zip(kept, sim)},
                     {k: centres[j].copy() for k, j in prob.col.items() if k in held},
                     {m: models[m].idx.copy() for m in kept})


def _at_least_3(ok: np.ndarray) -> np.ndarray:
    """`ok` (n,) bool, or all True when it would leave fewer than 3 photos (a model needs 3;
    its circles' and scale's checks judge it whole)."""
    return ok if ok.sum() >= 3 else np.ones_like(ok)


def rotation_from_bearings(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation R (3x3) that best takes unit bearings `b` (M, 3) onto `a` (M, 3) (a_i ~ R b_i;
    Kabsch / Procrustes)."""
    U, _, Vt = np.linalg.svd(a.T @ b)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def pure_rotation(xy_i: np.ndarray, xy_j: np.ndarray, K: np.ndarray, config: CircleConfig = CircleConfig()):
    """cam_i_from_cam_j rotation (3x3) from matched pixels `xy_i`, `xy_j` (M, 2) of two photos
    taken from (nearly) one point with intrinsics `K`, refitted once without the matches
    more than `max_angle_px` off; None with fewer than `min_matches` (left) matches."""
    if len(xy_i) < config.min_matches:
        return None
    Kinv = np.linalg.inv(K)
    bi, bj = (np.c_[p, np.ones(len(p))] @ Kinv.T for p in (xy_i, xy_j))
    bi /= np.linalg.norm(bi, axis=1, keepdims=True)
    bj /= np.linalg.norm(bj, axis=1, keepdims=True)
    ok = np.ones(len(bi), bool)
    for _ in range(3):
        if ok.sum() < config.min_matches:
            return None
        R = rotation_from_bearings(bi[ok], bj[ok])
        ok = np.arccos(np.clip(np.sum(bi * (bj @ R.T), axis=1), -1, 1)) * K[0, 0] < config.max_angle_px
    return R if ok.sum() >= config.min_matches else None


def _yaw(world_from_cam: np.ndarray) -> float:
    """Heading (rad) of a camera's optical axis in the world's xy plane (of its world_from_cam
    (4, 4) or rotation (3, 3))."""
    return float(np.arctan2(world_from_cam[1, 2], world_from_cam[0, 2]))


def _turn(world_from_cam_j: np.ndarray, R: np.ndarray) -> float:
    """The turn (rad) from camera j to camera i, cam_i_from_cam_j rotation `R`, about the world's up."""
    return float(wrap_angle(_yaw(world_from_cam_j[:3, :3] @ R.T) - _yaw(world_from_cam_j)))


def turn_gains(circle: np.ndarray, heading: np.ndarray, matches, K: np.ndarray, reference: np.ndarray,
               config: CircleConfig = CircleConfig(), circles=None) -> dict[int, float]:
    """{circle: how far `pure_rotation` over-turns there}: the slope of the compass `heading`
    (N,) rad against the turns it chains from photo to photo of the circle (a least-squares
    line per run of matched neighbours, one slope for the circle). The camera sits ahead of
    the axle, so a turn in place swings it sideways too, and a rotation fitted to the image
    takes that parallax for more turn: by the mount over the scene's depth (5 cm at 1-2 m,
    about 3 %; chained over a gap of 27 photos in apartment 2's random stage it put the last
    one 8 degrees off). SfM's own poses of a circle over-turned alike (+0.2-0.3 degrees per
    step, apartments 7 and 9: its cameras are only the mount apart), so the compass, noisy
    but unbiased, is what measures it; over a circle's 360 degrees its 2 degrees per reading
    leave the slope ~0.3 % uncertain. One gain per circle, while the parallax follows the
    depth in each direction: a chain across a far wall is over-corrected (apartment 9:
    -0.25 degrees per step over 25 photos, +0.25 before). A circle whose slope is less sure than
    `max_gain_sigma` keeps 1 (no correction). `reference` (4, 4) world_from_cam of any posed
    photo: the mount's tilt, to read a rotation as a turn about the world's up. `circles`:
    the circles to measure (None: all)."""
    gains = {}
    for k in np.unique(circle) if circles is None else circles:
        ids = np.flatnonzero(circle == k)
        points = []  # (chained turn, compass heading, run) of each photo on a run
        r, at = 0, 0.0
        for a, b in zip(ids, ids[1:]):
            R = pure_rotation(*matches(int(b), int(a)), K, config)
            if R is None:
                r, at = r + 1, 0.0  # a new run: its own offset
                continue
            if not points or points[-1][2] != r:
                points.append((at, heading[a], r))
            at += _turn(reference, R)
            points.append((at, heading[b], r))
        x, y, run = np.array(points).reshape(-1, 3).T
        gains[int(k)] = _slope(x, y, run, config.max_gain_sigma)
    return gains


def _slope(x: np.ndarray, y: np.ndarray, run: np.ndarray, max_sigma: float) -> float:
    """The slope g of y ~ g x + c_run (common g, an offset per run; y unwrapped around x),
    or 1 when fewer than 6 points or its standard error exceeds `max_sigma`."""
    if len(x) < 6:
        return 1.0
    runs = np.unique(run)
    y = y.copy()
    for r in runs:  # each run's compass unwrapped around its own chain
        on = run == r
        d = wrap_angle(y[on] - x[on])
        y[on] = x[on] + wrap_angle(d - np.median(d))
    A = np.c_[x, (run[:, None] == runs[None, :]).astype(float)]
    if np.linalg.matrix_rank(A) < A.shape[1] or len(x) <= A.shape[1]:
        return 1.0
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ coef
    cov = np.linalg.inv(A.T @ A) * (resid @ resid) / (len(x) - A.shape[1])
    return float(1.0 / coef[0]) if np.sqrt(cov[0, 0]) <= max_sigma and coef[0] > 0 else 1.0


def complete_circles(world_from_cam: dict[int, np.ndarray], circle: np.ndarray, centres: dict[int, np.ndarray],
                     heading: np.ndarray, matches, K: np.ndarray, mount_xy: np.ndarray, mount_yaw: float,
                     camera_height_m: float, config: CircleConfig = CircleConfig()) -> dict[int, np.ndarray]:
    """world_from_cam (4x4) of the photos of the placed circles (`centres` {circle: robot
    position (2,) m}) that no model posed: turned from a posed photo of the same circle by
    the rotation of their matched features (`pure_rotation`; `matches(i, j)` gives the
    (M, 2) pixel pairs of photos i and j) about the world's up, divided by the circle's
    `turn_gains` (the mount's parallax, measured against the compass), nearest in the circle
    first, and placed `mount_xy` from the circle's centre at the camera's height. A photo
    whose rotation matches no posed neighbour, or turns it more than 4 compass sigmas off its
    compass `heading`, stays out. Photos posed here are themselves neighbours for the rest of
    their circle."""
    posed = dict(world_from_cam)
    if not posed:
        return {}
    gains = turn_gains(circle, heading, matches, K, next(iter(posed.values())), config, list(centres))
    added: dict[int, np.ndarray] = {}
    grew = True
    while grew:
        grew = False
        for i in np.flatnonzero(np.isin(circle, list(centres))):
            i = int(i)
            if i in posed:
                continue
            same = [j for j in posed if circle[j] == circle[i]]
            for j in sorted(same, key=lambda j: abs(j - i))[:4]:
                R = pure_rotation(*matches(i, j), K, config)
                if R is None:
                    continue
                yaw = _yaw(posed[j]) + _turn(posed[j], R) / gains[int(circle[i])]
                if abs(wrap_angle(yaw - heading[i])) > 4 * config.compass_sigma_rad:
                    continue
                T = np.eye(4)
                T[:3, :3] = Rotation.from_euler("z", yaw - _yaw(posed[j])).as_matrix() @ posed[j][:3, :3]
                T[:2, 3] = centres[int(circle[i])] + rot2d(yaw - mount_yaw) @ mount_xy
                T[2, 3] = camera_height_m
                posed[i] = added[i] = T
                grew = True
                break
    return added
