"""6-DoF particle filter for the pose of a hand-held photo, weighted by rendered views.

Heigl et al. (light-field particle filter): each particle's weight compares the photo with
the view the model renders at the particle's pose. For a single, static photo the filter is
iterated on the same image (Loc-NeRF, Maggio et al. 2023), as an annealed particle filter
(Deutscher, Blake & Reid 2000): a wide first sample from the prior thinned to N particles;
each step a random walk whose covariance is a fraction of the particles' own (so it follows
the posterior's shape, e.g. the ridge along which a narrow camera trades sideways motion for
yaw, and shrinks with it); weights tempered so that a fixed share of the particles survives;
systematic resampling (filterpy; not residual, filterpy issue #290); and a random
perturbation of a fraction of the particles at a wide scale every step, so the filter can
still leave a wrong basin. Views are compared coarse-to-fine at a few small widths (24 and
48 pixels by default, the height following the photo's aspect), and the model may re-focus
on the current estimate at each finer width. The filter only finds the basin: the pose is
then refined by photometric Gauss-Newton (`localization.direct_alignment`) and judged
(`localization.confidence`), see `localization.render_localizer`.

Scales come from the scene and the photo, not from metres fixed in code: the weight is the
robust cost of `render_likelihood` (dimensionless); the smallest random walk is a fraction
of a pixel at the finest width, turned into metres with the scene's typical depth; the
wide perturbation is a fraction of the prior's own spread.

Particles are (N, 6): camera centre (world, metres) and the rotation vector (radians) of
`world_from_cam`'s rotation. The model is a `BatchedLikelihood` over a mesh (for photos:
the proxy of `ibr.proxy.proxy_geometry.build_proxy` textured from the photos,
`localization.photo_texture`, rendered unlit).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from filterpy.monte_carlo import systematic_resample
from scipy.spatial.transform import Rotation

from ibr.camera import Camera, rigid
from localization.particle_filter import numpy_random_from
from localization.render_likelihood import BatchedLikelihood, comparison_camera


@dataclass(frozen=True)
class Pose6FilterConfig:
    """Settings of `Pose6Filter`."""

    n_particles: int = 150
    """Particles after the first step."""
    n_initial: int = 1500
    """Particles drawn from the prior and weighted at the first step, then resampled down to
    `n_particles`: a 6-D prior is a large volume to cover."""
    steps: int = 8
    """Filter iterations on the one photo (it only has to find the basin: Gauss-Newton
    refines)."""
    ess_fraction: float = 0.5
    """Annealing: each step's temperature is the one at which the effective sample size of
    the weights is this fraction of the particles (Deutscher et al.'s survival rate)."""
    temperature: tuple[float, float] = (0.2, 0.002)
    """Bounds of the temperature (robust-cost units, dimensionless): hottest and coldest."""
    diffusion: float = 0.6
    """Random-walk noise = diffusion x the particles' own spread (6-D covariance of centre
    and rotation offsets), so the noise follows the posterior's shape and shrinks with it."""
    floor_px: float = 0.5
    """Smallest random-walk noise: this many pixels at the finest width, as a rotation
    (px / focal) and as a translation at the scene's typical depth (px x depth / focal)."""
    wide_fraction: float = 0.15
    """Noise of the perturbed fraction, as a fraction of the prior's spread (each of metres
    and radians), which keeps exploring the prior."""
    perturb_fraction: float = 0.1
    """Fraction of particles perturbed widely every step."""
    widths: tuple[int, ...] = (24, 48)
    """Comparison widths in pixels, coarse to fine, each used for an equal share of the steps."""


def annealing_temperature(cost: np.ndarray, ess_fraction: float, bounds: tuple[float, float]) -> float:
    """The temperature at which the weights exp(-cost / T) have an effective sample size of
    `ess_fraction` x N (Deutscher, Blake & Reid 2000, annealed particle filter: a fixed
    survival rate), by bisection on log T within bounds (hottest, coldest)."""
    c = cost - cost.min()

    def ess(t: float) -> float:
        w = np.exp(-c / t)
        return w.sum() ** 2 / (w @ w) / len(c)

    hot, cold = np.log(bounds[0]), np.log(bounds[1])
    if ess(np.exp(cold)) >= ess_fraction:
        return float(np.exp(cold))
    if ess(np.exp(hot)) <= ess_fraction:
        return float(np.exp(hot))
    for _ in range(30):
        mid = 0.5 * (hot + cold)
        hot, cold = (mid, cold) if ess(np.exp(mid)) >= ess_fraction else (hot, mid)
    return float(np.exp(hot))


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
    return apply_offsets(particles, np.c_[rng.normal(scale=sigma_m, size=(len(particles), 3)),
                                          rng.normal(scale=sigma_rad, size=(len(particles), 3))])


def apply_offsets(particles: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Particles (N, 6) moved by offsets (N, 6): centre + offset[:3] (world metres),
    rotation composed with exp(offset[3:]) in the camera frame (radians)."""
    R = Rotation.from_rotvec(particles[:, 3:]) * Rotation.from_rotvec(offsets[:, 3:])
    return np.c_[particles[:, :3] + offsets[:, :3], R.as_rotvec()]


def pose_covariance(particles: np.ndarray) -> np.ndarray:
    """(6, 6) covariance of the particles' offsets from their mean pose: centre (metres) and
    the rotation vector of mean^-1 * R (radians, camera frame)."""
    mean = particles_from_cam_from_world(weighted_pose(particles, np.ones(len(particles))))[0]
    R0 = Rotation.from_rotvec(mean[3:])
    rot = (R0.inv() * Rotation.from_rotvec(particles[:, 3:])).as_rotvec()
    return np.cov(np.c_[particles[:, :3] - mean[:3], rot].T)


def diffuse(particles: np.ndarray, scale: float, floor: tuple[float, float], rng: np.random.Generator,
            cov: np.ndarray | None = None) -> np.ndarray:
    """The annealed particle filter's random walk (Deutscher et al. 2000): Gaussian noise
    with scale^2 x the particles' own covariance (`pose_covariance`, or `cov` when the
    caller has it) plus a floor (metres, radians) on the diagonal."""
    cov = pose_covariance(particles) if cov is None else cov
    noise = scale ** 2 * cov + np.diag([floor[0] ** 2] * 3 + [floor[1] ** 2] * 3)
    return apply_offsets(particles, rng.multivariate_normal(np.zeros(6), noise, size=len(particles)))


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


@dataclass(frozen=True)
class PriorBox:
    """The support of `sample_around`'s uniform prior: centres within +-spread_m (metres) per
    axis of the pose's centre, rotations within spread_rad (radians) of its rotation.
    cam_from_world: (4, 4) the prior pose."""

    cam_from_world: np.ndarray
    spread_m: float
    spread_rad: float

    def contains(self, particles: np.ndarray) -> np.ndarray:
        """(N,) bool: which particles (N, 6) lie inside the prior's support."""
        p = particles_from_cam_from_world(self.cam_from_world)[0]
        dR = Rotation.from_rotvec(p[3:]).inv() * Rotation.from_rotvec(particles[:, 3:])
        return (np.abs(particles[:, :3] - p[:3]).max(axis=1) <= self.spread_m) & (dR.magnitude() <= self.spread_rad)


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
    """cam_from_world (4, 4) weighted mean; best (4, 4) lowest-cost particle; particles
    (N, 6), weights (N,) and costs (N,) of the last step; history: per step (mean pose (4, 4))."""

    cam_from_world: np.ndarray
    best: np.ndarray
    particles: np.ndarray
    weights: np.ndarray
    history: list[np.ndarray]
    costs: np.ndarray


class Pose6Filter:
    """Localise one photo: `run(image, camera, particles)`.

    depth_m: the scene's typical viewing depth (metres, e.g. the median depth of the model
    from its photos) that turns pixels into metres; spread: the prior's (metres, radians)
    half-widths, the scale of the wide perturbation; prior: the support of the prior the
    particles were drawn from (the posterior is zero outside it, so particles the random
    walk carries out of it get no weight)."""

    def __init__(self, likelihood: BatchedLikelihood, config: Pose6FilterConfig, rng: np.random.Generator,
                 depth_m: float, spread: tuple[float, float], prior: PriorBox | None = None):
        self.likelihood, self.config, self.rng, self.prior = likelihood, config, rng, prior
        self.depth_m, self.spread = depth_m, spread

    def width_at(self, k: int) -> int:
        """Comparison width at step k: coarse to fine, an equal share of the steps each."""
        c = self.config
        return c.widths[min(k * len(c.widths) // max(c.steps, 1), len(c.widths) - 1)]

    def cost(self, particles: np.ndarray, camera: Camera, width: int) -> np.ndarray:
        """(N,) robust costs (`render_likelihood`) of particles against the current
        observation, which must have been set at `comparison_camera(camera, width)`'s size."""
        m = self.likelihood.model
        template = comparison_camera(camera, width)
        clip = template.gl_projection(m.near, m.far) @ cam_from_world_of(particles)
        return self.likelihood.view_scores(clip, particles[:, :3])[:, 3].astype(float)

    def floor(self, camera: Camera) -> tuple[float, float]:
        """(metres, radians) of `floor_px` at the finest width."""
        f = comparison_camera(camera, self.config.widths[-1]).K[0, 0]
        return self.config.floor_px * self.depth_m / f, self.config.floor_px / f

    def _move(self, particles: np.ndarray, floor: tuple[float, float]) -> np.ndarray:
        """Diffuse every particle by the particle spread; perturb a fraction widely."""
        c, rng = self.config, self.rng
        particles = diffuse(particles, c.diffusion, floor, rng)
        jump = rng.random(len(particles)) < c.perturb_fraction
        particles[jump] = perturb(particles[jump], c.wide_fraction * self.spread[0],
                                  c.wide_fraction * self.spread[1], rng)
        return particles

    def weights(self, particles: np.ndarray, camera: Camera, width: int) -> tuple[np.ndarray, np.ndarray]:
        """(N,) normalised weights: the rendered likelihood tempered to the annealing
        temperature, zero outside the prior's support; and the (N,) costs."""
        c = self.config
        cost = self.cost(particles, camera, width)
        inside = self.prior.contains(particles) if self.prior is not None else np.ones(len(cost), bool)
        if not inside.any():
            inside[:] = True
        ll = np.where(inside, -cost / annealing_temperature(cost[inside], c.ess_fraction, c.temperature), -np.inf)
        w = np.exp(ll - ll.max())
        return w / w.sum(), np.where(inside, cost, np.inf)

    def run(self, image: np.ndarray, camera: Camera, particles: np.ndarray,
            on_step: Callable[[int, np.ndarray, np.ndarray], None] | None = None) -> Pose6Estimate:
        """Iterate the filter on `image` ((H, W, 3) uint8) taken by a camera with the
        intrinsics of `camera` (pose ignored), from initial particles (N, 6) (N may exceed
        `n_particles`: the first step thins them). on_step(k, particles, weights)."""
        c, rng = self.config, self.rng
        floor = self.floor(camera)
        history, width_set = [], None
        for k in range(c.steps):
            width = self.width_at(k)
            if width != width_set:
                small = comparison_camera(camera, width)
                self.likelihood.set_observation(image, (small.width, small.height))
                if self.likelihood.focus is not None:
                    self.likelihood.focus(particles[:, :3].mean(axis=0))
                width_set = width
            if k > 0:
                particles = self._move(particles, floor)
            w, cost = self.weights(particles, camera, width)
            history.append(weighted_pose(particles, w))
            if on_step:
                on_step(k, particles, w)
            if k < c.steps - 1:
                with numpy_random_from(rng):
                    particles = particles[systematic_resample(w)]
                if len(particles) > c.n_particles:  # the wide first sample, thinned
                    particles = particles[rng.choice(len(particles), c.n_particles, replace=False)]
        best = cam_from_world_of(particles[np.argmin(cost)][None])[0]
        return Pose6Estimate(history[-1], best, particles, w, history, cost)


def camera_at(camera: Camera, cam_from_world: np.ndarray) -> Camera:
    """`camera`'s intrinsics at a pose (re-orthonormalised)."""
    R = Rotation.from_matrix(cam_from_world[:3, :3]).as_matrix()
    return camera.with_pose(rigid(R, cam_from_world[:3, 3]))
