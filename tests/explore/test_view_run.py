"""The free run ahead of a pose (`explore.view_run`): known answers in a 6 x 4 m room."""

import numpy as np
import shapely

from explore.view_run import view_runs

ROOM = shapely.box(0.0, 0.0, 6.0, 4.0)


def test_the_run_is_the_distance_to_the_wall_ahead():
    poses = np.array([[1.0, 2.0, 0.0], [1.0, 2.0, np.pi], [1.0, 2.0, np.pi / 2], [1.0, 1.0, np.arctan2(3, 4)]])
    runs = view_runs(poses, ROOM, 0.01)
    assert np.allclose(runs, [5.0, 1.0, 2.0, 5.0], atol=0.02)  # the last: corner to corner, 3-4-5


def test_a_surface_another_sensor_met_ends_the_run_and_a_pose_outside_runs_nowhere():
    poses = np.array([[1.0, 2.0, 0.0], [1.0, 2.0, np.pi], [7.0, 2.0, np.pi]])
    runs = view_runs(poses, ROOM, 0.01, blocked=lambda xy: np.abs(xy[:, 0] - 3.0) < 0.05)  # a plain wall at x = 3
    assert np.allclose(runs, [1.95, 1.0, 0.0], atol=0.02)


def test_a_room_beyond_a_doorway_is_in_the_run_when_the_ray_passes_the_doorway():
    two_rooms = shapely.union_all([shapely.box(0, 0, 4, 4), shapely.box(4, 1.5, 4.2, 2.5), shapely.box(4.2, 0, 8, 4)])
    runs = view_runs(np.array([[1.0, 2.0, 0.0], [1.0, 3.0, 0.0]]), two_rooms, 0.01)
    assert np.allclose(runs, [7.0, 3.0], atol=0.02)
