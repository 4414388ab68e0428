"""3-D reconstruction from a stereo pair for the Scenic Route Planner (Mendez et al., Sec. 3.1):
match the two images, triangulate the matches into points, and give every point a
covariance from the triangulation geometry.

The paper uses dense, bidirectional learned correspondences. Here the default matcher is
dense and bidirectional too, without learning: OpenCV's DIS optical flow computed left->right
and right->left, sampled on a pixel grid and kept where the two flows agree (forward-backward
check) and the match satisfies the epipolar constraint of the known poses. The alternative
(`matcher="sift"`) is SIFT features matched with Lowe's ratio test and the same epipolar check.
Matches are triangulated with `cv2.triangulatePoints`; the covariance is first-order
propagation of isotropic pixel noise σ through the Jacobian of the triangulation,
Σ = σ² J Jᵀ with J = ∂X/∂(u_L, v_L, u_R, v_R) (3 x 4) taken by central differences (all
points at once). Badly conditioned pairs (short baselines, rays at grazing angles) get
large covariances, which the NBV cost then wants to reduce.

Units: pixels for image coordinates, metres for points, m^2 for covariances.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ibr.camera import Camera
from ibr.proxy.triangulation import fundamental_matrix


@dataclass(frozen=True)
class StereoConfig:
    pixel_sigma: float = 0.5
    """Standard deviation of a matched feature's position (pixels)."""
    ratio: float = 0.8
    """Lowe's ratio test threshold on SIFT descriptor distances."""
    max_epipolar_px: float = 1.5
    """Largest distance of a match from its epipolar line (pixels)."""
    max_reprojection_px: float = 2.0
    """Largest reprojection error of a triangulated point in either image (pixels)."""
    max_depth_m: float = 30.0
    """Points farther than this from either camera are dropped (metres)."""
    min_angle_deg: float = 2.0
    """Points whose two viewing rays meet at less than this angle are dropped (degrees):
    near the epipole of a forward motion the depth is a guess."""
    max_sigma_m: float = 0.3
    """Points whose largest standard deviation exceeds this are dropped (metres)."""
    n_features: int = 2000
    """SIFT features detected per image at most."""
    matcher: str = "dense"
    """'dense' (bidirectional DIS optical flow) or 'sift' (sparse features)."""
    dense_stride_px: int = 4
    """Grid step of the dense matches in the left image (pixels)."""
    max_fb_px: float = 1.0
    """Largest forward-backward disagreement of a dense match (pixels)."""
    min_gradient: float = 4.0
    """Dense matches need at least this mean image gradient around them (grey levels per
    pixel): flow in textureless areas is a guess."""


def detect(image: np.ndarray, config: StereoConfig) -> tuple[np.ndarray, np.ndarray]:
    """SIFT keypoints (K, 2) pixel positions and descriptors (K, 128) of an RGB image."""
    sift = cv2.SIFT_create(nfeatures=config.n_features, contrastThreshold=0.02)
    kps, desc = sift.detectAndCompute(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY), None)
    uv = np.array([k.pt for k in kps], dtype=np.float64).reshape(-1, 2)
    return uv, (desc if desc is not None else np.zeros((0, 128), np.float32))


