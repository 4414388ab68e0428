"""Speed figures of the basic renderer (see `ibrnav bench`)."""

from __future__ import annotations

import time

import numpy as np

from ibr.synthetic import make_world

N_VIEWS = 256


def best_seconds(fn, repeats: int = 3, warm_up: bool = True) -> float:
    """Least wall time (s) of `repeats` calls of fn(), after one untimed warm-up call
    (shader compilation, first uploads) unless warm_up is False. Every bench module times
    with this, so figures and baselines are measured alike."""
    if warm_up:
        fn()
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def _rate(fn, n_items: int, repeats: int = 3) -> float:
    """Best items/s of `repeats` timed calls of fn() (after one warm-up call)."""
    return n_items / best_seconds(fn, repeats)


def mesh_views_per_s_64x48() -> dict:
    """Views/s of the office mesh at 64x48 (colour + depth read back): one instanced draw
    of 256 views into an atlas vs the naive loop of one render + read-back per view."""
    world = make_world("office", 0)
    renderer = world.renderer()
    cams = [c.scaled(0.1) for c in world.default_cameras(N_VIEWS)]
    batched = _rate(lambda: renderer.render_batch(cams), N_VIEWS)
    loop = _rate(lambda: [renderer.render(c) for c in cams], N_VIEWS, repeats=1)
    return {"value": batched, "unit": "views/s", "baseline": loop, "ratio": batched / loop}


FIGURES = {"mesh_views_per_s_64x48": mesh_views_per_s_64x48}
