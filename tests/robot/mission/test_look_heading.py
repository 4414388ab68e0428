"""Where a localise photo looks (`robot.mission.look_heading`): toward the map points SIFT can
match, on a hand-made map with known geometry."""

import numpy as np

from ibr.camera import intrinsics_from_fov
from localization.pose_views import forward_camera_mount
from robot.mission.look_heading import LookConfig, heading_counts, look_heading, matchable

SIZE = (320, 240)
K = intrinsics_from_fov(60.0, *SIZE)
MOUNT = forward_camera_mount(0.4)


def wall(x: float, n: int = 400, seed: int = 0) -> np.ndarray:
    """Points on the wall x = const, 4 m wide, 0-1.5 m high."""
    rng = np.random.default_rng(seed)
    return np.c_[np.full(n, x), rng.uniform(-2, 2, n), rng.uniform(0.0, 1.5, n)]


def test_turns_to_the_wall_the_map_saw_from_this_side():
    pts = wall(-3.0)  # behind a robot at the origin facing +x
    seen_from = np.tile([-1.0, 0.0, 0.4], (len(pts), 1))  # triangulated from 1 m in front of it
    heading = look_heading(np.zeros(3), pts, seen_from, K, SIZE, MOUNT, min_points=12)
    assert heading is not None and abs(np.cos(heading) + 1) < 0.05  # facing -x


def test_a_wall_seen_only_from_its_other_side_does_not_count():
    pts = wall(-3.0)
    seen_from = np.tile([-5.0, 0.0, 0.4], (len(pts), 1))  # the map photo stood behind the wall
    _, counts = heading_counts(np.zeros(3), pts, seen_from, K, SIZE, MOUNT)
    assert counts.max() == 0
    assert look_heading(np.zeros(3), pts, seen_from, K, SIZE, MOUNT, min_points=12) is None


def test_points_seen_from_much_closer_do_not_count():
    pts = wall(-3.0)
    near = pts + np.array([1.0, 0.0, 0.0])  # cameras 1 m from the wall; the robot is 3 m from it
    ok = matchable(pts, near, np.array([0.0, 0.0, 0.4]), LookConfig(max_scale_ratio=2.0))
    assert not ok.any()
    ok = matchable(pts, near, np.array([0.0, 0.0, 0.4]), LookConfig(max_scale_ratio=4.0, max_view_angle_deg=90))
    assert ok.mean() > 0.9


def test_keeps_its_heading_when_it_already_sees_the_map():
    front, back = wall(3.0, 400, 1), wall(-3.0, 500, 2)
    pts = np.vstack([front, back])
    seen_from = np.vstack([np.tile([1.0, 0.0, 0.4], (400, 1)), np.tile([-1.0, 0.0, 0.4], (500, 1))])
    headings, counts = heading_counts(np.zeros(3), pts, seen_from, K, SIZE, MOUNT)
    assert headings[0] == 0.0 and counts[0] > 300
    # the back wall holds more points, but not 1.5 times more: no turn
    assert look_heading(np.zeros(3), pts, seen_from, K, SIZE, MOUNT, min_points=12) is None


def test_no_map_points_no_turn():
    none = np.zeros((0, 3))
    assert look_heading(np.array([1.0, 2.0, 0.3]), none, none, K, SIZE, MOUNT, min_points=12) is None




def test_points_of_the_next_room_hidden_by_the_maps_mesh_do_not_count():
    """The next room's wall (x = 4) was mapped from its own side of the wall between the
    rooms (x = 2), so the angle test passes it; the map's mesh of that wall hides it."""
    import trimesh
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    from robot.mission.look_heading import hidden_by

    near, far = wall(-2.0, 300, 1), wall(4.0, 900, 2)  # behind the robot / beyond the wall at x = 2
    pts = np.vstack([near, far])
    seen_from = np.vstack([np.tile([-0.5, 0.0, 0.4], (300, 1)), np.tile([2.5, 0.0, 0.4], (900, 1))])
    partition = trimesh.creation.box(extents=(0.1, 6.0, 3.0), transform=trimesh.transformations.translation_matrix(
        (2.0, 0.0, 1.5)))
    hidden = hidden_by(RayMeshIntersector(partition), LookConfig().occlusion_margin_m)
    assert hidden(np.array([0.0, 0.0, 0.4]), far).all() and not hidden(np.array([0.0, 0.0, 0.4]), near).any()
    through = look_heading(np.zeros(3), pts, seen_from, K, SIZE, MOUNT, min_points=12)
    assert through is None  # it faces the hidden wall already, with the most points
    seen = look_heading(np.zeros(3), pts, seen_from, K, SIZE, MOUNT, min_points=12, hidden=hidden)
    assert seen is not None and np.cos(seen) < -0.9  # turns to the wall it can see (-x, within a step)


def test_the_retry_looks_away_from_the_failed_view():
    from robot.mission.look_heading import retry_heading

    front, back = wall(3.0, 900, 1) * [1.0, 0.25, 1.0], wall(-3.0, 300, 2)  # the front one 1 m wide
    pts = np.vstack([front, back])
    seen_from = np.vstack([np.tile([1.0, 0.0, 0.4], (900, 1)), np.tile([-1.0, 0.0, 0.4], (300, 1))])
    heading = retry_heading(np.zeros(3), pts, seen_from, K, SIZE, MOUNT, min_points=12)
    assert heading is not None and np.cos(heading) < -0.9  # the front wall failed: the back one
    assert retry_heading(np.zeros(3), front, seen_from[:900], K, SIZE, MOUNT, min_points=12) is None
