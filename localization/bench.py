"""Speed figures of the rendered-view likelihood (see `ibrnav bench`)."""

from __future__ import annotations

import numpy as np

from ibr.bench import best_seconds
from ibr.camera import Camera, intrinsics_from_fov
from ibr.synthetic import make_world
from localization.particle_filter import sample_free_poses
from localization.pose_views import forward_camera_mount, robot_camera, se2_views
from localization.render_likelihood import (
    BatchedLikelihood,
    LikelihoodConfig,
    likelihood_renderer,
    luminance,
    reference_tile_scores,
    scores_to_loglik,
)

N_PARTICLES = 512
SIZE = (64, 48)


def particle_likelihoods_per_s_64x48() -> dict:
    """Particle log-likelihoods/s at 64x48 in the synthetic office (lean likelihood
    renderer, NCC): `BatchedLikelihood` (one instanced draw of all particle views into an
    atlas, GPU comparison and reduction, N numbers read back) vs the naive path on the same
    512 SE(2) poses, `reference_tile_scores` (one render + read-back per particle, the
    statistics in numpy)."""
    world = make_world("office", 0)
    K = intrinsics_from_fov(60, 320, 240)
    mount = forward_camera_mount(0.4)
    photo = world.photograph(robot_camera(np.array([-1.5, -2.5, 0.3]), K, (320, 240), mount))
    poses = sample_free_poses(world.free_space, N_PARTICLES, np.random.default_rng(0))
    template = Camera(K, 320, 240).scaled(SIZE[0] / 320)
    renderer = likelihood_renderer(world.mesh, background=world.background)
    config = LikelihoodConfig(size=SIZE)
    lik = BatchedLikelihood(renderer, config, world.light)
    lik.set_observation(photo, SIZE)
    clip, eyes = se2_views(poses, template, mount, renderer.near, renderer.far)
    cams = [robot_camera(p, K, (320, 240), mount).scaled(SIZE[0] / 320) for p in poses]
    observed = luminance(photo, SIZE)
    batched = N_PARTICLES / best_seconds(lambda: lik(clip, eyes), repeats=3)
    naive = N_PARTICLES / best_seconds(
        lambda: scores_to_loglik(reference_tile_scores(renderer, cams, observed, world.light), config), repeats=1)
    return {"value": batched, "unit": "likelihoods/s", "baseline": naive, "ratio": batched / naive}


FIGURES = {"particle_likelihoods_per_s_64x48": particle_likelihoods_per_s_64x48}
