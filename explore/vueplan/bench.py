"""`ibrnav bench` figures for VuePlan (Blaer & Allen 2009).

vueplan_phase2_s_per_nbv: seconds to compute one next-best view (every potential view's
    count of visible boundary-unseen voxels, `count_visible` with its default Embree
    occlusion queries) on the courtyard at 0.2 m
    voxels (200 x 200 x 70 = 2.8 M voxels) after two scans from opposite corners, so that
    >= 20k voxels are boundary unseen (the paper: ~10 min per NBV on Fort Jay's 2.7 M
    voxels, 25k boundary unseen). Baseline: the straightforward per-ray reference (one
    scalar voxel walk per (voxel, view) pair, `count_visible_per_ray`'s loop), timed on a
    random sample of the same grid's pairs and scaled to all of them; ratio = baseline /
    value. So that the sampled baseline can be checked, the reference is also run in full on a smaller grid (the same
    scans in 1 m voxels) beside `count_visible` with both backends (Embree, numpy walk):
    "small_grid_ratio" is the reference's time over Embree's and "small_grid_agree_*" the
    share of views whose counts agree exactly (views stand on the voxel lattice, so rays
    through voxel edges or corners, where tie-breaking differs, are common).
vueplan_phase1_s_500: Phase I seconds for 500 candidates on the courtyard. Baseline: a
    naive per-candidate shapely visibility test (each wall element's midpoint is visible
    when the sight line from the candidate is covered by the free space, one shapely call
    per candidate and element), timed on 20 candidates and scaled to 500.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace

import numpy as np
import shapely

from explore.floorplan import FloorPlan
from explore.vueplan.voxel_grid import EMPTY, OCCUPIED, VoxelGrid, boundary_unseen, insert_scan
from explore.vueplan.phase1 import Phase1Config, plan_phase1, sample_candidates, wall_elements
from explore.vueplan.phase2 import (FACE_NORMALS, Phase2Config, walk_one, count_visible, count_visible_per_ray,
                                    ground_candidates)
from explore.vueplan.scan_simulator import ScanConfig, simulate_scan
from ibr.synthetic import make_world

log = logging.getLogger(__name__)


def _phase2_state(voxel_m: float, stride: int, scans=None):
    """The courtyard's voxel grid (voxel_m) after two scans from opposite corners, its
    potential views (every stride-th ground voxel) and the scans."""
    world = make_world("courtyard")
    grid = VoxelGrid.covering([-20, -20, 0], [20, 20, 14], voxel_m)
    if scans is None:
        renderer = world.renderer()
        scans = [simulate_scan(renderer, np.array([*xy, 1.6]), ScanConfig(resolution_deg=0.5))
                 for xy in ((15.0, 15.0), (-15.0, -15.0))]
    for scan in scans:
        insert_scan(grid, scan.origin, scan.points, scan.no_return, scan.max_range_m)
    cfg = Phase2Config(candidate_stride=stride)
    return grid, ground_candidates(grid, world.free_space, cfg), cfg, scans


def _small_grid_reference(scans) -> dict:
    """count_visible and the per-ray reference, both in full, on the same scans in 1 m voxels."""
    grid, views, cfg, _ = _phase2_state(1.0, 4, scans)
    out, counts = {}, {}
    for name, fn in (("embree", lambda: count_visible(grid, views, cfg)),
                     ("walk", lambda: count_visible(grid, views, replace(cfg, ray_backend="walk"))),
                     ("per_ray", lambda: count_visible_per_ray(grid, views, cfg))):
        t = time.perf_counter()
        counts[name] = fn()
        out[name] = time.perf_counter() - t
    log.info(f"phase2 small grid {grid.shape} = {np.prod(grid.shape):,} voxels, "
          f"{len(boundary_unseen(grid)[0]):,} boundary unseen, {len(views)} views: embree "
          f"{out['embree']:.2f} s, numpy walk {out['walk']:.2f} s, per-ray {out['per_ray']:.2f} s")
    return {"small_grid_voxels": int(np.prod(grid.shape)), "small_grid_s": out["embree"],
            "small_grid_walk_s": out["walk"], "small_grid_per_ray_s": out["per_ray"],
            "small_grid_ratio": out["per_ray"] / out["embree"],
            "small_grid_agree_embree": float(np.mean(counts["embree"] == counts["per_ray"])),
            "small_grid_agree_walk": float(np.mean(counts["walk"] == counts["per_ray"]))}


def phase2_s_per_nbv() -> dict:
    t = time.perf_counter()
    grid, views, cfg, scans = _phase2_state(0.2, 5)
    log.info(f"phase2: two scans inserted in {time.perf_counter() - t:.1f} s")
    frontier = boundary_unseen(grid)
    stats: dict = {}
    t, cpu = time.perf_counter(), time.process_time()
    counts = count_visible(grid, views, cfg, frontier, stats)
    seconds, cpu_seconds = time.perf_counter() - t, time.process_time() - cpu
    # the per-ray reference on a random sample of the same pairs, scaled to all of them
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
        walk_one(blocked, grid.to_voxel(u_c[[i]])[0], grid.to_voxel(views[[j]])[0])
        walked += 1
    per_ray = (time.perf_counter() - t) / walked
    baseline = per_ray * stats["rays"]
    log.info(f"phase2: grid {grid.shape} = {np.prod(grid.shape):,} voxels, "
          f"{len(idx):,} boundary unseen, {int((grid.state == OCCUPIED).sum()):,} seen-occupied, "
          f"{len(views)} views, {stats['rays']:,} rays tested (of {stats['pairs']:,} pairs): "
          f"{seconds:.1f} s ({cpu_seconds:.1f} s CPU); best view sees {counts.max()}")
    return {"value": seconds, "unit": "s/NBV", "baseline": baseline, "ratio": baseline / seconds,
            "cpu_s": cpu_seconds, "voxels": int(np.prod(grid.shape)), "boundary_unseen": int(len(idx)),
            "seen_occupied": int((grid.state == OCCUPIED).sum()), "views": int(len(views)),
            "pairs": int(stats["pairs"]), "rays": int(stats["rays"]), "best_count": int(counts.max()),
            **_small_grid_reference(scans)}


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
    log.info(f"phase1: {len(res.chosen)} views, {100 * res.boundary_coverage:.1f}% boundary")
    return {"value": seconds, "unit": "s", "baseline": baseline, "ratio": baseline / seconds,
            "views": len(res.chosen), "boundary_coverage": res.boundary_coverage}


FIGURES = {"vueplan_phase2_s_per_nbv": phase2_s_per_nbv, "vueplan_phase1_s_500": phase1_s_500}
