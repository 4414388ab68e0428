"""Feature localiser (SIFT map triangulated with known poses + RANSAC PnP) on real photos
with laser-measured cameras."""

import numpy as np
import pytest

from ibr.scene import load_scene
from localization.feature_localizer import FeatureMap, pose_errors


@pytest.fixture(scope="module")
def fountain(strecha_dir):
    return load_scene(strecha_dir / "fountain-P11")


@pytest.mark.realdata
def test_pnp_localises_a_held_out_strecha_photo_within_1cm_and_0_2deg(fountain):
    scene = fountain
    held = scene.view("0005.jpg")
    # a map of the held-out photo's four neighbours (not itself): fast, and still leave-one-out
    others = [n for n in scene.views if n.name in ("0003.jpg", "0004.jpg", "0006.jpg", "0007.jpg")]
    fmap = FeatureMap.from_scene(scene, exclude=[v.name for v in scene.views if v not in others])
    assert len(fmap) > 1000
    res = fmap.localize(held.image, held.camera.with_pose(np.eye(4)))
    assert res is not None and res.n_inliers > 100
    pos, rot = pose_errors(res.cam_from_world, held.camera.cam_from_world)
    assert pos < 0.01 and rot < 0.2, (pos, rot)
    np.testing.assert_allclose(res.camera.cam_from_world, res.cam_from_world)


@pytest.mark.realdata
def test_pnp_gives_no_pose_for_a_photo_of_something_else(fountain):
    scene = fountain
    fmap = FeatureMap.from_scene(scene, exclude=[v.name for v in scene.views][:-3])
    noise = np.random.default_rng(0).integers(0, 256, scene.views[0].image.shape, dtype=np.uint8)
    assert fmap.localize(noise, scene.views[0].camera) is None


def test_a_map_matches_the_same_whatever_ran_before_it(monkeypatch):
    """FLANN's randomised KD-trees draw their splits from OpenCV's process-wide RNG; the map
    seeds it, so the same map built after other work in the process (here OpenCV random draws)
    returns the same approximate neighbours (unseeded, a mission's PnP fixes depended on
    which maps had been built before, and a test on the tests run before it)."""
    import cv2

    rng = np.random.default_rng(0)
    descriptors = rng.random((4000, 128), np.float32)
    points = rng.random((4000, 3))
    queries = rng.random((300, 128), np.float32)

    def neighbours() -> list[int]:
        fmap = FeatureMap(points, descriptors, np.arange(4000))
        return [m.trainIdx for m in fmap.matcher.match(queries)]

    first = neighbours()
    cv2.randu(np.zeros((1000, 1), np.float32), 0.0, 1.0)  # other users of the RNG in between
    assert neighbours() == first
