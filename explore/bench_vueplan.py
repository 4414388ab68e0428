"""`ibrnav bench` figures for VuePlan (Blaer & Allen 2009).

vueplan_phase2_s_per_nbv: seconds to compute one next-best view (all potential views'
    counts of visible boundary-unseen voxels) on the courtyard at 0.2 m voxels
    (200 x 200 x 70 = 2.8 M voxels) after two scans from opposite corners, so that >= 20k voxels are
    boundary unseen (the paper: ~10 min per NBV on Fort Jay's 2.7 M voxels, 25k boundary
    unseen). Baseline: the same count with one scalar voxel walk per ray
    (`count_visible_per_ray`'s walk), timed on a random sample of the same rays and scaled
    to all rays the NBV walks; ratio = per-ray throughput of the vectorised walk over the
    scalar one.
vueplan_phase1_s_500: Phase I seconds for 500 candidates on the courtyard. Baseline: a
    naive per-candidate shapely visibility test (each wall element's midpoint is visible
    when the sight line from the candidate is covered by the free space, one shapely call
    per candidate and element), timed on 20 candidates and scaled to 500.
"""

from __future__ import annotations

import time

import numpy as np
import shapely

from explore.floorplan import FloorPlan
from explore.voxel_grid import EMPTY, VoxelGrid, boundary_unseen, insert_scan
from explore.vueplan_phase1 import Phase1Config, plan_phase1, sample_candidates, wall_elements
from explore.vueplan_phase2 import FACE_NORMALS, Phase2Config, _walk_one, count_visible, ground_candidates
from ibr.scan_simulator import ScanConfig, simulate_scan
from ibr.synthetic import make_world


def _phase2_state():
    world = make_world("courtyard")
    grid = VoxelGrid.covering([-20, -20, 0], [20, 20, 14], 0.2)
    for xy in ((15.0, 15.0), (-15.0, -15.0)):  # two opposite corners: >= 20k boundary unseen
        scan = simulate_scan(world.renderer(), np.array([*xy, 1.6]), ScanConfig(resolution_deg=0.5))
        insert_scan(grid, scan.origin, scan.points, scan.no_return, scan.max_range_m)
    cfg = Phase2Config(candidate_stride=5)
    return grid, ground_candidates(grid, world.free_space, cfg), cfg


def phase2_s_per_nbv() -> dict:
    grid, views, cfg = _phase2_state()
    frontier = boundary_unseen(grid)
    stats: dict = {}
    t = time.perf_counter()
    counts = count_visible(grid, views, cfg, frontier, stats)
    seconds = time.perf_counter() - t
    # scalar reference on a random sample of the rays the vectorised pass walked
    rng = np.random.default_rng(0)
    idx, faces = frontier
    u_c = grid.centers(idx)
    blocked = grid.state != EMPTY
    cos_max = np.cos(cfg.max_grazing_rad)
    sample, walked = 0, 0
    t = time.perf_counter()
    while walked < 1500:
        i, j = rng.integers(len(idx)), rng.integers(len(views))
        d = views[j] - u_c[i]
        r = np.linalg.norm(d)
        sample += 1
        if not (cfg.min_range_m <= r <= cfg.max_range_m):
            continue
        if max((FACE_NORMALS[k] @ d) / r for k in range(6) if faces[i, k]) < cos_max:
            continue
        _walk_one(blocked, grid.to_voxel(u_c[[i]])[0], grid.to_voxel(views[[j]])[0])
        walked += 1
    per_ray = (time.perf_counter() - t) / walked
    baseline = per_ray * stats["rays"]
    print(f"[bench] phase2: grid {grid.shape} = {np.prod(grid.shape):,} voxels, "
          f"{len(idx):,} boundary unseen, {len(views)} views, {stats['rays']:,} rays walked, "
          f"best view sees {counts.max()}", flush=True)
    return {"value": seconds, "unit": "s/NBV", "baseline": baseline, "ratio": baseline / seconds,
            "voxels": int(np.prod(grid.shape)), "boundary_unseen": int(len(idx)),
            "rays": int(stats["rays"])}


def _naive_phase1(plan: FloorPlan, positions: np.ndarray, cfg: Phase1Config) -> np.ndarray:
    walls = plan.wall_segments()
    ew, et, _ = wall_elements(walls, cfg.element_m)
    mids = walls[ew, 0] + et[:, None] * (walls[ew, 1] - walls[ew, 0])
    normal = (walls[ew, 1] - walls[ew, 0]) @ np.array([[0, -1], [1, 0]])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    region = plan.free_space.buffer(1e-6)
    cover = np.zeros((len(positions), len(mids)), bool)
    for i, c in enumerate(positions):
        for q, m in enumerate(mids):
            d = m - c
            r = np.linalg.norm(d)
            if not (cfg.min_range_m <= r <= cfg.max_range_m):
                continue
            if abs(d @ normal[q]) / r < np.cos(cfg.max_grazing_rad):
                continue
            cover[i, q] = region.covers(shapely.LineString([c, m]))
    return cover


def phase1_s_500() -> dict:
    plan = FloorPlan(make_world("courtyard").free_space)
    cfg = Phase1Config(n_candidates=500)
    t = time.perf_counter()
    res = plan_phase1(plan, cfg, np.random.default_rng(0))
    seconds = time.perf_counter() - t
    pos, _ = sample_candidates(plan.free_space, 20, np.random.default_rng(1), cfg.clearance_m)
    t = time.perf_counter()
    _naive_phase1(plan, pos, cfg)
    baseline = (time.perf_counter() - t) * 500 / 20
    print(f"[bench] phase1: {len(res.chosen)} views, {100 * res.boundary_coverage:.1f}% boundary", flush=True)
    return {"value": seconds, "unit": "s", "baseline": baseline, "ratio": baseline / seconds,
            "views": len(res.chosen), "boundary_coverage": res.boundary_coverage}


FIGURES = {"vueplan_phase2_s_per_nbv": phase2_s_per_nbv, "vueplan_phase1_s_500": phase1_s_500}
