"""The map's metric scale from the floor seen in pairs of photos (the floor plane's homography).

The map's cameras stand at the camera's known height above a flat floor (floor frame: world
metres, z up, floor z = 0), so a floor pixel of photo i lies at a known floor point whatever the
map's scale; the horizontal baselines between the photos carry the scale. For one pair (i, j)
the map's baseline from i to j is multiplied by a factor k (camera j moved to
C_i + k (C_j - C_i), heights and rotations kept), the floor pixels of photo i are projected
into photo j and compared; the k whose warp matches best (a robust photometric cost, searched
over log k, then refined jointly with a small turn of photo j about the vertical and a
small turn of the baseline's direction: SfM's headings are off by tenths of a degree and its
photos a few cm sideways, which the floor's parallax alone would take for scale) is the
pair's estimate of true / map scale. The pairs' estimates are combined by
their median (`floor_scale`: one factor for a whole map), none when they disagree; or per
two stops (`stop_spans`: the distance between the robot's positions at two of its circles
of photos, by which the first map is placed with `MapConfig.floor_spans`), since pairs of
the same two stops share their errors and a map can be off unevenly. Pairs need a
baseline and a common floor (`candidate_pairs`), so a map of one stop gets none.
Everything is relative to the camera height h (floor range, baselines) and the image
(intensities in [0, 1]).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from ibr.camera import Camera


@dataclass(frozen=True)
class FloorScaleConfig:
    """Settings of `floor_scale` (lengths in camera heights h, intensities in [0, 1])."""

    max_range_h: float = 5.0
    """Floor pixels are those whose rays hit the floor within this many heights (horizontal)."""
    min_baseline_h: float = 0.5
    """Pairs: photos at least this many heights apart (horizontally, in the map)."""
    max_baseline_h: float = 6.0
    """... and at most this many."""
    min_overlap: float = 0.3
    """Pairs: this share of photo i's floor pixels or more lands inside photo j."""
    min_pixels: int = 400
    """Pairs need this many floor pixels in common."""
    stride_px: int = 2
    """Floor pixels sampled every `stride_px` pixels."""
    blur_px: float = 1.0
    """Gaussian blur of the photos (sigma, px) before comparing: a wider basin."""
    robust: float = 0.08
    """Geman-McClure scale of the intensity difference."""
    log_k_range: float = 0.25
    """log k searched over [-log_k_range, +log_k_range] (k in 0.78 .. 1.28)."""
    log_k_step: float = 0.005
    """Grid step of the search (then a parabola through the best three)."""
    min_sharpness: float = 0.1
    """A pair counts if its cost 10 % away from its optimum is at least this share higher
    than at the optimum (a flat cost: no floor texture or no parallax)."""
    max_pairs: int = 300
    """At most this many pairs (those whose common floor moves most with k)."""
    refine_yaw: bool = True
    """Refine log k jointly with a small turn of photo j about the vertical and a small turn
    of the baseline's direction about photo i (Gauss-Newton, robust): the map's cameras are
    level, but their headings are 0.2-0.8 degrees off one another (apartments), a 1-4 px
    shift that the 1-D search took for up to 1.2 % of scale; and photo j stands a few cm
    beside the map's baseline, whose parallax a fit of k and the turn alone took for scale
    too (apartments 1-3, every pair against its true baseline ratio: medians 0.7-1.3 % low,
    quartiles up to 3.7 % apart; with the baseline's direction free, medians within 0.25 %,
    quartiles within 0.8 %). The floor's homography fixes the whole horizontal offset (the
    height is known), so the third parameter costs no ambiguity."""
    gn_iterations: int = 12
    """Gauss-Newton iterations of the refinement."""
    min_pairs: int = 10
    """Fewer pairs that count: no estimate (NaN)."""
    min_span_pairs: int = 3
    """`stop_spans`: a span between two stops needs this many pairs of their photos."""
    min_span_sigma: float = 0.003
    """`stop_spans`: the least relative noise of a span: the pairs' medians lay within 0.03-0.27 %
    of their baselines' true ratio (apartments 0, 1, 8, every span between two stops), and
    pairs of photos of the same two stops share their errors (the stops' floor and layout), so
    their median's standard error alone would claim more than they know."""
    max_standard_error: float = 0.01
    """No estimate (NaN) either when the median's standard error (`median_standard_error`
    of the pairs' log k) is above this: the pairs disagree, the map's layout is wrong, not
    only its scale (apartment seed 4, two stops 0.3 m apart: 56 pairs, quartiles
    0.77-1.04, the median took the map from -8 % to -15 %; maps that came out right had
    quartiles within 2.4 %, errors of 0.1-0.3 %). The issue's bar on the map's scale."""


