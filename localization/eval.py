"""Leave-one-out evaluation of the localisers (`localization.localize.SceneLocalizer`): the map
(feature points, proxy mesh) is built from the other photos, the held-out photo is the query,
the prior is drawn around its true pose with the given spread, and the errors are measured
against the truth."""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
import shapely

from ibr.progress import progress
from ibr.proxy.proxy_geometry import build_proxy
from ibr.proxy.triangulation import sift_features
from ibr.scene import Scene, View
from localization.confidence import judge
from localization.feature_localizer import pose_errors
from localization.localize import METHODS, LocalizeError, LocConfig, SceneLocalizer
from localization.mapped_share import MappedShare
from localization.pose6_filter import cam_from_world_of, sample_around
from localization.render_localizer import RenderModel

log = logging.getLogger(__name__)


def draw_prior(truth: np.ndarray, spread_m: float, spread_deg: float, rng: np.random.Generator) -> np.ndarray:
    """A prior pose (4, 4) drawn uniformly within +-spread_m per axis and spread_deg of `truth`."""
    return cam_from_world_of(sample_around(truth, 1, spread_m, np.radians(spread_deg), rng))[0]


def median_point_depth(scene: Scene) -> float:
    """The scene's depth (metres): the median camera-z of its triangulated points over the
    photos that see them (points in front of the camera and inside its image)."""
    points = build_proxy(scene).points
    depths = []
    for cam in scene.cameras:
        uv, z = cam.project(points)
        inside = (z > 0) & np.all((uv >= 0) & (uv < [cam.width, cam.height]), axis=1)
        depths.append(z[inside])
    d = np.concatenate(depths)
    if not len(d):
        raise LocalizeError(f"scene {scene.name!r}: no triangulated point is seen by its photos")
    return float(np.median(d))


def prior_spread_m(spread: str, scene: Scene) -> float:
    """--spread-m as metres: "0.5" is metres, "10%" a fraction of `median_point_depth`."""
    text = str(spread).strip()
    share = text.endswith("%")
    try:
        value = float(text[:-1] if share else text)
    except ValueError:
        value = float("nan")
    if np.isfinite(value) and value > 0 and share:
        return value / 100.0 * median_point_depth(scene)
    if not np.isfinite(value) or value <= 0:
        raise LocalizeError(f"--spread-m {spread!r}: expected metres (e.g. 1.0) or a share of the scene depth (e.g. 10%)")
    return value


def novel_queries(scene: Scene, n: int, rng: np.random.Generator, depth_m: float, offset: float = 0.1,
                  turn_deg: float = 10.0) -> list[View]:
    """n photos of a synthetic scene's world from new poses near its map photos: a map photo's
    camera moved by up to `offset` x the scene's depth `depth_m` (metres, `median_point_depth`)
    per horizontal axis (and a tenth of that vertically) and turned by up to `turn_deg`, its
    centre kept in the world's free space.
    They are not in the map, as a robot's photo when it comes back is not."""
    free = scene.world.free_space
    views = []
    while len(views) < n:
        cam = scene.cameras[int(rng.integers(len(scene)))]
        shift = rng.uniform(-offset, offset, 3) * depth_m * np.array([1.0, 1.0, 0.1])
        T = cam_from_world_of(sample_around(cam.cam_from_world, 1, 0.0, np.radians(turn_deg), rng))[0]
        centre = cam.center + shift
        if not free.contains(shapely.Point(centre[:2])):
            continue
        T[:3, 3] = -T[:3, :3] @ centre
        query = cam.with_pose(T, f"query_{len(views):03d}")
        views.append(View(query, scene.world.photograph(query)))
    return views


def evaluate_localization(scene: Scene, method: str, trials: int, spread_m: float, spread_deg: float,
                          seed: int, config: LocConfig = LocConfig(),
                          on_trial: Callable | None = None, queries: str = "held-out") -> dict:
    """Trial i localises a query photo against a map, from a prior drawn around its true pose
    (seed + i). queries "held-out": the query is view i mod len(scene), the map the other
    views (leave-one-out); "novel" (synthetic scenes): the map is every view and the queries
    are new photos of the world near them (`novel_queries`), one map for all trials.
    Returns the JSON-ready summary (`summarise`) and per-trial rows (errors null when no
    pose was returned, the verdict and its reason). on_trial(i, query_view, LocResult, row)
    is called after each trial."""
    if method not in METHODS:
        raise LocalizeError(f"unknown method {method!r}; choose from {', '.join(METHODS)}")
    if trials < 1:
        raise LocalizeError(f"--trials must be at least 1, got {trials}")
    runs = {"held-out": evaluate_held_out, "novel": evaluate_novel}
    if queries not in runs:
        raise LocalizeError(f"unknown queries {queries!r}; choose from {', '.join(runs)}")
    rows = runs[queries](scene, method, trials, spread_m, spread_deg, seed, config, on_trial)
    return {"scene": scene.name, "method": method, "queries": queries, "trials": trials, "spread_m": spread_m,
            "spread_deg": spread_deg, "seed": seed, **summarise(rows), "per_trial": rows}


