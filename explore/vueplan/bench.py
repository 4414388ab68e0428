"""`ibrnav bench` figures for VuePlan (Blaer & Allen 2009).

vueplan_phase2_s_per_nbv: seconds to compute one next-best view (every potential view's
    count of visible boundary-unseen voxels, `count_visible` with its default GL backend) on
    the courtyard at 0.2 m voxels (200 x 200 x 70 = 2.8 M voxels) after two scans from
    opposite corners, so that >= 20k voxels are boundary unseen (the paper: ~10 min per NBV
    on Fort Jay's 2.7 M voxels, 25k boundary unseen). Baseline: the same count with the
    Embree backend (the exact reference), in the same run; ratio = baseline / value.
    "same_nbv" says whether both choose the same view, "nbv_score" is the Embree count of
    the GL NBV over Embree's best; CPU seconds (all threads) beside the wall clock. So that
    the backends can be checked against the straightforward per-ray walk, all are also run
    in full on a smaller grid (the same scans in 1 m voxels): "small_grid_agree_*" is the
    share of views whose counts agree exactly with it (views stand on the voxel lattice, so
    rays through voxel edges or corners, where tie-breaking differs, are common).
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
from explore.vueplan.voxel_grid import OCCUPIED, VoxelGrid, boundary_unseen, insert_scan
from explore.vueplan.phase1 import Phase1Config, plan_phase1, sample_candidates, wall_elements
from explore.vueplan.phase2 import Phase2Config, count_visible, count_visible_per_ray, ground_candidates
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
    for name, fn in (("gl", lambda: count_visible(grid, views, cfg)),
                     ("embree", lambda: count_visible(grid, views, replace(cfg, ray_backend="embree"))),
                     ("walk", lambda: count_visible(grid, views, replace(cfg, ray_backend="walk"))),
                     ("per_ray", lambda: count_visible_per_ray(grid, views, cfg))):
        t = time.perf_counter()
        counts[name] = fn()
        out[name] = time.perf_counter() - t
    log.info(f"phase2 small grid {grid.shape} = {np.prod(grid.shape):,} voxels, "
          f"{len(boundary_unseen(grid)[0]):,} boundary unseen, {len(views)} views: gl {out['gl']:.2f} s, "
          f"embree {out['embree']:.2f} s, numpy walk {out['walk']:.2f} s, per-ray {out['per_ray']:.2f} s")
    return {"small_grid_voxels": int(np.prod(grid.shape)), "small_grid_s": out["gl"],
            "small_grid_embree_s": out["embree"], "small_grid_walk_s": out["walk"],
            "small_grid_per_ray_s": out["per_ray"],
            "small_grid_agree_gl": float(np.mean(counts["gl"] == counts["per_ray"])),
            "small_grid_agree_embree": float(np.mean(counts["embree"] == counts["per_ray"])),
            "small_grid_agree_walk": float(np.mean(counts["walk"] == counts["per_ray"]))}


def phase2_s_per_nbv() -> dict:
    t = time.perf_counter()
    grid, views, cfg, scans = _phase2_state(0.2, 5)
    log.info(f"phase2: two scans inserted in {time.perf_counter() - t:.1f} s")
    frontier = boundary_unseen(grid)
    runs = {}
    for backend in ("gl", "embree"):
        stats: dict = {}
        t, cpu = time.perf_counter(), time.process_time()
        counts = count_visible(grid, views, replace(cfg, ray_backend=backend), frontier, stats)
        runs[backend] = (time.perf_counter() - t, time.process_time() - cpu, counts, stats)
        log.info(f"phase2 {backend}: {runs[backend][0]:.1f} s ({runs[backend][1]:.1f} s CPU), "
                 f"{stats['rays']:,} rays of {stats['pairs']:,} pairs; best view sees {counts.max()}")
    (seconds, cpu_s, gl, gl_stats), (base_s, base_cpu, exact, _) = runs["gl"], runs["embree"]
    log.info(f"phase2: grid {grid.shape} = {np.prod(grid.shape):,} voxels, {len(frontier[0]):,} boundary "
             f"unseen, {int((grid.state == OCCUPIED).sum()):,} seen-occupied, {len(views)} views")
    return {"value": seconds, "unit": "s/NBV", "baseline": base_s, "ratio": base_s / seconds,
            "cpu_s": cpu_s, "baseline_cpu_s": base_cpu, "cpu_ratio": base_cpu / cpu_s,
            "same_nbv": bool(np.argmax(gl) == np.argmax(exact)),
            "nbv_score": float(exact[np.argmax(gl)] / exact.max()),
            "voxels": int(np.prod(grid.shape)), "boundary_unseen": int(len(frontier[0])),
            "seen_occupied": int((grid.state == OCCUPIED).sum()), "views": int(len(views)),
            "pairs": int(gl_stats["pairs"]), "rays": int(gl_stats["rays"]), "best_count": int(gl.max()),
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
