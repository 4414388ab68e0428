"""Global search of a level camera's photo over every position and heading of a map, with
one cylindrical panorama per position: the poses that a global (re-)initialisation of the
SE(2) filter starts from.

Why: a uniform prior cannot hit the likelihood's basin in a large free space. In the
40 x 40 m courtyard (1400 m^2) the basin's half-widths are ~0.4 m and ~8 deg, i.e. ~60,000
basin cells, and a 6000-particle prior puts a particle in about one in ten of them: the
truth is usually not in the cloud, and no amount of motion brings it in. One photo does not
single out the place either (the view at the truth ranked 0 to ~1000th of 200,000 grid
poses, the best wrong poses fitting as well as the truth, measured on courtyard 3), but
its top poses do contain the truth. So the filter starts from the poses the first photo
does not rule out (the measurement's own samples: mixture / dual MCL, Thrun et al. 2001),
and the motion separates them.

How: a level camera turning about its vertical axis sees the same cylinder of rays, only
shifted. At every position of a grid over the free space (spacing: the likelihood's
measured position basin) the map is rendered all round (`n_views` views of the robot
camera) and resampled to a cylindrical panorama; the photo is resampled to the same
cylinder over its field of view. The horizon-free NCC of the photo with every window of
the panorama (every heading, one panorama column apart) is a circular cross-correlation
per row (FFT), with sliding sums for the windows' row means and norms. The panoramas depend
only on the map and the camera, so they are rendered once and reused by every search.
Every square of the grid that the free space overlaps has a panorama (a robot drives along
walls and facades), and a track of photos is searched as well as one photo: each cell's
score is the mean of the photos' scores at the cells the odometry puts it in at their steps
(`track_scores`), which singles out a place that one photo fits as well as many others.

Frames: world, metres, radians; a panorama column c looks along world yaw -c * step (image
columns run clockwise, to the camera's right).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import shapely

from localization.level_view_likelihood import LevelViewLikelihood
from localization.motion_models import se2_backward
from localization.render_likelihood import luminance


def grid_positions(free: shapely.Geometry, spacing_m: float) -> np.ndarray:
    """(P, 2) one position per square of a grid of `spacing_m` that overlaps `free` by more
    than a thousandth of its area: the square's centre where that is free, else the centre
    of the square's free part (its centroid, or a point on its surface where the part is
    not convex). Every free point is thus within a square's diagonal of a position; with
    centres only, a robot driving along a wall or an obstacle was up to ~1.5 spacings from
    the nearest panorama (measured in courtyard 2: the truth's cell ranked 1,000-12,000th
    after a kidnapping, beyond every draw of the filter)."""
    lo_x, lo_y, hi_x, hi_y = free.bounds
    gx, gy = np.meshgrid(np.arange(lo_x + spacing_m / 2, hi_x + spacing_m / 2, spacing_m),
                         np.arange(lo_y + spacing_m / 2, hi_y + spacing_m / 2, spacing_m))
    xy = np.c_[gx.ravel(), gy.ravel()]
    h = spacing_m / 2
    squares = shapely.box(xy[:, 0] - h, xy[:, 1] - h, xy[:, 0] + h, xy[:, 1] + h)
    part = shapely.intersection(squares, free)
    keep = shapely.area(part) > 1e-3 * spacing_m**2
    xy, part = xy[keep], part[keep]
    inside = shapely.contains_xy(free, xy[:, 0], xy[:, 1])
    centre = shapely.centroid(part[~inside])
    centre = np.where(shapely.contains(part[~inside], centre), centre, shapely.point_on_surface(part[~inside]))
    xy[~inside] = shapely.get_coordinates(centre)
    return xy


@dataclass(frozen=True)
class Cylinder:
    """The resampling of a pinhole image (focal f px, principal point cx, cy, size w x h)
    onto a cylinder of the same focal length: column step 1 / f rad, rows at heights
    (v - cy_c) / f on the unit cylinder, `rows` of them (the pinhole image's height shrunk
    by cos(half field of view), so that every ray is inside it)."""

    f: float
    cx: float
    cy: float
    width: int
    height: int

    @property
    def n_cols(self) -> int:
        """Panorama columns all round (a multiple of 8)."""
        return int(8 * np.ceil(2 * np.pi * self.f / 8))

    @property
    def step(self) -> float:
        """Column step (rad)."""
        return 2 * np.pi / self.n_cols

    @property
    def half_fov(self) -> float:
        return float(np.arctan(max(self.cx + 0.5, self.width - 0.5 - self.cx) / self.f))

    @property
    def rows(self) -> int:
        return max(2, int(np.floor(self.height * np.cos(self.half_fov))))

    def maps(self, azimuths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """cv2.remap maps (rows, len(azimuths)) sampling the pinhole image at the columns'
        azimuths (rad, to the right of the optical axis)."""
        h = (np.arange(self.rows) - (self.rows - 1) / 2) / self.f
        a = np.asarray(azimuths)[None, :]
        u = self.f * np.tan(a) + self.cx + 0 * h[:, None]
        v = self.f * h[:, None] / np.cos(a) + self.cy
        return u.astype(np.float32), v.astype(np.float32)


def _camera_offset(cam_from_robot: np.ndarray) -> tuple[np.ndarray, float]:
    """The camera centre (2,) in the robot frame (m) and its optical axis's yaw (rad)
    relative to the robot's x axis."""
    robot_from_cam = np.linalg.inv(cam_from_robot)
    z = robot_from_cam[:3, 2]
    return robot_from_cam[:2, 3].copy(), float(np.arctan2(z[1], z[0]))