def evaluate_held_out(scene: Scene, method: str, trials: int, spread_m: float, spread_deg: float,
                      seed: int, config: LocConfig, on_trial: Callable | None) -> list[dict]:
    """The rows of `evaluate_localization` with queries "held-out" (leave-one-out)."""
    if len(scene) < 3:
        raise LocalizeError(f"scene {scene.name!r} has {len(scene)} views; leave-one-out needs at least 3")
    feats = None
    if method != "pf":
        log.info(f"SIFT features of {len(scene)} photos")
        tri = config.features.triangulation
        feats = [sift_features(v.image, tri.n_features, tri.contrast_threshold) for v in scene.views]
    localizers: dict[int, SceneLocalizer] = {}
    rows, share = [], None
    for i in progress(range(trials), desc="queries", logger=log):
        k = i % len(scene)
        held = scene.views[k]
        if k not in localizers:
            log.info(f"map without {held.name}")
            for loc in localizers.values():  # one map at a time: a GL model each
                loc.release()
            localizers.clear()
            others = [f for j, f in enumerate(feats) if j != k] if feats else None
            rest = scene.without(held.name)
            localizers[k] = SceneLocalizer(rest, method, config, others)
            release(share)
            share = mapped_share(rest)
        rows.append(query_trial(localizers[k], i, trials, held, spread_m, spread_deg, seed, config, on_trial, share))
    for loc in localizers.values():
        loc.release()
    release(share)
    return rows


def evaluate_novel(scene: Scene, method: str, trials: int, spread_m: float, spread_deg: float,
                   seed: int, config: LocConfig, on_trial: Callable | None) -> list[dict]:
    """The rows of `evaluate_localization` with queries "novel": one map of every view, new photos."""
    if scene.world is None:
        raise LocalizeError(f"scene {scene.name!r}: novel queries need a synthetic world to photograph")
    queries = novel_queries(scene, trials, np.random.default_rng(seed), median_point_depth(scene))
    loc = SceneLocalizer(scene, method, config)
    share = mapped_share(scene)
    rows = [query_trial(loc, i, trials, queries[i], spread_m, spread_deg, seed, config, on_trial, share)
            for i in progress(range(trials), desc="queries", logger=log)]
    release(share)
    loc.release()
    return rows


def mapped_share(map_scene: Scene) -> MappedShare | None:
    """What measures the mapped share of query cameras against the photos of `map_scene`
    (`localization.mapped_share`) when it is a synthetic world's (its true mesh known), else
    None; `release` it when done."""
    return MappedShare(map_scene.world.mesh, map_scene.cameras) if map_scene.world is not None else None


def release(share: MappedShare | None) -> None:
    if share is not None:
        share.release()


def query_trial(loc: SceneLocalizer, i: int, trials: int, query: View, spread_m: float, spread_deg: float,
                seed: int, config: LocConfig, on_trial: Callable | None,
                share: MappedShare | None = None) -> dict:
    """Trial i: `query` localised from a prior drawn around its true pose (seed + i); its row
    (`trial_row`, with the query's `mapped_share` when `share` measures it), logged and
    passed to on_trial(i, query, LocResult, row)."""
    rng = np.random.default_rng(seed + i)
    truth = query.camera.cam_from_world
    prior = draw_prior(truth, spread_m, spread_deg, rng)
    res = loc.localize(query.image, query.camera, prior, spread_m, spread_deg, rng)
    row = trial_row(i, query.name, res, truth, config)
    if loc.model is not None:
        row["from_truth"] = aligned_from_truth(loc.model, query, config)
    mapped = ""
    if share is not None:
        row["mapped_share"] = share(query.camera)
        mapped = f", mapped share {row['mapped_share']:.2f}"
    log.info(f"[{i + 1}/{trials}] {query.name}: {row['position_m']} m, {row['rotation_deg']} deg, "
             f"{'localised' if row['localized'] else 'not localised: ' + row['reason']}, "
             f"confidence {row['confidence']:.2f}, {res.seconds:.2f} s{mapped}")
    if on_trial:
        on_trial(i, query, res, row)
    return row


