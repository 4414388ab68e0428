"""Speed figures of localisation (see `ibrnav bench`).

particle_likelihoods_per_s_64x48: the rendered-view likelihood, batched vs one render per particle.
pnp_s_per_query: seconds per PnP query of the feature localiser on fountain-P11 (SIFT of the
    query, matching against the map through the prebuilt FLANN KD-tree, RANSAC PnP +
    refinement) vs the same query with brute-force descriptor matching against every map
    descriptor (no index), in the same run. The map is built from the other ten photos
    (leave-one-out) and is not timed.
pf_seconds_per_query: seconds per rendered-view localisation of a fountain-P11 photo (0005
    held out, +-1 m / +-30 deg priors, 3 queries): the particle filter at 24-48 px on the
    coarse model, then Gauss-Newton (`render_localizer`) vs the schedule it replaced, a
    pure annealed particle filter of 48 steps x 100 particles (2,000 at the first step)
    compared at 48, 96, 192 and 384 px on the 16k-triangle model, same cost, same map, in
    the same run. Both position errors are reported beside the times (value_error_m,
    baseline_error_m: medians). The map is built once and not timed."""

from __future__ import annotations

from concurrent.futures import Future
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

    def _start_index(self) -> Future:  # no KD-tree built (nor building) beside it
        matcher = cv2.BFMatcher(cv2.NORM_L2)
        matcher.add([np.ascontiguousarray(self.descriptors, np.float32)])
        built = Future()
        built.set_result(matcher)
        return built


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


def pf_seconds_per_query(queries: int = 3) -> dict:
    """Seconds per query of the rendered-view localiser vs the old annealing schedule."""
    import time

    from localization.eval import draw_prior
    from localization.feature_localizer import pose_errors
    from localization.localize import LocConfig, SceneLocalizer
    from localization.pose6_filter import Pose6Filter, Pose6FilterConfig, PriorBox, sample_around

    if not FOUNTAIN.is_dir():
        raise InputError(f"{FOUNTAIN}: real data not found (pf_seconds_per_query needs fountain-P11)")
    scene = load_scene(FOUNTAIN)
    held = scene.view("0005.jpg")
    loc = SceneLocalizer(scene.without(held.name), "pf", LocConfig())
    model, truth = loc.model, held.camera.cam_from_world
    old = Pose6FilterConfig(n_particles=100, n_initial=2000, steps=48, widths=(48, 96, 192, 384))
    new_s, old_s, new_e, old_e = [], [], [], []
    for q in range(queries):
        rng = np.random.default_rng(q)
        prior = draw_prior(truth, 1.0, 30.0, rng)
        res = loc.localize(held.image, held.camera, prior, 1.0, 30.0, rng)
        new_s.append(res.seconds)
        new_e.append(pose_errors(res.cam_from_world, truth)[0])
        rng = np.random.default_rng(q)
        t = time.perf_counter()
        spread = (1.0, np.radians(30.0))
        pf = Pose6Filter(model.fine.likelihood, old, rng, model.depth_m, spread, PriorBox(prior, *spread))
        est = pf.run(held.image, held.camera, sample_around(prior, old.n_initial, *spread, rng))
        old_s.append(time.perf_counter() - t)
        old_e.append(pose_errors(est.cam_from_world, truth)[0])
    loc.release()
    value, baseline = float(np.mean(new_s)), float(np.mean(old_s))
    return {"value": value, "unit": "s/query", "baseline": baseline, "ratio": baseline / value,
            "value_error_m": float(np.median(new_e)), "baseline_error_m": float(np.median(old_e))}


FIGURES = {"particle_likelihoods_per_s_64x48": particle_likelihoods_per_s_64x48,
           "pnp_s_per_query": pnp_s_per_query, "pf_seconds_per_query": pf_seconds_per_query}
