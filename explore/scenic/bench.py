"""Speed figure of the Scenic Route Planner's NBV cost (see `ibrnav bench`): SMC particles
scored per second by the batched ray traversal of `explore.scenic.cost.view_costs` against the
naive loop that marches one ray at a time, on the office map after the initial pair."""

from __future__ import annotations

import time

import numpy as np

from explore.scenic.cost import NBVConfig, pose_rays, ray_costs, too_near, view_costs
from explore.scenic.map import EMPTY, OCCUPIED
from explore.scenic.session import ScenicSession, SessionConfig
from ibr.synthetic import make_world


def naive_view_cost(vmap, pose: np.ndarray, model, config: NBVConfig) -> float:
    """C_view of one pose with a Python loop per ray and per half-voxel step."""
    rays = pose_rays(pose[None], model, config)[0]
    step, hits = 0.5 * vmap.voxel_m, []
    for r in rays:
        hit, t = -1, 0.5 * step
        while t < config.max_range_m:
            ijk, inside = vmap.voxel_of(pose[None, :3] + t * r)
            s = vmap.state[tuple(ijk[0])] if inside[0] else -1
            if s != EMPTY:
                hit = int(np.ravel_multi_index(tuple(ijk[0]), vmap.state.shape)) if s == OCCUPIED else -1
                break
            t += step
        hits.append(hit)
    cost = ray_costs(vmap, np.array(hits), rays, config)
    cost[too_near(vmap, pose[None, :3], np.array(hits)[None], config.min_range_m)[0]] = 1.0
    return float(cost.mean())


def nbv_poses_per_s() -> dict:
    """Poses/s of the NBV cost (16 x 12 rays each): 300 batched vs a per-ray loop on 5."""
    session = ScenicSession(make_world("office", 0), SessionConfig(), np.random.default_rng(0))
    vmap, model, nbv = session.map, session.config.camera, session.config.nbv
    poses = session.space.particles
    t = time.perf_counter()
    batched = view_costs(vmap, poses, model, nbv)
    rate = len(poses) / (time.perf_counter() - t)
    t = time.perf_counter()
    naive = [naive_view_cost(vmap, q, model, nbv) for q in poses[:5]]
    base = 5 / (time.perf_counter() - t)
    np.testing.assert_allclose(naive, batched[:5], atol=1e-9)  # the same costs
    return {"value": rate, "unit": "poses/s", "baseline": base, "ratio": rate / base}


FIGURES = {"scenic_nbv_poses_per_s": nbv_poses_per_s}
