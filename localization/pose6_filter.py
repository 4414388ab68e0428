"""6-DoF particle filter for the pose of a hand-held photo, weighted by rendered views.

Heigl et al. (light-field particle filter): each particle's weight compares the photo with
the view the model renders at the particle's pose. For a single, static photo the filter is
iterated on the same image (Loc-NeRF, Maggio et al. 2023): a random-walk motion model whose
noise is annealed from a coarse to a fine scale, tempered weights (the temperature falls
with the noise), systematic resampling (filterpy; not residual, filterpy issue #290), and a
random perturbation of a fraction of the particles at the coarse scale every step, so the
filter can still leave a wrong basin. Views are compared coarse-to-fine.

Particles are (N, 6): camera centre (world, metres) and the rotation vector (radians) of
`world_from_cam`'s rotation. The model is a `BatchedLikelihood` over a mesh (for Strecha:
the proxy of `ibr.proxy_geometry.build_proxy`, vertex-coloured, rendered unlit).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from filterpy.monte_carlo import systematic_resample
from scipy.spatial.transform import Rotation

from ibr.camera import Camera, rigid
from localization.particle_filter import _numpy_random_from
from localization.render_likelihood import BatchedLikelihood


@dataclass(frozen=True)
class Pose6FilterConfig:
    """Settings of `Pose6Filter`."""

    n_particles: int = 300
    """Particles (Loc-NeRF uses 300)."""
    steps: int = 30
    """Filter iterations on the one photo."""
    sigma_m: tuple[float, float] = (0.15, 0.005)
    """Random-walk position noise (metres, 1-sigma) at the first and the last step (geometric)."""
    sigma_deg: tuple[float, float] = (4.0, 0.15)
    """Random-walk rotation noise (degrees, 1-sigma) at the first and the last step."""
    perturb_fraction: float = 0.1
    """Fraction of particles perturbed with the first step's noise every step."""
    temperature: tuple[float, float] = (0.03, 0.005)
    """Likelihood temperature (NCC units) at the first and the last step (tempering)."""
    coverage_ref: float = 0.5
    """Covered fraction of the view above which the model earns no more credit: a proxy
    covers only part of a real photo, and rewarding coverage pulls the views onto it."""
    sizes: tuple[tuple[int, int], ...] = ((48, 32), (96, 64), (192, 128))
    """Comparison sizes (width, height), coarse to fine, each used for an equal share of the steps."""


def ncc_loglik(scores: np.ndarray, temperature: float, coverage_ref: float) -> np.ndarray:
    """(N,) log-likelihoods from tile scores (N, 4) (ncc, mse, coverage, _):
    -(1 - NCC * min(1, coverage / coverage_ref)) / temperature. Views covering less than
    `coverage_ref` of the frame are discounted (uncovered pixels count as uncorrelated)."""
    return -(1.0 - scores[:, 0] * np.minimum(1.0, scores[:, 2] / coverage_ref)) / temperature


def cam_from_world_of(particles: np.ndarray) -> np.ndarray:
    """(N, 4, 4) cam_from_world of particles (N, 6) = (centre, rotvec of world_from_cam)."""
    R_wc = Rotation.from_rotvec(particles[:, 3:]).as_matrix()
    R_cw = np.transpose(R_wc, (0, 2, 1))
    T = np.zeros((len(particles), 4, 4))
    T[:, :3, :3] = R_cw
    T[:, :3, 3] = -np.einsum("nij,nj->ni", R_cw, particles[:, :3])
    T[:, 3, 3] = 1.0
    return T


def particles_from_cam_from_world(T: np.ndarray) -> np.ndarray:
    """Inverse of `cam_from_world_of`: (N, 4, 4) -> (N, 6)."""
    T = np.asarray(T).reshape(-1, 4, 4)
    R_wc = np.transpose(T[:, :3, :3], (0, 2, 1))
    c = -np.einsum("nij,nj->ni", R_wc, T[:, :3, 3])
    return np.c_[c, Rotation.from_matrix(R_wc).as_rotvec()]


def perturb(particles: np.ndarray, sigma_m: float, sigma_rad: float, rng: np.random.Generator) -> np.ndarray:
    """Random walk: centre + N(0, sigma_m^2 I), rotation composed with exp(N(0, sigma_rad^2 I))
    in the camera frame."""
    n = len(particles)
    c = particles[:, :3] + rng.normal(scale=sigma_m, size=(n, 3))
    R = Rotation.from_rotvec(particles[:, 3:]) * Rotation.from_rotvec(rng.normal(scale=sigma_rad, size=(n, 3)))
    return np.c_[c, R.as_rotvec()]


def sample_around(cam_from_world: np.ndarray, n: int, spread_m: float, spread_rad: float,
                  rng: np.random.Generator) -> np.ndarray:
    """n particles uniform within +-spread_m per axis of the centre and a rotation of up to
    spread_rad (uniform direction and angle) about the pose."""
    p = particles_from_cam_from_world(cam_from_world)[0]
    c = p[:3] + rng.uniform(-spread_m, spread_m, (n, 3))
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    dR = Rotation.from_rotvec(axis * rng.uniform(0, spread_rad, (n, 1)))
    return np.c_[c, (Rotation.from_rotvec(p[3:]) * dR).as_rotvec()]