def gray(image: np.ndarray, blur_px: float) -> np.ndarray:
    """(H, W) float32 intensity in [0, 1] of an RGB uint8 (or gray) photo, blurred."""
    g = image.astype(np.float32) / 255.0
    if g.ndim == 3:
        g = g.mean(2)
    return cv2.GaussianBlur(g, (0, 0), blur_px) if blur_px > 0 else g


def sample(image: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Bilinear values of a float32 (H, W) `image` at pixels `xy` (..., 2) (x right, y down,
    pixel centres at integers); cv2.remap, its maps folded to under 32767 rows."""
    flat = xy.reshape(-1, 2).astype(np.float32)
    n, width = len(flat), 1024
    pad = np.zeros((-n % width, 2), np.float32)
    m = np.concatenate([flat, pad]).reshape(-1, width, 2)
    return cv2.remap(image, m[..., 0], m[..., 1], cv2.INTER_LINEAR).ravel()[:n].reshape(xy.shape[:-1])


def floor_pixels(cam: Camera, max_range_m: float, stride_px: int) -> tuple[np.ndarray, np.ndarray]:
    """(uv (N, 2) px, X (N, 3) world m): pixels of `cam` (every `stride_px`) whose rays hit
    the floor z = 0 within `max_range_m` horizontally of the camera, and the floor points hit."""
    u, v = np.meshgrid(np.arange(0, cam.width, stride_px), np.arange(0, cam.height, stride_px))
    uv = np.stack([u.ravel(), v.ravel()], 1).astype(float)
    rays = (np.c_[uv, np.ones(len(uv))] @ np.linalg.inv(cam.K).T) @ cam.cam_from_world[:3, :3]  # world dirs
    c = cam.center
    down = rays[:, 2] < -1e-9
    lam = np.where(down, -c[2] / np.where(down, rays[:, 2], -1.0), np.inf)
    X = c + lam[:, None] * rays
    keep = down & (np.hypot(*(X[:, :2] - c[:2]).T) <= max_range_m)
    return uv[keep], X[keep]


def project_moved(cam_i: Camera, cam_j: Camera, X: np.ndarray, log_k: np.ndarray,
                  yaw_rad: float = 0.0, turn_rad: float = 0.0) -> np.ndarray:
    """(len(log_k), N, 2) pixels in photo j of world points X (N, 3) with j's horizontal
    offset from i turned by `turn_rad` about the vertical and scaled by exp(log_k), and j
    turned by `yaw_rad` about the vertical (its height kept); NaN behind j."""
    ci, cj = cam_i.center, cam_j.center
    R, K = cam_j.cam_from_world[:3, :3] @ Rotation.from_euler("z", -yaw_rad).as_matrix(), cam_j.K
    d = Rotation.from_euler("z", turn_rad).apply(np.r_[(cj - ci)[:2], 0.0])
    base = np.r_[ci[:2], cj[2]]
    out = np.empty((len(log_k), len(X), 2))
    for n, lk in enumerate(log_k):
        p = (X - (base + np.exp(lk) * d)) @ R.T @ K.T
        z = np.where(p[:, 2] > 1e-6, p[:, 2], np.nan)
        out[n] = p[:, :2] / z[:, None]
    return out


def in_image(p: np.ndarray, width: int, height: int) -> np.ndarray:
    """(N,) bool: the pixels p (K, N, 2) of every one of K warps lie inside a photo of
    `width` x `height` (bilinear sampling reaches the last row and column)."""
    return np.all((p[..., 0] >= 0) & (p[..., 0] <= width - 1) & (p[..., 1] >= 0) & (p[..., 1] <= height - 1),
                  axis=0)


def pair_cost(gi: np.ndarray, gj: np.ndarray, uv_i: np.ndarray, uv_j: np.ndarray,
              robust: float) -> tuple[np.ndarray, int]:
    """((K,) mean Geman-McClure cost of intensity differences between photo i at `uv_i` (N, 2)
    and photo j at `uv_j` (K, N, 2) (bilinear); only pixels inside j for every K count; and their number)."""
    inside = in_image(uv_j, gj.shape[1], gj.shape[0])
    if not inside.any():
        return np.full(len(uv_j), np.nan), 0
    a = gi[uv_i[inside, 1].astype(int), uv_i[inside, 0].astype(int)]
    b = sample(gj, uv_j[:, inside])
    r2 = ((b - a[None]) / robust) ** 2
    return (r2 / (1.0 + r2)).mean(1), int(inside.sum())


@dataclass
class PairEstimate:
    """One pair's fit: photos i, j; log_k its optimum; sharpness its cost's rise 10 % away
    (relative, from the 1-D search); pixels compared; cost at the 1-D optimum."""

    i: int
    j: int
    log_k: float
    sharpness: float
    pixels: int
    cost: float
    yaw_rad: float = 0.0
    """The refined turn of photo j (rad)."""
    log_k_se: float = np.inf
    """The refined log k's standard error (from the robust Gauss-Newton)."""


def _search(gi, gj, cam_i, cam_j, uv, X, grid, robust):
    """(cost (K,), pixels) of the warp i -> j at the log k of `grid`."""
    return pair_cost(gi, gj, uv, project_moved(cam_i, cam_j, X, grid), robust)


def refine(gi, gj, cam_i: Camera, cam_j: Camera, uv: np.ndarray, X: np.ndarray, log_k: float,
           config: FloorScaleConfig) -> tuple[float, float, float]:
    """(log k, yaw rad, standard error of log k): robust Gauss-Newton (Geman-McClure weights)
    of the warp i -> j over log k, a turn of j about the vertical and a turn of the baseline's
    direction (`project_moved`), from (`log_k`, 0, 0)."""
    h, w = gj.shape
    gx, gy = cv2.Sobel(gj, cv2.CV_32F, 1, 0, ksize=3) / 8, cv2.Sobel(gj, cv2.CV_32F, 0, 1, ksize=3) / 8
    a = gi[uv[:, 1].astype(int), uv[:, 0].astype(int)]
    th, eps, se = np.array([log_k, 0.0, 0.0]), 1e-4, np.inf
    at = lambda lk, yaw, turn: project_moved(cam_i, cam_j, X, np.array([lk]), yaw, turn)  # noqa: E731
    for _ in range(config.gn_iterations):
        p = np.concatenate([at(*th), at(th[0] + eps, *th[1:]), at(th[0], th[1] + eps, th[2]),
                            at(*th[:2], th[2] + eps)])
        ok = in_image(p, w, h)
        if ok.sum() < config.min_pixels:
            return th[0], th[1], np.inf
        b, bx, by = (sample(g, p[0, ok]) for g in (gj, gx, gy))
        r = b - a[ok]
        dp = (p[1:, ok] - p[0, ok]) / eps                       # (3 params, N, 2)
        J = (dp[..., 0] * bx + dp[..., 1] * by).T              # (N, 3)
        wgt = 1.0 / (1.0 + (r / config.robust) ** 2) ** 2
        A, g = (J * wgt[:, None]).T @ J, (J * wgt[:, None]).T @ r
        step = -np.linalg.solve(A + 1e-9 * np.eye(len(th)), g)
        th = th + np.clip(step, -0.05, 0.05)
        se = _first_standard_error(A, (wgt * r ** 2).sum() / max(wgt.sum() - len(th), 1))
        if np.abs(step).max() < 1e-5:
            break
    return float(th[0]), float(th[1]), se


def _first_standard_error(A: np.ndarray, residual_var: float) -> float:
    """Standard error of the first parameter of a Gauss-Newton fit with normal matrix `A`
    and residual variance `residual_var`: infinite where `A` is singular, a parameter the
    data do not constrain (a bare floor has no gradient to warp)."""
    try:
        var = np.linalg.inv(A)[0, 0] * residual_var
    except np.linalg.LinAlgError:
        return np.inf
    return float(np.sqrt(var)) if np.isfinite(var) and var > 0 else np.inf


def fit_pair(gi, gj, cam_i: Camera, cam_j: Camera, config: FloorScaleConfig) -> PairEstimate | None:
    """The factor k of the map's baseline from i to j that best warps i's floor onto j:
    a coarse grid over log k (4 steps), a fine one (1 step) about its best, a parabola."""
    h = cam_i.center[2]
    uv, X = floor_pixels(cam_i, config.max_range_h * h, config.stride_px)
    if len(uv) < config.min_pixels:
        return None
    r, st = config.log_k_range, config.log_k_step
    coarse = np.arange(-r, r + 1e-9, 4 * st)
    cost, n = _search(gi, gj, cam_i, cam_j, uv, X, coarse, config.robust)
    if n < config.min_pixels:
        return None
    b = int(np.nanargmin(cost))
    if b == 0 or b == len(coarse) - 1:
        return None
    fine = coarse[b] + np.arange(-4, 5) * st
    fcost, _ = _search(gi, gj, cam_i, cam_j, uv, X, fine, config.robust)
    f = int(np.nanargmin(fcost))
    if f == 0 or f == len(fine) - 1:
        return None
    c0, c1, c2 = fcost[f - 1:f + 2]
    den = c0 - 2 * c1 + c2
    lk = fine[f] + (0.5 * (c0 - c2) / den if den > 0 else 0.0) * st
    away = np.interp([lk - 0.1, lk + 0.1], coarse, cost)
    sharp = float(min(away) / max(fcost[f], 1e-9) - 1.0)
    est = PairEstimate(-1, -1, float(lk), sharp, n, float(fcost[f]))
    if config.refine_yaw:
        est.log_k, est.yaw_rad, est.log_k_se = refine(gi, gj, cam_i, cam_j, uv, X, lk, config)
    return est


def candidate_pairs(cameras: dict[int, Camera], config: FloorScaleConfig) -> list[tuple[int, int, float]]:
    """(i, j, information) of the pairs whose floors overlap, most first; information: the root sum
    of squares of the common floor pixels' motion per unit log k (px)."""
    ids = sorted(cameras)
    out = []
    floors = {i: floor_pixels(cameras[i], config.max_range_h * cameras[i].center[2], 8) for i in ids}
    for i in ids:
        ci, (uv, X) = cameras[i], floors[i]
        if len(X) == 0:
            continue
        for j in ids:
            cj = cameras[j]
            base = np.hypot(*(cj.center - ci.center)[:2]) / ci.center[2]
            if j == i or not config.min_baseline_h <= base <= config.max_baseline_h:
                continue
            p = project_moved(ci, cj, X, np.array([0.0, 0.01]))
            inside = in_image(p, cj.width, cj.height)
            if inside.mean() < config.min_overlap:
                continue
            par = np.linalg.norm(p[1, inside] - p[0, inside], axis=1) / 0.01
            out.append((i, j, float(np.sqrt((par ** 2).sum()))))
    return sorted(out, key=lambda q: -q[2])


def floor_scale(images: dict[int, np.ndarray], cameras: dict[int, Camera],
                config: FloorScaleConfig = FloorScaleConfig()) -> tuple[float, list[PairEstimate]]:
    """(k, pairs): the factor by which to multiply the map's horizontal lengths (true / map
    scale; NaN if no pair counts) from the floor seen by pairs of the photos `images`
    {index: RGB uint8} posed by `cameras` {index: Camera in the floor frame}; and the pairs'
    fits that counted. The map scaled by k about any point (heights kept) is metric."""
    pairs = candidate_pairs(cameras, config)[:config.max_pairs]
    g = {}
    fits = []
    for i, j, _ in pairs:
        for q in (i, j):
            if q not in g:
                g[q] = gray(images[q], config.blur_px)
        f = fit_pair(g[i], g[j], cameras[i], cameras[j], config)
        if f is not None and f.sharpness >= config.min_sharpness:
            f.i, f.j = i, j
            fits.append(f)
    log_k = np.array([f.log_k for f in fits])
    if len(fits) < config.min_pairs or median_standard_error(log_k) > config.max_standard_error:
        return float("nan"), fits
    return float(np.exp(np.median(log_k))), fits


def stop_spans(fits: list[PairEstimate], cameras: dict[int, Camera], stop: dict[int, int],
               robot_xy: dict[int, np.ndarray], config: FloorScaleConfig = FloorScaleConfig()
               ) -> dict[tuple[int, int], tuple[float, float]]:
    """{(a, b): (length m, relative sigma)}: the floor's measure of the horizontal distance
    between the robot's positions at stops a < b (its circles of photos), from the `fits` of
    pairs of photos i, j taken at two different stops (`stop` {photo: stop}): photo j's
    camera moved to C_i + k (C_j - C_i) (the pair's k), less the mount's offset of each
    camera from its robot position (`robot_xy` {photo: (2,) m} in the map of `cameras`). Per
    two stops, the median over their pairs; sigma the median's standard error
    (`median_standard_error` of the logs), at least `min_span_sigma`. Two stops with fewer
    than `min_span_pairs` pairs, or pairs that disagree (standard error above
    `max_standard_error`), measure nothing. Unlike one factor for the whole map (the
    median over every pair), each span says only what its two stops saw: apartment 14's 65
    pairs were all of one span, 0.6 m of a map 2.3 m across, whose other stops were 4-6 %
    too close."""
    lengths: dict[tuple[int, int], list[float]] = {}
    for f in fits:
        a, b = stop[f.i], stop[f.j]
        if a == b:
            continue
        ci, cj = cameras[f.i].center[:2], cameras[f.j].center[:2]
        mount_i, mount_j = ci - robot_xy[f.i], cj - robot_xy[f.j]
        length = np.linalg.norm(np.exp(f.log_k) * (cj - ci) - (mount_j - mount_i))
        lengths.setdefault((min(a, b), max(a, b)), []).append(float(np.log(length)))
    out = {}
    for span, logs in lengths.items():
        logs = np.array(logs)
        if len(logs) < config.min_span_pairs:
            continue
        se = median_standard_error(logs)
        if se <= config.max_standard_error:
            out[span] = (float(np.exp(np.median(logs))), max(se, config.min_span_sigma))
    return out


def median_standard_error(x: np.ndarray) -> float:
    """The standard error of the median of the samples `x` (n,): sqrt(pi / 2) sigma / sqrt(n),
    sigma robustly from the interquartile range (IQR / 1.349, a normal's)."""
    q1, q3 = np.percentile(x, [25, 75])
    return float(np.sqrt(np.pi / 2) * (q3 - q1) / 1.349 / np.sqrt(len(x)))


def rescaled(cameras: dict[int, Camera], points: np.ndarray, k: float,
             origin: np.ndarray) -> tuple[dict[int, Camera], np.ndarray]:
    """The map's `cameras` and `points` (N, 3) scaled by `k` about `origin` (3,) (a point at
    the cameras' height: they stay at it; rotations kept)."""
    out = {}
    for i, c in cameras.items():
        T = c.cam_from_world.copy()
        T[:3, 3] = -T[:3, :3] @ (origin + k * (c.center - origin))
        out[i] = c.with_pose(T)
    return out, origin + k * (np.asarray(points, float).reshape(-1, 3) - origin)
