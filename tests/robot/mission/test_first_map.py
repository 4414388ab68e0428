"""The mission's first map (`robot.mission.mission._first_map`): while SfM cannot map the
random stage, or the floor cannot check the map's scale (a map of one stop), the random
stage goes on for another circle from where the robot stands, and the map is built again."""

import numpy as np
import pytest

import robot.mission.mission as mission
from robot.mission.adaptive import AdaptiveConfig
from robot.mission.journal import MissionJournal
from robot.mission.map_building import MapError
from robot.mission.observer import MissionObserver
from robot.mission.random_stage import RandomExplorationConfig
from robot.sim_robot import SimRobot, SimRobotConfig

START = np.array([-1.5, -2.5, 0.0])
STEP = RandomExplorationConfig(circle_step_rad=np.radians(30))  # 12 photos a circle


class Map:
    """What `_first_map` reads of a map: whether the floor checked its scale."""

    def __init__(self, floor_scaled):
        self.floor_scaled = floor_scaled


def _stage(office, budget: int) -> mission.RandomStage:
    robot = SimRobot(office, SimRobotConfig(image_size=(32, 24)), np.random.default_rng(4), start_pose=START)
    return mission.RandomStage(robot, START, STEP, np.random.default_rng(9), MissionObserver(), MissionJournal(),
                               budget)


def _maps(monkeypatch, outcomes: list) -> list[int]:
    """`initial_map` gives `outcomes` in turn (a floor_scaled value or an exception); returns
    the photo counts it was called with."""
    calls = []

    def fake(images, *args, **kwargs):
        calls.append(len(images))
        out = outcomes[min(len(calls), len(outcomes)) - 1]
        if isinstance(out, Exception):
            raise out
        return Map(out)

    monkeypatch.setattr(mission, "initial_map", fake)
    return calls


def test_a_map_whose_scale_the_floor_checked_is_kept(monkeypatch, office):
    calls = _maps(monkeypatch, [True])
    stage = _stage(office, 100)
    assert mission._first_map(stage, stage.body.robot, 24, AdaptiveConfig()).floor_scaled
    assert calls == [24]


def test_a_map_of_one_stop_gets_more_circles_from_new_stops(monkeypatch, office):
    calls = _maps(monkeypatch, [False, False, False])
    stage = _stage(office, 100)
    rmap = mission._first_map(stage, stage.body.robot, 24, AdaptiveConfig(extra_random_circles=2))
    assert rmap.floor_scaled is False and calls == [24, 36, 48]  # two more circles, then it goes on
    xy = np.array([t["pose"][:2] for t in stage.body.robot.truth])
    stops = [xy[k * 12] for k in range(4)]
    assert all(np.allclose(xy[k * 12:(k + 1) * 12], stops[k]) for k in range(4))  # each circle turns in place
    assert min(np.hypot(*(a - b)) for i, a in enumerate(stops) for b in stops[:i]) > 0.1  # at a new stop


def test_sfm_failing_gets_another_circle_and_fails_clearly_when_out_of_circles(monkeypatch, office):
    calls = _maps(monkeypatch, [MapError("SfM registered only 3 of 24 photos"), True])
    stage = _stage(office, 100)
    assert mission._first_map(stage, stage.body.robot, 24, AdaptiveConfig()).floor_scaled and calls == [24, 36]
    calls = _maps(monkeypatch, [MapError("SfM registered only 3 photos")])
    stage = _stage(office, 100)
    with pytest.raises(MapError, match="only 3 photos"):
        mission._first_map(stage, stage.body.robot, 24, AdaptiveConfig(extra_random_circles=1))
    assert calls == [24, 36]


def test_no_circle_beyond_the_photo_budget(monkeypatch, office):
    calls = _maps(monkeypatch, [False])
    stage = _stage(office, 24)
    assert mission._first_map(stage, stage.body.robot, 24, AdaptiveConfig()).floor_scaled is False
    assert calls == [24] and len(stage.photos) == 24


def test_a_resumed_stage_first_takes_the_whole_circles_its_journal_began(monkeypatch, office):
    """A real robot stopped 6 photos into its first extra circle (30 logged, 24 planned):
    the resumed stage ends that circle (36) before mapping, as the uninterrupted run did."""
    calls = _maps(monkeypatch, [True])
    robot = SimRobot(office, SimRobotConfig(image_size=(32, 24)), np.random.default_rng(4), start_pose=START)
    logged = [mission.MissionPhoto(robot.capture(), START.copy(), "random") for _ in range(30)]

    class Journal(MissionJournal):
        replayable = False

        def resumed_photos(self, stage_of):
            return list(logged)

    stage = mission.RandomStage(robot, START, STEP, np.random.default_rng(9), MissionObserver(), Journal(), 100)
    mission._first_map(stage, robot, 24, AdaptiveConfig())
    assert calls == [36] and stage.photos[:30] == logged


def test_a_map_without_a_photo_of_the_start_circle_says_its_place_is_odometry(office, caplog):
    """The robot knows its start; a map whose start circle SfM did not pose stands there
    only by the odometry of the drives (apartments 2 and 9: the whole map 16-27 cm off)."""
    stage = _stage(office, 100)
    stage.take(36)  # three circles of 12
    assert mission.start_anchored({3: None, 20: None}, stage.photos)
    assert not mission.start_anchored({20: None, 30: None}, stage.photos)

    class Posed:
        cameras = {20: None, 30: None}

    assert not mission._warn_unanchored(Posed(), stage.photos, mission.MapConfig())
    assert "SfM posed no photo of the start circle" in caplog.text and "odometry" in caplog.text
