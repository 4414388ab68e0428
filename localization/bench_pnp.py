"""Speed figure of the feature localiser (see `ibrnav bench`): seconds per PnP query on
fountain-P11 (SIFT of the query, matching against the map through the prebuilt FLANN
KD-tree, RANSAC PnP + refinement) vs the same query with brute-force descriptor matching
against every map descriptor (no index), in the same run. The map is built from the
other ten photos (leave-one-out) and is not timed."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ibr.bench import best_seconds
from ibr.errors import InputError
from ibr.scene import load_scene
from localization.feature_localizer import FeatureMap

FOUNTAIN = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "strecha" / "fountain-P11"


class BruteForceFeatureMap(FeatureMap):
    """The naive baseline: the same map, matched exhaustively (cv2.BFMatcher, L2)."""

    def __init__(self, points, descriptors, owner, config):
        super().__init__(points, descriptors, owner, config)
        self.matcher = cv2.BFMatcher(cv2.NORM_L2)
        self.matcher.add([np.ascontiguousarray(descriptors, np.float32)])


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


FIGURES = {"pnp_s_per_query": pnp_s_per_query}
