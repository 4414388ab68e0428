"""Sequential Monte-Carlo approximation of the view-quality cost space (Mendez et al.,
"Scenic Route Planner", Sec. 3.2.1).

Particles are 4-DoF poses (x, y, z, yaw): positions drawn uniformly from the empty voxels
Ve (never from occupied ones, where a camera would collide), yaw drawn uniformly. Each
particle i is weighted by

    w_i = 1 - C_nbv^i                                                 (1)

with C_nbv the NBV cost of Sec. 3.2.2 (in [0, 1]). Resampling has three parts, so that the
set approximates the whole cost function and still finds newly emerging peaks:
I_p the best particles propagated unchanged, I_g a weighted resample with Gaussian noise,
and I_u fresh uniform samples from Ve;  I = I_p ∪ I_g ∪ I_u.
Arrays: particles (N, 4) metres / radians, weights (N,).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from explore.scenic.cost import NBVConfig, view_costs
from explore.scenic.map import ScenicMap
from explore.scenic.pose import CameraModel
from explore.scenic.workspace import Workspace, uniform_positions


@dataclass(frozen=True)
class SMCConfig:
    n_particles: int = 300
    """Particles in the cost-space approximation, |I|."""
    frac_best: float = 0.1
    """Fraction of the set propagated unchanged from the best particles, |I_p| / |I|."""
    frac_uniform: float = 0.2
    """Fraction drawn afresh uniformly from Ve, |I_u| / |I|; the rest is I_g."""
    sigma_pos_m: float = 0.2
    """Standard deviation of the Gaussian noise on resampled positions (metres)."""
    sigma_yaw_rad: float = 0.3
    """Standard deviation of the Gaussian noise on resampled yaws (radians)."""

    def counts(self) -> tuple[int, int, int]:
        """(|I_p|, |I_g|, |I_u|), summing to n_particles."""
        n_p = int(round(self.frac_best * self.n_particles))
        n_u = int(round(self.frac_uniform * self.n_particles))
        return n_p, self.n_particles - n_p - n_u, n_u


def sample_uniform(vmap: ScenicMap, ws: Workspace, n: int, rng: np.random.Generator) -> np.ndarray:
    """n particles (n, 4): positions uniform over Ve in the workspace, yaw uniform in [-π, π)."""
    return np.c_[uniform_positions(vmap, ws, n, rng), rng.uniform(-np.pi, np.pi, n)]


def weights(vmap: ScenicMap, particles: np.ndarray, model: CameraModel, nbv: NBVConfig) -> np.ndarray:
    """w_i = 1 - C_nbv of each particle, eq. (1)."""
    return 1.0 - view_costs(vmap, particles, model, nbv)


def resample(particles: np.ndarray, w: np.ndarray, vmap: ScenicMap, ws: Workspace,
             config: SMCConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The next particle set I = I_p ∪ I_g ∪ I_u (N, 4) and the label of each particle
    (0 = I_p best kept, 1 = I_g weighted resample + noise, 2 = I_u fresh uniform).
    A noisy I_g particle that leaves the workspace keeps its parent's position."""
    n_p, n_g, n_u = config.counts()
    best = particles[np.argsort(-w, kind="stable")[:n_p]]
    p = np.clip(w, 0.0, None)
    p = p / p.sum() if p.sum() > 0 else np.full(len(w), 1.0 / len(w))
    parents = particles[rng.choice(len(particles), size=n_g, p=p)]
    noisy = parents + np.c_[rng.normal(0, config.sigma_pos_m, (n_g, 3)),
                            rng.normal(0, config.sigma_yaw_rad, n_g)]
    noisy[:, :3] = np.where(ws.contains(noisy[:, :3])[:, None], noisy[:, :3], parents[:, :3])
    noisy[:, 3] = np.angle(np.exp(1j * noisy[:, 3]))
    fresh = sample_uniform(vmap, ws, n_u, rng)
    labels = np.repeat(np.arange(3), [n_p, n_g, n_u])
    return np.r_[best, noisy, fresh], labels


class CostSpace:
    """The SMC particle set held between frames: `update(vmap)` re-weights the particles on
    the new map and resamples them; `goal()` is the current peak of the cost function."""

    def __init__(self, vmap: ScenicMap, ws: Workspace, model: CameraModel, nbv: NBVConfig,
                 config: SMCConfig, rng: np.random.Generator):
        self.ws, self.model, self.nbv, self.config, self.rng = ws, model, nbv, config, rng
        self.particles = sample_uniform(vmap, ws, config.n_particles, rng)
        self.w = weights(vmap, self.particles, model, nbv)

    def update(self, vmap: ScenicMap) -> None:
        """Resample on the previous weights, then weight the new set on the current map."""
        self.particles, _ = resample(self.particles, self.w, vmap, self.ws, self.config, self.rng)
        self.w = weights(vmap, self.particles, self.model, self.nbv)

    def goals(self, agents: np.ndarray, separation_m: float, min_distance_m: float) -> np.ndarray:
        """Goal states x_goal (A, 4) of agents at positions (A, 3): the best particles at least
        separation_m apart and min_distance_m from every agent (a camera standing on the peak
        has nothing left to plan); the best particle repeats if the set cannot supply them."""
        d_agents = np.linalg.norm(self.particles[:, None, :3] - agents[None, :, :3], axis=-1)
        ok = d_agents.min(axis=1) >= min_distance_m
        order = np.argsort(-np.where(ok, self.w, -np.inf), kind="stable")
        out = []
        for i in order[:max(ok.sum(), 1)]:  # best first, at least the overall best
            q = self.particles[i]
            if all(np.linalg.norm(q[:3] - g[:3]) >= separation_m for g in out):
                out.append(q)
            if len(out) == len(agents):
                break
        while len(out) < len(agents):
            out.append(out[0])
        return np.array(out)
