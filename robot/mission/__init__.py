"""robot.mission: the autonomous scene-capture mission of Foster, Wang & Grupen: the random
stage, the map from its photos (SfM, Poisson), adaptive rounds driven by the rendering-quality
heuristic, the mission's SE(2) localiser, its journal in a capture session (resume after a
kill), the recorder, surface-coverage evaluation and the virtual tour."""

from robot.mission.adaptive import AdaptiveConfig, AdaptiveMission
from robot.mission.coverage import CoverageConfig, CoverageTracker
from robot.mission.journal import MissionJournal, SessionJournal
from robot.mission.localizer import FilteredBody, MissionFilterConfig, MissionLocalizer
from robot.mission.map_building import MapConfig, RobotMap, extend_map, initial_map
from robot.mission.mission import MissionResult, run_mission, run_random_only, run_random_stage
from robot.mission.observer import MissionObserver, MissionPhoto
from robot.mission.random_stage import Body, RandomExplorationConfig, random_exploration
from robot.mission.virtual_tour import render_tour, tour_poses, tour_route

__all__ = ["AdaptiveConfig", "AdaptiveMission", "Body", "CoverageConfig", "CoverageTracker", "FilteredBody",
           "MapConfig", "MissionFilterConfig", "MissionJournal", "MissionLocalizer", "MissionObserver",
           "MissionPhoto", "MissionResult", "RandomExplorationConfig", "RobotMap", "SessionJournal", "extend_map",
           "initial_map", "random_exploration", "render_tour", "run_mission", "run_random_only", "run_random_stage",
           "tour_poses", "tour_route"]