def weighted_pose(particles: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted mean pose (4, 4) cam_from_world: mean centre and the quaternion eigen-mean
    (Markley et al. 2007) of the rotations."""
    w = weights / weights.sum()
    q = Rotation.from_rotvec(particles[:, 3:]).as_quat()
    M = (q * w[:, None]).T @ q
    q_mean = np.linalg.eigh(M)[1][:, -1]
    p = np.r_[w @ particles[:, :3], Rotation.from_quat(q_mean).as_rotvec()]
    return cam_from_world_of(p[None])[0]


@dataclass
class Pose6Estimate:
    """cam_from_world (4, 4) weighted mean; best (4, 4) highest-weight particle; particles
    (N, 6) and weights (N,) of the last step; history: per step (mean pose (4, 4))."""

    cam_from_world: np.ndarray
    best: np.ndarray
    particles: np.ndarray
    weights: np.ndarray
    history: list[np.ndarray]


class Pose6Filter:
    """Localise one photo: `run(image, camera, particles)`; `proposal(step)` may return extra
    particles (M, 6) to mix in each step (the hybrid's PnP proposal), weighted like the rest."""

    def __init__(self, likelihood: BatchedLikelihood, config: Pose6FilterConfig, rng: np.random.Generator):
        self.likelihood, self.config, self.rng = likelihood, config, rng

    def schedule(self, k: int) -> tuple[float, float, float, tuple[int, int]]:
        """(sigma_m, sigma_rad, temperature, size) at step k: geometric annealing."""
        c = self.config
        a = k / max(c.steps - 1, 1)
        geo = lambda pair: pair[0] * (pair[1] / pair[0]) ** a  # noqa: E731
        size = c.sizes[min(int(a * len(c.sizes)), len(c.sizes) - 1)]
        return geo(c.sigma_m), np.radians(geo(c.sigma_deg)), geo(c.temperature), size

    def loglik(self, particles: np.ndarray, camera: Camera, size: tuple[int, int], temperature: float) -> np.ndarray:
        """(N,) tempered log-likelihoods of particles against the current observation."""
        m = self.likelihood.model
        template = camera.scaled(size[0] / camera.width)
        template = Camera(template.K, size[0], size[1])
        clip = template.gl_projection(m.near, m.far) @ cam_from_world_of(particles)
        scores = self.likelihood.view_scores(clip, particles[:, :3])
        return ncc_loglik(scores, temperature, self.config.coverage_ref)

    def run(self, image: np.ndarray, camera: Camera, particles: np.ndarray,
            proposal: Callable[[int], np.ndarray | None] | None = None,
            on_step: Callable[[int, np.ndarray, np.ndarray], None] | None = None,
            extra_loglik: Callable[[np.ndarray], np.ndarray] | None = None) -> Pose6Estimate:
        """Iterate the filter on `image` ((H, W, 3) uint8) taken by a camera with the
        intrinsics of `camera` (pose ignored), from initial particles (N, 6).
        proposal(step): particles (M, 6) replacing the last M each step (mixture proposal);
        extra_loglik(particles): (N,) log-likelihood of another sensor, added to the weights."""
        c, rng = self.config, self.rng
        history, size_set = [], None
        p0_m, p0_rad = c.sigma_m[0], np.radians(c.sigma_deg[0])
        for k in range(c.steps):
            sigma_m, sigma_rad, temperature, size = self.schedule(k)
            if size != size_set:
                self.likelihood.set_observation(image, size)
                size_set = size
            if k > 0:
                particles = perturb(particles, sigma_m, sigma_rad, rng)
                wide = rng.random(len(particles)) < c.perturb_fraction
                particles[wide] = perturb(particles[wide], p0_m, p0_rad, rng)
            extra = proposal(k) if proposal else None
            if extra is not None and len(extra):
                particles = np.r_[particles[: len(particles) - len(extra)], extra]
            ll = self.loglik(particles, camera, size, temperature)
            if extra_loglik is not None:
                ll = ll + extra_loglik(particles)
            w = np.exp(ll - ll.max())
            w /= w.sum()
            history.append(weighted_pose(particles, w))
            if on_step:
                on_step(k, particles, w)
            if k < c.steps - 1:
                with _numpy_random_from(rng):
                    particles = particles[systematic_resample(w)]
        best = cam_from_world_of(particles[np.argmax(w)][None])[0]
        return Pose6Estimate(history[-1], best, particles, w, history)


def camera_at(camera: Camera, cam_from_world: np.ndarray) -> Camera:
    """`camera`'s intrinsics at a pose (re-orthonormalised)."""
    R = Rotation.from_matrix(cam_from_world[:3, :3]).as_matrix()
    return camera.with_pose(rigid(R, cam_from_world[:3, 3]))
