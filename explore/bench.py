"""`ibrnav bench` figures of explore's shared planners: the rendering-quality heuristic
(`explore.view_quality`, Foster, Wang & Grupen Sec. IV-B) and A* on the navigation grid.

heuristic_evals_per_s_100src_64x48, heuristic_evals_per_s_100src_160x120: candidate
    views scored per second by the rendering-quality heuristic (`ViewQuality.score_views`:
    one instanced draw + compute-shader reduction per 256 views) with 100 source cameras
    (`world.default_cameras(100)` of synthetic:office, untextured office mesh as the
    proxy), 128 random candidate poses in the free space. Baseline: the numpy per-pixel
    reference on the same views (one render + read-back per view, then
    `view_quality_numpy`), timed on the first few views; ratio = GPU / numpy throughput.
    `max_abs_diff` is the largest score difference between the two on those views (rad).
    (The paper: ~155 evaluations/s with 100 sources on a GeForce GTX 480, CUDA.)
astar_s_100x100, astar_s_1000x1000: seconds of one A* search (pure Python, heapq)
    corner to corner (-1.5, -2.5) -> (1.5, 2.5) m on the office's navigation grid
    (KDE of 200k points sampled on the ground-truth mesh) over the square (-4, -4)..(4, 4) m
    with 100 x 100 / 1000 x 1000 cells. Baseline: scipy.sparse.csgraph.dijkstra (compiled) from the same start on
    the same graph (`grid_graph`, whose build time is reported apart as `graph_build_s`);
    ratio = baseline / A* seconds (> 1: A* is faster).
"""

from __future__ import annotations

import time

import numpy as np
import trimesh
from scipy.sparse.csgraph import dijkstra

from explore.astar import astar, grid_graph
from explore.candidates import sample_candidates
from explore.nav_grid import NavGridConfig, nav_grid_from_points
from explore.view_quality import ViewQuality, ViewQualityConfig
from ibr.camera import Camera, intrinsics_from_fov
from ibr.synthetic import make_world

N_CANDIDATES = 128


def level_mount(height_m: float) -> np.ndarray:
    """cam_from_robot (4, 4) of a level camera height_m above the floor looking along the
    robot's x axis (camera x = -robot y, camera y = -robot z)."""
    R = np.array([[0, -1.0, 0], [0, 0, -1.0], [1.0, 0, 0]])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, -R @ np.array([0.0, 0.0, height_m])
    return T


def _heuristic(size: tuple[int, int], n_reference: int) -> dict:
    world = make_world("office")
    proxy = trimesh.Trimesh(world.mesh.vertices, world.mesh.faces, process=False)
    vq = ViewQuality(proxy, world.default_cameras(100, 640, 480), config=ViewQualityConfig(size=size))
    poses = sample_candidates(world.free_space, N_CANDIDATES, np.random.default_rng(0), 0.3)
    template = Camera(intrinsics_from_fov(60.0, *size), *size)
    clip, eyes = vq.pose_views(poses, template, level_mount(world.view_height_m))
    vq.score_views(clip[:8], eyes[:8])  # warm-up: llvmpipe compiles shaders on first use
    t = time.perf_counter()
    gpu = vq.score_views(clip, eyes)
    rate = N_CANDIDATES / (time.perf_counter() - t)
    t = time.perf_counter()
    ref = vq.score_views_numpy(clip[:n_reference], eyes[:n_reference])[:, 0]
    baseline = n_reference / (time.perf_counter() - t)
    return {"value": rate, "unit": "evals/s", "baseline": baseline, "ratio": rate / baseline,
            "max_abs_diff": float(np.abs(gpu[:n_reference] - ref).max())}


def heuristic_64x48() -> dict:
    return _heuristic((64, 48), 16)


def heuristic_160x120() -> dict:
    return _heuristic((160, 120), 6)


def _astar(cells: int) -> dict:
    world = make_world("office")
    points, _ = trimesh.sample.sample_surface(world.mesh, 200_000, seed=0)
    s = cells / 100  # keep the kernel's width in metres
    config = NavGridConfig(cells_long_side=cells, sigma_cells=1.5 * s, radius_cells=int(round(4 * s)))
    grid = nav_grid_from_points(points, (-4.0, -4.0, 4.0, 4.0), config)  # square: cells x cells
    start, goal = grid.world_to_cell(np.array([-1.5, -2.5])), grid.world_to_cell(np.array([1.5, 2.5]))
    t = time.perf_counter()
    path = astar(grid.cost, start, goal)
    seconds = time.perf_counter() - t
    t = time.perf_counter()
    G = grid_graph(grid.cost)
    build = time.perf_counter() - t
    t = time.perf_counter()
    dijkstra(G, indices=int(start[0] * grid.shape[1] + start[1]))
    baseline = time.perf_counter() - t
    return {"value": seconds, "unit": "s", "baseline": baseline, "ratio": baseline / seconds,
            "graph_build_s": build, "path_cells": len(path)}


FIGURES = {
    "heuristic_evals_per_s_100src_64x48": heuristic_64x48,
    "heuristic_evals_per_s_100src_160x120": heuristic_160x120,
    "astar_s_100x100": lambda: _astar(100),
    "astar_s_1000x1000": lambda: _astar(1000),
}
