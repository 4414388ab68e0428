"""Photometric Gauss-Newton alignment of a photo to the rendered model: the fine stage of
rendered-view localisation, after the particle filter has found the basin.

Direct image alignment as in LSD-SLAM / DSO (Engel et al. 2014, 2018), with the rendered
model as the keyframe: the model is rendered at the current pose, its depth lifts every
trusted pixel u to a point X in the camera frame, and the residual of a pose increment
xi = (v, w) (metres, radians, camera frame) is

    e_u(xi) = I(pi(R(w) X + v)) - (g M(u) + b),

I the photo's luminance, M the render's, (g, b) the exposure fitted by weighted least squares
(`render_likelihood.exposure_fit`). Its Jacobian at xi = 0 is grad I(u) . d pi / dX . [I, -[X]x],
and each Levenberg-Marquardt step solves (J^T W J + lambda diag) xi = -J^T W e with W the
pixel's trust weight (`render_likelihood.pixel_weights`) times a Huber weight. A step is kept
only if the robust cost the filter uses (`render_likelihood.robust_cost`) does not rise, so
the alignment never trades the likelihood for the least-squares fit. Widths go coarse to
fine; each width's first step may re-focus the model's texture on the current estimate.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from ibr.camera import Camera
from ibr.mesh_renderer import Light, MeshRenderer
from localization.render_likelihood import (LUMA, LikelihoodConfig, comparison_camera, luminance, pixel_weights,
                                            robust_terms, truncation)


@dataclass(frozen=True)
class AlignConfig:
    """Settings of `refine_pose`."""

    iterations: int = 12
    """Levenberg-Marquardt steps per width."""
    huber: float = 0.5
    """Huber threshold in units of the residual truncation tau (the photo's contrast)."""
    damping: float = 1e-3
    """Initial Levenberg-Marquardt damping, relative to the Hessian's diagonal."""
    min_pixels: int = 30
    """Fewer trusted pixels than this: no step (the pose is left as it is)."""
    blur_px: float = 1.0
    """Gaussian blur (pixels at the width) of the photo before its gradient is taken."""


@dataclass
class Alignment:
    """A pose judged against the model at one width. cam_from_world (4, 4); cost: the robust
    cost (0 perfect, 1 nothing explained); explained: share of the null model's truncated
    cost the model removes over its trusted pixels (1 perfect, 0 no better than flat);
    trusted: sum of pixel weights / pixels; hessian (6, 6) J^T W J at the pose (v, w)."""

    cam_from_world: np.ndarray
    cost: float
    explained: float
    trusted: float
    hessian: np.ndarray | None = None


def observed_at(image: np.ndarray, camera: Camera) -> np.ndarray:
    """(h, w) luminance of the photo at the camera's size."""
    return luminance(image, (camera.width, camera.height))


def render_terms(model: MeshRenderer, camera: Camera, light: Light | None, lik: LikelihoodConfig):
    """Luminance (h, w), depth (h, w) camera-z metres and robust weights (h, w) of the model."""
    g = model.render(camera, light)
    lum = g.color.astype(np.float32) / 255.0 @ LUMA
    return lum, g.depth, pixel_weights(g.depth, g.trust, lik.edge_jump, lik.edge_band)


def evaluate_pose(model: MeshRenderer, observed: np.ndarray, camera: Camera, tau: float,
                  lik: LikelihoodConfig = LikelihoodConfig(), light: Light | None = None) -> Alignment:
    """The robust cost, explained share and trusted share of `camera` (pose and size) against
    `observed` luminance at that size."""
    r, _, w = render_terms(model, camera, light, lik)
    return judge_terms(camera.cam_from_world, r, observed, w, tau, lik)


def judge_terms(T: np.ndarray, r: np.ndarray, o: np.ndarray, w: np.ndarray, tau: float,
                lik: LikelihoodConfig, hessian: np.ndarray | None = None) -> Alignment:
    """`Alignment` of a rendered view r against o with weights w (all (h, w))."""
    if w.sum() <= 2.0:
        return Alignment(T, 1.0, 0.0, float(w.sum()) / w.size, hessian)
    rn, rm, _ = robust_terms(r.ravel(), o.ravel(), w.ravel(), tau, lik.gain)
    gain = float(w.ravel() @ (rn - rm))
    null = float(w.ravel() @ rn)
    return Alignment(T, 1.0 - gain / w.size, gain / null if null > 0 else 0.0, float(w.sum()) / w.size, hessian)


def se3_step(xi: np.ndarray) -> np.ndarray:
    """(4, 4) [R(w) | v] of an increment xi = (v, w), applied on the camera side."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(xi[3:]).as_matrix()
    T[:3, 3] = xi[:3]
    return T


def photometric_jacobian(camera: Camera, grad: tuple[np.ndarray, np.ndarray], u: np.ndarray,
                         v: np.ndarray, z: np.ndarray) -> np.ndarray:
    """(P, 6) d I(pi(R(w) X + v)) / d (v, w) at xi = 0 for pixels (u, v) of depth z (camera-z,
    metres): the photo's gradient grad = (dI/du, dI/dv) (h, w) times the projection's
    Jacobian times [I, -[X]x]."""
    K = camera.K
    x = (u - K[0, 2]) / K[0, 0] * z
    y = (v - K[1, 2]) / K[1, 1] * z
    du = K[0, 0] * grad[0][v, u] / z  # dI / d(x, y, z) through the projection
    dv = K[1, 1] * grad[1][v, u] / z
    dz = -(du * x + dv * y) / z
    return np.c_[du, dv, dz, dz * y - dv * z, du * z - dz * x, dv * x - du * y]


def normal_equations(camera: Camera, observed: np.ndarray, grad: tuple[np.ndarray, np.ndarray],
                     r: np.ndarray, depth: np.ndarray, w: np.ndarray, tau: float,
                     lik: LikelihoodConfig, huber: float) -> tuple[np.ndarray, np.ndarray]:
    """(H (6, 6), b (6,)) of the weighted Gauss-Newton system at the current pose."""
    v, u = np.nonzero(w > 0)
    g, off, _ = robust_terms(r[v, u], observed[v, u], w[v, u], tau, lik.gain)[2]
    e = observed[v, u] - g * r[v, u] - off
    J = photometric_jacobian(camera, grad, u, v, depth[v, u].astype(float))
    k = huber * tau
    weight = w[v, u] * np.where(np.abs(e) <= k, 1.0, k / np.maximum(np.abs(e), 1e-12))
    return (J * weight[:, None]).T @ J, (J * weight[:, None]).T @ e


def align_at_width(model: MeshRenderer, image: np.ndarray, camera: Camera, T: np.ndarray,
                   config: AlignConfig, lik: LikelihoodConfig, light: Light | None) -> Alignment:
    """Levenberg-Marquardt on the pose at one width (`camera` sized, pose ignored)."""
    o = observed_at(image, camera)
    tau = truncation(o, lik)
    blurred = cv2.GaussianBlur(o, (0, 0), config.blur_px)
    grad = (cv2.Sobel(blurred, cv2.CV_32F, 1, 0, ksize=3) / 8.0, cv2.Sobel(blurred, cv2.CV_32F, 0, 1, ksize=3) / 8.0)
    r, depth, w = render_terms(model, camera.with_pose(T), light, lik)
    best = judge_terms(T, r, o, w, tau, lik)
    lam = config.damping
    for _ in range(config.iterations):
        if (w > 0).sum() < config.min_pixels:
            break
        H, b = normal_equations(camera, o, grad, r, depth, w, tau, lik, config.huber)
        best.hessian = H
        try:
            xi = -np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-9), b)
        except np.linalg.LinAlgError:
            break
        T_new = se3_step(xi) @ T
        r_new, d_new, w_new = render_terms(model, camera.with_pose(T_new), light, lik)
        trial = judge_terms(T_new, r_new, o, w_new, tau, lik)
        if trial.cost <= best.cost:
            T, r, depth, w, best, lam = T_new, r_new, d_new, w_new, trial, lam / 3
            if np.abs(xi[3:]).max() * camera.K[0, 0] < 0.05:  # converged: < 0.05 px of rotation
                break
        else:
            lam *= 4
            if lam > 1e4:
                break
    return best


def refine_pose(model: MeshRenderer, image: np.ndarray, camera: Camera, cam_from_world: np.ndarray,
                widths: tuple[int, ...], config: AlignConfig = AlignConfig(),
                lik: LikelihoodConfig = LikelihoodConfig(), focus: Callable[[np.ndarray], None] | None = None,
                light: Light | None = None) -> Alignment:
    """Align photo `image` ((H, W, 3) uint8, intrinsics of `camera`) to the model from
    `cam_from_world`, coarse to fine over `widths` (pixels). focus(eye) re-chooses the
    model's textures for views near eye (world metres) before each width."""
    T = np.asarray(cam_from_world, float)
    result = None
    for width in widths:
        if focus is not None:
            focus(np.linalg.inv(T)[:3, 3])
        result = align_at_width(model, image, comparison_camera(camera, width), T, config, lik, light)
        T = result.cam_from_world
    return result