def epipolar_distance(F: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(M,) distance (pixels) of right pixels b (M, 2) from the epipolar lines of left pixels a."""
    ha, hb = np.c_[a, np.ones(len(a))], np.c_[b, np.ones(len(b))]
    lines = ha @ F.T
    return np.abs(np.sum(lines * hb, axis=1)) / np.maximum(np.hypot(lines[:, 0], lines[:, 1]), 1e-12)


def _median_parallax(left_image, right_image, left: Camera, right: Camera, H: np.ndarray,
                     config: StereoConfig) -> np.ndarray:
    """(3, 3) translation by the median parallax of the SIFT matches after the rotation H
    (identity without matches): DIS flow then only has to find the residual parallax."""
    a, b = sift_match(left_image, right_image, left, right, config)
    T = np.eye(3)
    if len(a) >= 5:
        hb = np.c_[b, np.ones(len(b))] @ np.linalg.inv(H).T
        T[:2, 2] = np.median(hb[:, :2] / hb[:, 2:] - a, axis=0)
    return T


def dense_match(left_image: np.ndarray, right_image: np.ndarray, left: Camera, right: Camera,
                config: StereoConfig) -> tuple[np.ndarray, np.ndarray]:
    """Dense bidirectional matches (M, 2) left and right pixels. The right image is first
    rotated into the left camera's orientation (infinite homography H = K_R R K_L⁻¹ of the
    known poses) so that only the parallax remains; then DIS optical flow both ways on a grid
    of `dense_stride_px`, kept where forward and backward flow agree within `max_fb_px`, the
    texture is strong enough and the epipolar constraint holds."""
    gl = cv2.cvtColor(left_image, cv2.COLOR_RGB2GRAY)
    h, w = gl.shape
    R = (right.cam_from_world @ left.world_from_cam)[:3, :3]
    H = right.K @ R @ np.linalg.inv(left.K)                 # left pixel -> right pixel at infinity
    H = H @ _median_parallax(left_image, right_image, left, right, H, config)
    gr = cv2.warpPerspective(cv2.cvtColor(right_image, cv2.COLOR_RGB2GRAY), H, (w, h),
                             flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    fwd, bwd = dis.calc(gl, gr, None), dis.calc(gr, gl, None)
    s = config.dense_stride_px
    vv, uu = np.mgrid[s // 2:h:s, s // 2:w:s]
    a = np.c_[uu.ravel(), vv.ravel()].astype(np.float64)
    b = a + fwd[vv.ravel(), uu.ravel()]                    # in the rotated right image
    inside = (b[:, 0] >= 0) & (b[:, 0] <= w - 1) & (b[:, 1] >= 0) & (b[:, 1] <= h - 1)
    a, b = a[inside], b[inside]
    if len(b) == 0:
        return a, b
    back = cv2.remap(bwd, b[:, :1].astype(np.float32), b[:, 1:].astype(np.float32),
                     cv2.INTER_LINEAR).reshape(-1, 2)          # backward flow at the match
    keep = np.linalg.norm(b + back - a, axis=1) < config.max_fb_px
    grad = cv2.blur(np.hypot(cv2.Sobel(gl, cv2.CV_32F, 1, 0), cv2.Sobel(gl, cv2.CV_32F, 0, 1)), (5, 5))
    keep &= grad[a[:, 1].astype(int), a[:, 0].astype(int)] >= config.min_gradient
    hb = np.c_[b, np.ones(len(b))] @ H.T
    b = hb[:, :2] / hb[:, 2:]                               # back to right-image pixels
    keep &= (hb[:, 2] > 0) & (b[:, 0] >= 0) & (b[:, 0] <= w - 1) & (b[:, 1] >= 0) & (b[:, 1] <= h - 1)
    keep &= epipolar_distance(fundamental_matrix(left, right), a, b) < config.max_epipolar_px
    return a[keep], b[keep]


def match(left_image: np.ndarray, right_image: np.ndarray, left: Camera, right: Camera,
          config: StereoConfig) -> tuple[np.ndarray, np.ndarray]:
    """Matched pixels (M, 2) in the left and right images with the configured matcher:
    dense (see `dense_match`) or SIFT with ratio test and the epipolar constraint."""
    if config.matcher == "dense":
        return dense_match(left_image, right_image, left, right, config)
    if config.matcher != "sift":
        raise ValueError(f"matcher must be 'dense' or 'sift', got {config.matcher!r}")
    return sift_match(left_image, right_image, left, right, config)


def sift_match(left_image: np.ndarray, right_image: np.ndarray, left: Camera, right: Camera,
               config: StereoConfig) -> tuple[np.ndarray, np.ndarray]:
    """SIFT matches (M, 2) left and right pixels: ratio test and the epipolar constraint."""
    uv_l, d_l = detect(left_image, config)
    uv_r, d_r = detect(right_image, config)
    if len(uv_l) < 2 or len(uv_r) < 2:
        return np.zeros((0, 2)), np.zeros((0, 2))
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(d_l, d_r, k=2)
    pairs = np.array([(m[0].queryIdx, m[0].trainIdx) for m in knn
                      if len(m) == 2 and m[0].distance < config.ratio * m[1].distance],
                     dtype=np.int64).reshape(-1, 2)
    a, b = uv_l[pairs[:, 0]], uv_r[pairs[:, 1]]
    keep = epipolar_distance(fundamental_matrix(left, right), a, b) < config.max_epipolar_px
    return a[keep], b[keep]


def _projection(camera: Camera) -> np.ndarray:
    return camera.K @ camera.cam_from_world[:3, :]


def triangulate(left: Camera, right: Camera, uv_l: np.ndarray, uv_r: np.ndarray) -> np.ndarray:
    """World points (M, 3) from matched pixels (M, 2) with `cv2.triangulatePoints` (DLT)."""
    if len(uv_l) == 0:
        return np.zeros((0, 3))
    X = cv2.triangulatePoints(_projection(left), _projection(right),
                              uv_l.T.astype(np.float64), uv_r.T.astype(np.float64))
    return (X[:3] / X[3]).T


def triangulation_covariance(left: Camera, right: Camera, uv_l: np.ndarray, uv_r: np.ndarray,
                             pixel_sigma: float, h: float = 0.25) -> np.ndarray:
    """Σ (M, 3, 3) = σ² J Jᵀ: first-order propagation of pixel noise through the
    triangulation, J (M, 3, 4) by central differences of step h pixels."""
    J = np.zeros((len(uv_l), 3, 4))
    for k in range(4):  # four pixel coordinates, each a batched triangulation
        d = np.zeros(4)
        d[k] = h
        plus = triangulate(left, right, uv_l + d[:2], uv_r + d[2:])
        minus = triangulate(left, right, uv_l - d[:2], uv_r - d[2:])
        J[:, :, k] = (plus - minus) / (2 * h)
    return pixel_sigma ** 2 * J @ J.transpose(0, 2, 1)


def reconstruct_pair(left: Camera, right: Camera, left_image: np.ndarray, right_image: np.ndarray,
                     config: StereoConfig = StereoConfig()) -> tuple[np.ndarray, np.ndarray]:
    """Points (M, 3) metres and covariances (M, 3, 3) m^2 from one stereo pair with known
    poses; matches failing cheirality, reprojection, depth or uncertainty checks are dropped."""
    uv_l, uv_r = match(left_image, right_image, left, right, config)
    if len(uv_l) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3, 3))
    X = triangulate(left, right, uv_l, uv_r)
    keep = np.all(np.isfinite(X), axis=1)
    for cam, uv in ((left, uv_l), (right, uv_r)):
        proj, depth = cam.project(np.where(keep[:, None], X, 0.0))
        keep &= (depth > 0.05) & (depth < config.max_depth_m)
        keep &= np.linalg.norm(proj - uv, axis=1) < config.max_reprojection_px
    ray_l, ray_r = X - left.center, X - right.center
    cos = np.sum(ray_l * ray_r, 1) / np.maximum(np.linalg.norm(ray_l, axis=1) * np.linalg.norm(ray_r, axis=1), 1e-12)
    keep &= cos < np.cos(np.radians(config.min_angle_deg))
    X, uv_l, uv_r = X[keep], uv_l[keep], uv_r[keep]
    if len(X) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3, 3))
    cov = triangulation_covariance(left, right, uv_l, uv_r, config.pixel_sigma)
    ok = np.sqrt(np.linalg.eigvalsh(cov)[:, -1]) < config.max_sigma_m
    return X[ok], cov[ok] + 1e-10 * np.eye(3)
