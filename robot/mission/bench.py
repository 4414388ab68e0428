"""`ibrnav bench` figures of the capture mission's maps (`robot.mission`).

first_map_again_s: seconds to build the mission's first map (`map_building.initial_map`:
    SfM, its models placed in metres, the floor's scale) twice, as `mission._first_map`
    does when the floor cannot check the scale of the first: from two circles of random
    photos, then again from three (synthetic:apartment seed 0, the random stage as the
    mission takes it, 36 photos a circle, 320 x 240). Value: both builds in one SfM
    workspace, so the second extracts and matches only the new circle's photos. Baseline:
    each build in a fresh workspace (the code before); ratio = baseline / value. `same_map`
    says whether the second builds posed the same photos at the same poses (they should:
    the test `test_a_first_map_built_again_in_its_workspace_is_the_same_map`). Measured
    2026-12-02 on 2 shared cores: 48.9 s against 66.5 s (ratio 1.36), the same map; the
    saving grows with the photos already matched (apartment 4's builds at 108, 144 and 180
    photos: 87 s against 138 s).
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from ibr.synthetic import make_world
from robot.mission.map_building import MapConfig, initial_map
from robot.mission.random_stage import Body, RandomExplorationConfig, random_exploration, steps_per_circle
from robot.sim_robot import SimRobot, SimRobotConfig

CIRCLES = (2, 3)


def _random_stage(n_photos: int):
    """(robot, photos) of the random stage on apartment 0 from its seeded start."""
    world = make_world("apartment", 0)
    rng = np.random.default_rng(0)
    start = world.start_pose(rng)
    robot = SimRobot(world, SimRobotConfig(), np.random.default_rng(1), start_pose=tuple(start))
    shots = list(random_exploration(robot, start, RandomExplorationConfig(n_photos=n_photos), rng,
                                    Body(robot, start)))
    return robot, shots


def _builds(robot, shots, counts: list[int], work: Path | None):
    """(seconds, maps) of `initial_map` of the first `counts` photos in turn, in `work`."""
    t, maps = time.perf_counter(), []
    for n in counts:
        s = shots[:n]
        maps.append(initial_map([p.photo.image for p in s], robot.intrinsics, np.array([p.estimate for p in s]),
                                np.array([p.photo.compass_rad for p in s]), robot.cam_from_robot, MapConfig(),
                                np.array([p.photo.range_m for p in s]), work=work))
    return time.perf_counter() - t, maps


def first_map_again_s() -> dict:
    counts = [k * steps_per_circle(RandomExplorationConfig()) for k in CIRCLES]
    robot, shots = _random_stage(counts[-1])
    fresh_s, fresh = _builds(robot, shots, counts, None)
    work = Path(tempfile.mkdtemp(prefix="ibrnav_bench_"))
    try:
        kept_s, kept = _builds(robot, shots, counts, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    a, b = fresh[-1].cameras, kept[-1].cameras
    same = set(a) == set(b) and all(np.array_equal(a[i].cam_from_world, b[i].cam_from_world) for i in a)
    return {"value": kept_s, "unit": "s", "baseline": fresh_s, "ratio": fresh_s / kept_s, "photos": counts,
            "posed": len(b), "same_map": bool(same)}


FIGURES = {"first_map_again_s": first_map_again_s}