class PanoramaIndex:
    """Cylindrical panoramas of the map at a grid of positions, and the search of a photo
    over them. lik: the level-view likelihood (renderer, camera, mount); free: the free
    space; spacing_m: the grid's spacing; size: comparison size (w, h) px; n_views: views
    rendered per position (8: each contributes the central 45 deg, where the pinhole
    image is least stretched)."""

    track_photos = 8
    """Photos whose scores are kept (`photo_scores`): the longest track searched."""

    def __init__(self, lik: LevelViewLikelihood, free: shapely.Geometry, spacing_m: float,
                 size: tuple[int, int] = (32, 24), n_views: int = 8):
        cam = lik.camera.scaled(size[0] / lik.camera.width)
        self.size, self.spacing_m = size, spacing_m
        self.cyl = Cylinder(float(cam.K[0, 0]), float(cam.K[0, 2]), float(cam.K[1, 2]), *size)
        self.offset, self.yaw = _camera_offset(lik.cam_from_robot)
        self.free = free
        self.positions = grid_positions(free, spacing_m)
        self.panoramas = self._render(lik, n_views)
        # the grid's squares: a position lies in its own square (its centre, or its free part's)
        self._origin = np.array(free.bounds[:2])
        ij = np.floor((self.positions - self._origin) / spacing_m).astype(np.int64)
        self._square = np.full(ij.max(axis=0) + 1, -1, np.int64)
        """Position index of each grid square (ix, iy); -1: no panorama there."""
        self._square[ij[:, 0], ij[:, 1]] = np.arange(len(self.positions))
        self._scored: list[tuple[np.ndarray, np.ndarray]] = []
        self._ranked: list[tuple[np.ndarray, int, np.ndarray]] = []
        """The last two rankings: (photo, track length, flat scores)."""

    def _render(self, lik: LevelViewLikelihood, n_views: int) -> np.ndarray:
        """(P, rows, n_cols) float32 panoramas: `n_views` robot poses per position whose
        camera centre is the position, view k looking along yaw -k 2 pi / n_views."""
        cyl, C = self.cyl, self.cyl.n_cols
        per, h = C // n_views, C // n_views // 2
        # view k looks along yaw -k per step; its column j along yaw -(k per + j - h) step
        mx, my = cyl.maps((np.arange(per) - h) * cyl.step)
        yaws = -np.arange(n_views) * per * cyl.step
        out = np.empty((len(self.positions), cyl.rows, C), np.float32)
        for i in range(0, len(self.positions), 512):
            xy = self.positions[i:i + 512]
            poses = self.robot_poses(np.repeat(xy, n_views, axis=0), np.tile(yaws, len(xy)))
            views = lik.render(poses, self.size).astype(np.float32)
            cols = np.stack([cv2.remap(v, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
                             for v in views])  # (n * n_views, rows, per)
            cols = cols.reshape(len(xy), n_views, cyl.rows, per).transpose(0, 2, 1, 3)
            out[i:i + len(xy)] = cols.reshape(len(xy), cyl.rows, C)
        return np.roll(out, -h, axis=2)  # column c looks along yaw -c step

    def robot_poses(self, cam_xy: np.ndarray, cam_yaw: np.ndarray) -> np.ndarray:
        """(N, 3) robot poses whose camera centre is at `cam_xy` (N, 2) looking along
        `cam_yaw` (N,)."""
        th = cam_yaw - self.yaw
        c, s = np.cos(th), np.sin(th)
        ox, oy = self.offset
        return np.c_[cam_xy[:, 0] - (c * ox - s * oy), cam_xy[:, 1] - (s * ox + c * oy), np.angle(np.exp(1j * th))]

    def _jitter(self, xy: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Positions (N, 2) uniform in the spacing's square around each of `xy` (N, 2),
        redrawn where they leave the free space (a square at a wall or an obstacle), and
        left at `xy` where the second draw leaves it too."""
        out = xy + rng.uniform(-0.5, 0.5, xy.shape) * self.spacing_m
        for last in (False, True):
            bad = ~shapely.contains_xy(self.free, out[:, 0], out[:, 1])
            out[bad] = xy[bad] if last else xy[bad] + rng.uniform(-0.5, 0.5, (int(bad.sum()), 2)) * self.spacing_m
        return out

    def photo_window(self, image: np.ndarray) -> np.ndarray:
        """The photo (H, W, 3) uint8 resampled to the cylinder over its field of view:
        (rows, w) luminance, columns left to right."""
        lum = luminance(image, self.size)
        half = int(np.floor(self.cyl.half_fov / self.cyl.step))
        az = np.arange(-half, half + 1) * self.cyl.step
        mx, my = self.cyl.maps(az)
        return cv2.remap(lum.astype(np.float32), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)

    def scores(self, image: np.ndarray) -> np.ndarray:
        """(P, n_cols) horizon-free NCC of the photo with the panorama window centred on
        each column (position p, camera yaw -c step)."""
        o = self.photo_window(image)
        o = o - o.mean(axis=1, keepdims=True)
        o_norm = float(np.sqrt((o * o).sum())) + 1e-9
        P, w, C = self.panoramas, o.shape[1], self.cyl.n_cols
        pad = np.zeros((o.shape[0], C), np.float32)
        pad[:, :w] = o
        num = np.zeros((len(P), C))
        s1 = np.zeros((len(P), C))
        fo = np.conj(np.fft.rfft(pad, axis=-1))
        for i in range(0, len(P), 1024):
            p = P[i:i + 1024].astype(np.float64)
            # window starting at column s: sum_j p[s + j] o[j] (circular)
            num[i:i + 1024] = np.fft.irfft(np.fft.rfft(p, axis=-1) * fo[None], n=C, axis=-1).sum(axis=1)
            ext = np.concatenate([p, p[..., :w]], axis=-1)
            c1 = np.concatenate([np.zeros(p.shape[:2] + (1,)), np.cumsum(ext, axis=-1)], axis=-1)
            c2 = np.concatenate([np.zeros(p.shape[:2] + (1,)), np.cumsum(ext * ext, axis=-1)], axis=-1)
            win1 = c1[..., w:w + C] - c1[..., :C]
            win2 = c2[..., w:w + C] - c2[..., :C]
            s1[i:i + 1024] = win2.sum(axis=1) - (win1 * win1).sum(axis=1) / w
        # a window with less contrast than one grey level (8 bits) per pixel is featureless:
        # its NCC is undefined, scored 0 (without the floor, rounding makes it huge)
        floor = o.size / 255.0**2
        v = np.where(s1 > floor, num / (np.sqrt(np.maximum(s1, floor)) * o_norm), 0.0).astype(np.float32)
        # the window starting at s is centred on column s + (w - 1) / 2
        return np.roll(v, (w - 1) // 2, axis=1)

    def photo_scores(self, image: np.ndarray) -> np.ndarray:
        """`scores` of the photo, kept for the last `track_photos` photos (by identity), so
        that a track and several draws for one photo cost one search per photo."""
        for im, v in self._scored:
            if im is image:
                return v
        v = self.scores(image)
        self._scored = (self._scored + [(image, v)])[-self.track_photos:]
        return v

    def square_of(self, xy: np.ndarray) -> np.ndarray:
        """Position index (...) of the grid square holding each point `xy` (..., 2), -1 where
        that square has no panorama or lies off the grid."""
        ij = np.floor((xy - self._origin) / self.spacing_m).astype(np.int64)
        nx, ny = self._square.shape
        ok = (ij[..., 0] >= 0) & (ij[..., 0] < nx) & (ij[..., 1] >= 0) & (ij[..., 1] < ny)
        return np.where(ok, self._square[np.clip(ij[..., 0], 0, nx - 1), np.clip(ij[..., 1], 0, ny - 1)], -1)

    def camera_xy(self, poses: np.ndarray) -> np.ndarray:
        """(N, 2) camera centres of robot poses (N, 3)."""
        c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
        ox, oy = self.offset
        return np.c_[poses[:, 0] + c * ox - s * oy, poses[:, 1] + s * ox + c * oy]

    def cells(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The (position index, column) cells (N,), (N,) of robot poses (N, 3): the grid
        square of the camera centre (-1: none) and the column nearest the camera's yaw."""
        col = np.round(-(poses[:, 2] + self.yaw) / self.cyl.step).astype(np.int64) % self.cyl.n_cols
        return self.square_of(self.camera_xy(poses)), col

    def track_scores(self, track: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
        """(P, n_cols) the mean NCC of a track's photos along the odometry: a cell now (its
        centre's robot pose) is moved back by the odometry to each photo's step
        (`se2_backward`) and scores that photo's cell there; -1 (the least NCC) where it
        leaves the grid. track: (odometry (3,), image) per step, oldest first, the last
        one now. A place that one photo cannot single out (a repeated facade, a wall seen
        from afar) differs from the truth's in the photos before it: sequence matching, the
        measurement of the last few steps instead of one (in courtyard 2 the truth's cell
        ranked up to 4,400th on one photo along a row of alike facades).
        The motion back is a rigid motion in the robot's frame, so a cell's camera moves by
        an offset that depends on its column only: one offset and one column shift per
        column, then a lookup of the squares (no per-cell trigonometry)."""
        odom_now, C = track[-1][0], self.cyl.n_cols
        cols = np.arange(C)
        here = self.robot_poses(np.zeros((C, 2)), -cols * self.cyl.step)  # cameras at the origin, column c
        total = np.zeros((len(self.positions), C))
        for odom, image in track:
            v = self.photo_scores(image)
            back = se2_backward(here, odom, odom_now)
            p = self.square_of(self.positions[:, None, :] + self.camera_xy(back)[None])  # (P, C)
            c = self.cells(back)[1]  # (C,)
            total += np.where(p >= 0, v[np.maximum(p, 0), c[None, :]], -1.0)
        return total / len(track)

    def best_poses(self, image: np.ndarray, n: int, rng: np.random.Generator,
                   n_cells: int | None = None,
                   track: list[tuple[np.ndarray, np.ndarray]] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """n robot poses (n, 3) in the best-scoring (position, heading) cells for the photo
        (with `track`, whose last photo is `image`: for the track, `track_scores`) and their
        cells' scores (n,): the `n` best cells, one pose each, or with `n_cells`, n
        draws among the `n_cells` best. Each pose is uniform within its cell (the free part
        of a square of the spacing, one column of heading)."""
        steps = len(track) if track else 1
        ranked = [v for im, k, v in self._ranked if im is image and k == steps]
        if ranked:
            v = ranked[0]
        else:
            v = (self.track_scores(track) if steps > 1 else self.photo_scores(image)).ravel()
            self._ranked = (self._ranked + [(image, steps, v)])[-2:]
        k = min(n if n_cells is None else n_cells, v.size)
        top = np.argpartition(-v, k - 1)[:k]
        if n_cells is not None:
            top = top[rng.integers(len(top), size=n)]
        n = len(top)
        p, c = np.unravel_index(top, (len(self.positions), self.cyl.n_cols))
        xy = self._jitter(self.positions[p], rng)
        yaw = -(c + rng.uniform(-0.5, 0.5, n)) * self.cyl.step
        return self.robot_poses(xy, yaw), v[top]