def aligned_from_truth(model: RenderModel, query: View, config: LocConfig) -> dict:
    """Where the rendered likelihood's optimum lies near the truth and whether the model could
    localise the photo at all: the fine alignment started at the true pose, its errors and
    its verdict (rivals ignored). A failed query whose alignment from the truth is localised
    failed the search; one whose alignment from the truth is not, failed for the model."""
    cam = query.camera
    a = model.align(model.fine, query.image, cam, cam.cam_from_world, model.fine_widths(cam))
    pos, rot = pose_errors(a.cam_from_world, cam.cam_from_world)
    v = judge(a, model.reference, None, model.config.confidence)
    return {"position_m": float(pos), "rotation_deg": float(rot), "explained": a.explained,
            "trusted": a.trusted, "localized": v.localized,
            "success": bool(pos < config.success_m and rot < config.success_deg)}


def trial_row(i: int, name: str, res, truth: np.ndarray, config: LocConfig) -> dict:
    """One trial's JSON row: errors (null without a pose), success, verdict, timing."""
    pos = rot = None
    if res.cam_from_world is not None:
        pos, rot = (float(x) for x in pose_errors(res.cam_from_world, truth))
    success = pos is not None and pos < config.success_m and rot < config.success_deg
    return {"trial": i, "view": name, "position_m": pos, "rotation_deg": rot, "success": bool(success),
            **res.verdict.as_dict(), "source": res.source, "n_inliers": res.n_inliers, "seconds": res.seconds}


def summarise(rows: list[dict]) -> dict:
    """Medians of the errors (null when over half the queries returned no pose), success
    rate, flagged rate (queries flagged localised), flag precision (successes among the
    flagged; null when none is flagged), mean seconds, success rate per confidence bin, and
    the failures by cause (rendered methods: "search" when the alignment from the truth is
    localised, so the model could have, "model" when it is not; null without failures), and
    the rates per bin of the queries' mapped share (`by_mapped_share`; null where no row has
    one: a scene without a true mesh)."""
    pos = np.array([np.inf if r["position_m"] is None else r["position_m"] for r in rows])
    rot = np.array([np.inf if r["rotation_deg"] is None else r["rotation_deg"] for r in rows])

    def median(x):
        m = float(np.median(x))
        return m if np.isfinite(m) else None
    bins = []
    for lo, hi in ((0.0, 0.5), (0.5, 0.9), (0.9, 1.01)):
        inside = [r for r in rows if lo <= r["confidence"] < hi]
        bins.append({"confidence": [lo, min(hi, 1.0)], "queries": len(inside),
                     "success_rate": float(np.mean([r["success"] for r in inside])) if inside else None})
    failed = [r for r in rows if not r["success"] and "from_truth" in r]
    mapped = [r for r in rows if "mapped_share" in r]
    causes = {"search": sum(r["from_truth"]["localized"] for r in failed),
              "model": sum(not r["from_truth"]["localized"] for r in failed)}
    return {"median_position_m": median(pos), "median_rotation_deg": median(rot),
            "failures_by_cause": causes if failed else None,
            **rates(rows), "seconds_per_query": float(np.mean([r["seconds"] for r in rows])), "calibration": bins,
            "by_mapped_share": by_mapped_share(mapped) if mapped else None}


def by_mapped_share(rows: list[dict]) -> list[dict]:
    """Queries, success rate, flagged rate and flag precision per bin of the mapped share
    (`localization.mapped_share`: how much of the query's view two map photos see at a
    matchable angle): what the localiser reaches where its map could model the view,
    apart from where the capture could not."""
    out = []
    for lo, hi in ((0.0, 0.25), (0.25, 0.5), (0.5, 1.01)):
        inside = [r for r in rows if lo <= r["mapped_share"] < hi]
        out.append({"mapped_share": [lo, min(hi, 1.0)], "queries": len(inside), **rates(inside)})
    return out


def rates(rows: list[dict]) -> dict:
    """Success rate, flagged rate (queries flagged localised) and flag precision (successes
    among the flagged) of `rows`; null where there is no row, or no flagged row."""
    flagged = [r for r in rows if r["localized"]]
    return {"success_rate": float(np.mean([r["success"] for r in rows])) if rows else None,
            "flagged_rate": len(flagged) / len(rows) if rows else None,
            "flag_precision": float(np.mean([r["success"] for r in flagged])) if flagged else None}
