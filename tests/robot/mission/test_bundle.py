"""Bundle adjustment of the grown photos (`robot.mission.bundle`) on the synthetic office's
true poses: photos moved a few centimetres off (as PnP fixes are) come back toward the
truth; photos with no held neighbour, or no held photo at all, stay where they are."""

import numpy as np
import pytest

from ibr.proxy.triangulation import sift_features
from ibr.synthetic import make_world
from robot.mission.adaptive import AdaptiveConfig
from robot.mission.bundle import BundleConfig, PairMatches, adjust_grown, view_tracks
from robot.mission.random_stage import Body, RandomExplorationConfig, random_exploration
from robot.protocol import robot_camera
from robot.sim_robot import SimRobot, SimRobotConfig

START = np.array([-1.5, -2.5, 0.0])
TRI = AdaptiveConfig().localizer.triangulation


@pytest.fixture(scope="module")
def office_photos():
    """60 photos of the office's random stage (three circles of 20) at their true cameras,
    and their SIFT features."""
    robot = SimRobot(make_world("office", 0), SimRobotConfig(image_size=(320, 240)), np.random.default_rng(0),
                     start_pose=tuple(START))
    cams, feats = {}, {}
    shots = random_exploration(robot, START, RandomExplorationConfig(n_photos=60, circle_step_rad=np.radians(18)),
                               np.random.default_rng(1), Body(robot, START))
    for k, shot in enumerate(shots):
        cams[k] = robot_camera(robot.truth[-1]["pose"], robot.intrinsics, robot.image_size, robot.cam_from_robot)
        feats[k] = sift_features(shot.photo.image, TRI.n_features, TRI.contrast_threshold)
    return cams, feats


def moved(cam, rng, off_m):
    """The camera moved `off_m` (m) sideways in a random direction and turned 0.3 degrees."""
    T = cam.world_from_cam.copy()
    d = rng.normal(size=2)
    T[:2, 3] += off_m * d / np.linalg.norm(d)
    a = np.radians(0.3)
    Rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    T[:3, :3] = Rz @ T[:3, :3]
    return cam.with_pose(np.linalg.inv(T))


def test_view_tracks_join_pairs_into_tracks_seen_by_distinct_photos(office_photos):
    cams, feats = office_photos
    t = view_tracks(cams, feats.__getitem__, PairMatches(feats.__getitem__, TRI.ratio), TRI)
    assert len(t.points) > 500
    assert len(np.unique(np.c_[t.point, t.photo], axis=0)) == len(t.point)  # no photo twice in a track
    assert np.bincount(t.point).min() >= 2 and np.bincount(t.point).max() > 2  # pairs joined across photos
    errs = [np.linalg.norm(cams[p].project(t.points[k:k + 1])[0][0] - feats[p].uv[f])
            for k, p, f in zip(t.point[:300], t.photo[:300], t.feature[:300])]
    assert np.median(errs) < 1.0  # each observation is its track's point on the true poses


def test_photos_a_few_centimetres_off_come_back_toward_the_truth(office_photos):
    cams, feats = office_photos
    rng = np.random.default_rng(3)
    held = set(range(40))  # two circles held, the third's photos each moved 4 cm
    off = {i: (moved(c, rng, 0.04) if i not in held else c) for i, c in cams.items()}
    prior = {i: c.center for i, c in off.items()}
    res = adjust_grown(off, held, prior, feats.__getitem__, PairMatches(feats.__getitem__, TRI.ratio), TRI)
    assert not isinstance(res, str), res
    assert res.held >= len(held) and len(res.cameras) >= 15
    before = np.array([np.linalg.norm(off[i].center - cams[i].center) for i in res.cameras])
    after = np.array([np.linalg.norm(c.center - cams[i].center) for i, c in res.cameras.items()])
    assert np.median(after) < 0.25 * np.median(before) and np.mean(after < before) >= 0.8
    assert res.error_px[1] < res.error_px[0]


def test_nothing_is_adjusted_without_a_held_photo_or_a_neighbour_of_one(office_photos):
    cams, feats = office_photos
    matches = PairMatches(feats.__getitem__, TRI.ratio)
    prior = {i: c.center for i, c in cams.items()}
    assert "nothing to adjust" in adjust_grown(cams, set(), prior, feats.__getitem__, matches, TRI)
    one_circle = {i: c for i, c in cams.items() if i < 20}  # one stop: no pair has a baseline
    assert "share no tracks" in adjust_grown(one_circle, {0}, prior, feats.__getitem__, matches, TRI)
    strict = BundleConfig(min_shared_points=10**6)  # no two photos joined: no free photo has a held neighbour
    res = adjust_grown(cams, set(range(20)), prior, feats.__getitem__, matches, TRI, strict)
    assert "weakly placed" in res
