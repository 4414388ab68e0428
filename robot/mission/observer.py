"""What the capture mission reports as it goes: each `MissionPhoto`, pose estimates, the
particles, the map, the candidate views and goals, the navigation grid and the path. The
mission calls a `MissionObserver`; `robot.mission.recorder` is the one that writes a session
folder and rerun. Frames: world SE(2) poses (x, y, theta), metres, radians."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ibr.camera import Camera
from robot.protocol import Photo

if TYPE_CHECKING:
    from robot.mission.map_building import RobotMap


@dataclass
class MissionPhoto:
    """A photo of the mission: `photo`; `estimate` (3,) the robot's pose estimate when it was
    taken; `stage` "random", "goal" or "localise" (taken to localise, not part of the model);
    `camera` its posed camera once SfM or PnP posed it (None: unposed); `dead_reckoning` (3,)
    the compass-aided dead-reckoning pose then (the baseline the filter is compared with);
    `fixed` whether a PnP fix of the photo passed the checks and was the filter's measurement
    (None: not known, as for the random stage's photos)."""

    photo: Photo
    estimate: np.ndarray
    stage: str
    camera: Camera | None = None
    dead_reckoning: np.ndarray | None = None
    fixed: bool | None = None


class MissionObserver:
    """What the mission reports; every method does nothing here (subclass to log)."""

    def photo(self, mp: MissionPhoto) -> None: ...
    def estimate(self, pose: np.ndarray, source: str) -> None: ...
    def particles(self, particles: np.ndarray, weights: np.ndarray) -> None: ...
    def map(self, robot_map: RobotMap, free_space) -> None: ...
    def candidates(self, poses: np.ndarray, scores: np.ndarray, goals: np.ndarray) -> None: ...
    def grid(self, grid) -> None: ...
    def sonar(self, grid) -> None: ...
    def path(self, xy: np.ndarray) -> None: ...
