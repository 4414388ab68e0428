"""Speed figures of the basic renderer (see `ibrnav bench`)."""

from __future__ import annotations

import time

from ibr.synthetic import make_world

N_VIEWS = 256


def _rate(fn, n_items: int, repeats: int = 3) -> float:
    """Best items/s of `repeats` timed calls of fn() (after one warm-up call)."""
    fn()
    best = min(_timed(fn) for _ in range(repeats))
    return n_items / best


def _timed(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


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
