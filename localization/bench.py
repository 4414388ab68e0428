"""Speed figures of localisation (see `ibrnav bench`).

particle_likelihoods_per_s_64x48: the rendered-view likelihood, batched vs one render per particle.
pnp_s_per_query: seconds per PnP query of the feature localiser on fountain-P11 (SIFT of the
    query, matching against the map through the prebuilt FLANN KD-tree, RANSAC PnP +
    refinement) vs the same query with brute-force descriptor matching against every map
    descriptor (no index), in the same run. The map is built from the other ten photos
    (leave-one-out) and is not timed."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ibr.bench import best_seconds
from ibr.camera import Camera, intrinsics_from_fov
from ibr.errors import InputError
from ibr.scene import load_scene
from ibr.synthetic import make_world
from localization.feature_localizer import FeatureMap
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
FOUNTAIN = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "strecha" / "fountain-P11"


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


class BruteForceFeatureMap(FeatureMap):
    """The naive baseline: the same map, matched exhaustively (cv2.BFMatcher, L2)."""

    def __init__(self, points, descriptors, owner, config):
        super().__init__(points, descriptors, owner, config)
        self.matcher = cv2.BFMatcher(cv2.NORM_L2)
        self.matcher.add([np.ascontiguousarray(descriptors, np.float32)])


def pnp_s_per_query() -> dict:
    """PnP seconds per query (fountain-P11, 0005.jpg held out), KD-tree index vs brute force."""
    if not FOUNTAIN.is_dir():
        raise InputError(f"{FOUNTAIN}: real data not found (pnp_s_per_query needs fountain-P11)")
    scene = load_scene(FOUNTAIN)
    held = scene.view("0005.jpg")
    fmap = FeatureMap.from_scene(scene, exclude=[held.name])
    naive = BruteForceFeatureMap(fmap.points, fmap.descriptors, fmap.owner, fmap.config)
    for m in (fmap, naive):  # both must actually localise the photo
        if m.localize(held.image, held.camera) is None:
            raise RuntimeError("PnP failed on fountain-P11 0005.jpg")
    fast = best_seconds(lambda: fmap.localize(held.image, held.camera), repeats=3, warm_up=False)
    slow = best_seconds(lambda: naive.localize(held.image, held.camera), repeats=3, warm_up=False)
    return {"value": fast, "unit": "s/query", "baseline": slow, "ratio": slow / fast}


FIGURES = {"particle_likelihoods_per_s_64x48": particle_likelihoods_per_s_64x48,
           "pnp_s_per_query": pnp_s_per_query}
