"""Leave-one-out evaluation of the localisers (`localization.localize.SceneLocalizer`): the map
(feature points, proxy mesh) is built from the other photos, the held-out photo is the query,
the prior is drawn around its true pose with the given spread, and the errors are measured
against the truth."""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from ibr.progress import progress
from ibr.proxy.triangulation import sift_features
from ibr.scene import Scene
from localization.feature_localizer import pose_errors
from localization.localize import METHODS, LocalizeError, LocConfig, SceneLocalizer
from localization.pose6_filter import cam_from_world_of, sample_around

log = logging.getLogger(__name__)


def draw_prior(truth: np.ndarray, spread_m: float, spread_deg: float, rng: np.random.Generator) -> np.ndarray:
    """A prior pose (4, 4) drawn uniformly within +-spread_m per axis and spread_deg of `truth`."""
    return cam_from_world_of(sample_around(truth, 1, spread_m, np.radians(spread_deg), rng))[0]


def evaluate_localization(scene: Scene, method: str, trials: int, spread_m: float, spread_deg: float,
                          seed: int, config: LocConfig = LocConfig(),
                          on_trial: Callable | None = None) -> dict:
    """Leave-one-out: trial i queries view i mod len(scene) against a map of the others,
    from a prior drawn around its true pose (seed + i). Returns the JSON-ready summary
    (median_position_m, median_rotation_deg, success_rate, seconds_per_query) and per-trial rows.
    on_trial(i, held_view, LocResult, row) is called after each trial (for logging)."""
    if method not in METHODS:
        raise LocalizeError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
    if len(scene) < 3:
        raise LocalizeError(f"scene {scene.name!r} has {len(scene)} views; leave-one-out needs at least 3")
    if trials < 1:
        raise LocalizeError(f"--trials must be at least 1, got {trials}")
    feats = None
    if method != "pf":
        log.info(f"SIFT features of {len(scene)} photos")
        feats = [sift_features(v.image, config.features.triangulation.n_features) for v in scene.views]
    localizers: dict[int, SceneLocalizer] = {}
    rows = []
    for i in progress(range(trials), desc="queries", logger=log):
        k = i % len(scene)
        held = scene.views[k]
        if k not in localizers:
            log.info(f"map without {held.name}")
            for loc in localizers.values():  # one map at a time: a GL model each
                loc.release()
            localizers.clear()
            others = [f for j, f in enumerate(feats) if j != k] if feats else None
            localizers[k] = SceneLocalizer(scene.without(held.name), method, config, others)
        rng = np.random.default_rng(seed + i)
        truth = held.camera.cam_from_world
        prior = draw_prior(truth, spread_m, spread_deg, rng)
        res = localizers[k].localize(held.image, held.camera, prior, spread_m, spread_deg, rng)
        pos, rot = pose_errors(res.cam_from_world, truth) if res.cam_from_world is not None else (np.inf, np.inf)
        rows.append({"trial": i, "view": held.name, "position_m": pos, "rotation_deg": rot,
                     "seconds": res.seconds, "n_inliers": res.n_inliers,
                     "success": bool(pos < config.success_m and rot < config.success_deg),
                     "reason": res.verdict.reason or None})
        log.info(f"[{i + 1}/{trials}] {held.name}: {pos:.4f} m, {rot:.3f} deg, {res.seconds:.2f} s")
        if on_trial:
            on_trial(i, held, res, rows[-1])
    for loc in localizers.values():
        loc.release()
    return {"scene": scene.name, "method": method, "trials": trials, "spread_m": spread_m,
            "spread_deg": spread_deg, "seed": seed, **summarise(rows), "per_trial": rows}


def summarise(rows: list[dict]) -> dict:
    """Medians of the errors (failed PnP counts as infinite), success rate, mean seconds."""
    pos = np.array([r["position_m"] for r in rows])
    rot = np.array([r["rotation_deg"] for r in rows])
    return {"median_position_m": float(np.median(pos)), "median_rotation_deg": float(np.median(rot)),
            "success_rate": float(np.mean([r["success"] for r in rows])),
            "seconds_per_query": float(np.mean([r["seconds"] for r in rows]))}
