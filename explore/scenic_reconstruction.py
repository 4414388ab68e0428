"""3-D reconstruction from a stereo pair for the Scenic Route Planner (Mendez et al., Sec. 3.1):
match the two images, triangulate the matches into points, and give every point a
covariance from the triangulation geometry.

The paper uses dense learned correspondences; here SIFT features (OpenCV) matched with
Lowe's ratio test and kept only if they satisfy the epipolar constraint of the known poses.
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
    max_sigma_m: float = 1.0
    """Points whose largest standard deviation exceeds this are dropped (metres)."""
    n_features: int = 2000
    """SIFT features detected per image at most."""


def detect(image: np.ndarray, config: StereoConfig) -> tuple[np.ndarray, np.ndarray]:
    """SIFT keypoints (K, 2) pixel positions and descriptors (K, 128) of an RGB image."""
    sift = cv2.SIFT_create(nfeatures=config.n_features, contrastThreshold=0.02)
    kps, desc = sift.detectAndCompute(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY), None)
    uv = np.array([k.pt for k in kps], dtype=np.float64).reshape(-1, 2)
    return uv, (desc if desc is not None else np.zeros((0, 128), np.float32))


def fundamental_from_cameras(left: Camera, right: Camera) -> np.ndarray:
    """F (3, 3) with x_Rᵀ F x_L = 0 for pixel coordinates of the two known cameras."""
    right_from_left = right.cam_from_world @ left.world_from_cam
    R, t = right_from_left[:3, :3], right_from_left[:3, 3]
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    return np.linalg.inv(right.K).T @ tx @ R @ np.linalg.inv(left.K)


def match(left_image: np.ndarray, right_image: np.ndarray, left: Camera, right: Camera,
          config: StereoConfig) -> tuple[np.ndarray, np.ndarray]:
    """Matched pixels (M, 2) in the left and right images: ratio test, mutual consistency
    and the epipolar constraint of the known poses."""
    uv_l, d_l = detect(left_image, config)
    uv_r, d_r = detect(right_image, config)
    if len(uv_l) < 2 or len(uv_r) < 2:
        return np.zeros((0, 2)), np.zeros((0, 2))
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(d_l, d_r, k=2)
    pairs = np.array([(m[0].queryIdx, m[0].trainIdx) for m in knn
                      if len(m) == 2 and m[0].distance < config.ratio * m[1].distance],
                     dtype=np.int64).reshape(-1, 2)
    a, b = uv_l[pairs[:, 0]], uv_r[pairs[:, 1]]
    F = fundamental_from_cameras(left, right)
    ha, hb = np.c_[a, np.ones(len(a))], np.c_[b, np.ones(len(b))]
    lines = ha @ F.T                                               # epipolar lines in right
    dist = np.abs(np.sum(lines * hb, axis=1)) / np.maximum(np.hypot(lines[:, 0], lines[:, 1]), 1e-12)
    keep = dist < config.max_epipolar_px
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
    X, uv_l, uv_r = X[keep], uv_l[keep], uv_r[keep]
    if len(X) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3, 3))
    cov = triangulation_covariance(left, right, uv_l, uv_r, config.pixel_sigma)
    ok = np.sqrt(np.linalg.eigvalsh(cov)[:, -1]) < config.max_sigma_m
    return X[ok], cov[ok] + 1e-10 * np.eye(3)
