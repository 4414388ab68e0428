"""The localisation evaluation's parts with known answers: novel query photos of a synthetic
world are new poses in its free space whose photos are the world's renders there; the prior
spread parses metres and shares of the scene depth; the summary counts flags and precision."""

import numpy as np
import pytest
import shapely

from ibr.scene import load_scene
from localization.confidence import Verdict
from localization.eval import novel_queries, prior_spread_m, summarise
from localization.localize import LocalizeError


def test_novel_queries_are_new_poses_in_free_space_photographed_by_the_world(gl_ctx):
    scene = load_scene("synthetic:office?views=6&width=160&height=120")
    queries = novel_queries(scene, 5, np.random.default_rng(0), depth_m=3.0)
    assert len(queries) == 5
    for q in queries:
        assert scene.world.free_space.contains(shapely.Point(q.camera.center[:2]))
        nearest = min(np.linalg.norm(q.camera.center - c.center) for c in scene.cameras)
        assert 0 < nearest <= 0.1 * 3.0 * np.sqrt(2 + 0.01) + 1e-9
        np.testing.assert_array_equal(q.image, scene.world.photograph(q.camera))


def test_prior_spread_is_metres_or_a_share_of_the_depth(monkeypatch):
    import localization.eval as ev
    monkeypatch.setattr(ev, "median_point_depth", lambda scene: 20.0)
    assert prior_spread_m("0.5", None) == 0.5
    assert prior_spread_m("10%", None) == pytest.approx(2.0)
    for bad in ("-1", "abc", "nan%"):
        with pytest.raises(LocalizeError, match="--spread-m"):
            prior_spread_m(bad, None)


def test_summary_counts_flags_and_their_precision():
    def row(pos, localized, confidence):
        v = Verdict(localized, confidence, "" if localized else "why")
        return {"position_m": pos, "rotation_deg": None if pos is None else 0.1, "success": pos is not None and pos < 0.05,
                "seconds": 1.0, **v.as_dict()}
    rows = [row(0.01, True, 1.0), row(0.02, True, 0.95), row(0.5, True, 0.6), row(None, False, 0.0)]
    s = summarise(rows)
    assert s["success_rate"] == 0.5 and s["flagged_rate"] == 0.75
    assert s["flag_precision"] == pytest.approx(2 / 3)
    assert s["median_position_m"] == pytest.approx(0.26)  # the missing pose counts as infinitely far
    assert [b["queries"] for b in s["calibration"]] == [1, 1, 2]


def test_failures_are_split_into_search_and_model_by_the_alignment_from_the_truth():
    def row(success, truth_localized):
        return {"position_m": 0.01 if success else 1.0, "rotation_deg": 0.1, "success": success, "seconds": 1.0,
                **Verdict(success, float(success), "").as_dict(),
                "from_truth": {"localized": truth_localized}}
    s = summarise([row(True, True), row(False, True), row(False, False), row(False, False)])
    assert s["failures_by_cause"] == {"search": 1, "model": 2}
    assert summarise([row(True, True)])["failures_by_cause"] is None


@pytest.mark.slow
def test_rendered_localiser_rows_say_what_the_model_reaches_from_the_truth(gl_ctx):
    """Novel queries of a small office against its photo-textured proxy: each row carries the
    alignment from the true pose and the query's mapped share; a localised success is near
    the truth, and its alignment from the truth is localised too."""
    from localization.eval import evaluate_localization
    from localization.localize import LocConfig
    scene = load_scene("synthetic:office?views=12&width=320&height=240")
    out = evaluate_localization(scene, "pf", 2, 0.2, 20.0, 0, LocConfig(), queries="novel")
    for r in out["per_trial"]:
        t = r["from_truth"]
        assert t["position_m"] < 0.05 and 0.0 <= t["trusted"] <= 1.0
        assert 0.0 <= r["mapped_share"] <= 1.0
        if r["success"] and r["localized"]:
            assert t["localized"]
    assert out["flag_precision"] in (None, 1.0)
    assert sum(b["queries"] for b in out["by_mapped_share"]) == 2


def test_summary_splits_the_queries_by_how_much_of_their_view_the_map_could_model():
    def row(success, localized, share):
        return {"position_m": 0.01 if success else 1.0, "rotation_deg": 0.1, "success": success, "seconds": 1.0,
                **Verdict(localized, float(localized), "").as_dict(), "mapped_share": share}
    s = summarise([row(False, False, 0.1), row(True, False, 0.3), row(True, True, 0.9), row(False, True, 0.6)])
    low, mid, high = s["by_mapped_share"]
    assert (low["queries"], low["success_rate"], low["flagged_rate"], low["flag_precision"]) == (1, 0.0, 0.0, None)
    assert (mid["queries"], mid["success_rate"]) == (1, 1.0)
    assert (high["queries"], high["success_rate"], high["flagged_rate"], high["flag_precision"]) == (2, 0.5, 1.0, 0.5)
    assert summarise([{k: v for k, v in row(True, True, 0.9).items() if k != "mapped_share"}])["by_mapped_share"] is None
