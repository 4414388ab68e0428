"""The adaptive stage's round loop (`adaptive_rounds`) with a stand-in mission whose every
round reaches one goal and takes two photos: by default (no round limit) it goes on until
the photo budget is spent, however many rounds that takes; a `max_rounds` still caps it.
A round skips its goals next to one it gave up."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from robot.mission.adaptive import AdaptiveConfig, AdaptiveMission
from robot.mission.localizer import MissionFilterConfig, MissionLocalizer
from robot.mission.mission import MissionResult, adaptive_rounds, say_if_lost
from robot.mission.observer import MissionPhoto


class OneGoalPerRound:
    """A mission in which every round has one reachable goal worth 1 rad, reached, with two
    photos taken there (into the photo list it shares with the result)."""

    def __init__(self, photos: list, config: AdaptiveConfig):
        self.photos, self.config, self.map = photos, config, None
        self.goals_reached, self.given_up_goals, self.given_up, self.give_up_reason = [], [], 0, ""
        self.body = SimpleNamespace(est=SimpleNamespace(pose=np.zeros(3)))
        self.rebuilds = self.grown = 0
        self.n_candidates, self.n_frontier_goals = 1, 0

    def choose_goals(self):
        return np.array([[len(self.photos), 0.0, 0.0]]), 1.0, None

    def go_to(self, goal, grid) -> bool:
        return True

    def capture_at(self, goal, budget: int) -> list:
        new = [MissionPhoto(None, goal, "goal") for _ in range(min(2, budget))]
        self.photos.extend(new)
        return new

    def grow_tracks(self) -> None:
        self.grown += 1

    def rebuild(self, new) -> None:
        self.rebuilds += 1

    def spread(self) -> float:
        return 0.0

    near_given_up = AdaptiveMission.near_given_up


class BlockedGoal(OneGoalPerRound):
    """A mission whose round draws three goals, the first unreachable and the second next
    to it; it records the goals it drove to."""

    def __init__(self, photos: list, config: AdaptiveConfig):
        super().__init__(photos, config)
        self.tried = []

    def choose_goals(self):
        sep = self.config.goal_separation_m
        return np.array([[5.0, 0.0, 0.0], [5.0 + sep / 2, 0.0, 1.0], [5.0 + 3 * sep, 0.0, 0.0]]), 1.0, None

    def go_to(self, goal, grid) -> bool:
        self.tried.append(goal[0])
        return goal[0] != 5.0


@pytest.mark.parametrize("max_rounds, rounds, stopped", [(None, 20, "budget"), (3, 3, "budget")])
def test_rounds_go_on_until_the_budget_unless_capped(max_rounds, rounds, stopped):
    photos = [MissionPhoto(None, np.zeros(3), "random") for _ in range(10)]
    mission = OneGoalPerRound(photos, AdaptiveConfig(max_rounds=max_rounds, step_limit_s=None))
    result = MissionResult(photos, None)
    adaptive_rounds(mission, result, photo_budget=50)  # 40 photos to take, 2 per round
    assert result.rounds == rounds == mission.rebuilds == mission.grown and result.stopped_because == stopped
    assert len(result.model_photos) == (50 if max_rounds is None else 10 + 2 * rounds)


def test_a_round_skips_its_goals_next_to_one_it_gave_up():
    photos = [MissionPhoto(None, np.zeros(3), "random") for _ in range(10)]
    mission = BlockedGoal(photos, AdaptiveConfig(max_rounds=1, step_limit_s=None))
    adaptive_rounds(mission, MissionResult(photos, None), photo_budget=50)
    sep = mission.config.goal_separation_m
    assert mission.tried == [5.0, 5.0 + 3 * sep] and mission.given_up == 1


class TwoFrontiers(OneGoalPerRound):
    """A round of three goals, the last two at frontiers; it records the goals at which it
    swept the ultrasonic round (`sweep_ultrasonic`)."""

    def __init__(self, photos: list, config: AdaptiveConfig):
        super().__init__(photos, config)
        self.swept, self.n_frontier_goals = [], 2

    def choose_goals(self):
        return np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 1.0], [9.0, 0.0, 2.0]]), 1.0, None

    def go_to(self, goal, grid) -> bool:
        self.at = goal[0]
        return True

    def sweep_ultrasonic(self) -> int:
        self.swept.append(self.at)
        return 1


def test_the_ultrasonic_is_swept_at_frontier_goals_only():
    photos = [MissionPhoto(None, np.zeros(3), "random") for _ in range(10)]
    mission = TwoFrontiers(photos, AdaptiveConfig(max_rounds=1, step_limit_s=None))
    adaptive_rounds(mission, MissionResult(photos, None), photo_budget=50)
    assert mission.swept == [5.0, 9.0]
    assert [p.estimate[2] for p in photos[10:]] == [0.0, 0.0, 1.0, 1.0, 2.0, 2.0]  # the photos face the goals' way


def test_the_default_has_no_round_limit():
    assert AdaptiveConfig().max_rounds is None


@pytest.mark.parametrize("spread_m, localised", [(0.03, True), (1.0, False)])
def test_a_mission_says_whether_the_robot_ends_localised(spread_m, localised, caplog):
    """A filter whose particles are 3 cm apart knows where the robot is; one 1 m apart does
    not, and the mission says so (a warning, `localised` False) instead of ending quietly."""
    rng = np.random.default_rng(0)
    loc = MissionLocalizer(np.zeros(3), np.zeros((1, 2)), MissionFilterConfig(), rng)
    particles = np.c_[rng.normal(0, spread_m, (500, 2)), np.zeros(500)]
    loc.set_particles(particles, np.zeros(500))
    result = MissionResult([], None)
    say_if_lost(result, loc)
    assert result.localised is localised and abs(result.final_spread_m / spread_m - 1) < 0.2
    assert ("lost" in caplog.text) is not localised
