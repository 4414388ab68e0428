"""Frontiers of the ultrasonic's occupancy grid (Yamauchi 1997) in rooms of known walls: a
closed room has none, a doorway makes one that faces out of the room."""

import numpy as np
import shapely

from explore.frontier import SonarConfig, frontiers, revealed, sonar_grid, toward_unknown

CFG = SonarConfig()


def readings(walls: shapely.Geometry, centre, n: int = 36, cone_rays: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """A robot turning in place at `centre` through n headings: poses (n, 3) and the
    ultrasonic's ranges (n,) as `SimRobot.ultrasonic` reads them (the nearest hit of 5 rays
    over the cone, capped at the maximum), against the 2-D `walls`."""
    poses, ranges = [], []
    for th in np.linspace(-np.pi, np.pi, n, endpoint=False):
        r = CFG.max_range_m
        for a in th + np.linspace(-CFG.half_cone_rad, CFG.half_cone_rad, cone_rays):
            ray = shapely.LineString([centre, np.add(centre, CFG.max_range_m * np.array([np.cos(a), np.sin(a)]))])
            hit = ray.intersection(walls)
            if not hit.is_empty:
                r = min(r, shapely.Point(centre).distance(hit))
        poses.append([*centre, th])
        ranges.append(r)
    return np.array(poses), np.array(ranges)


def room(door: bool) -> shapely.Geometry:
    """The walls of a 3 x 3 m room around the origin; with a 1 m doorway in the east wall."""
    sq = shapely.box(-1.5, -1.5, 1.5, 1.5).exterior
    return sq.difference(shapely.box(1.4, -0.5, 1.6, 0.5)) if door else sq


def test_a_closed_room_seen_from_its_middle_has_no_frontier():
    poses, ranges = readings(room(door=False), (0.0, 0.0))
    grid = sonar_grid(poses, ranges, 0.075)
    assert frontiers(grid, min_width_m=0.3) == []
    # the middle is free, the walls occupied, beyond them unknown
    assert grid.is_free(np.array([[0.0, 0.0], [1.0, -1.0]])).all()
    i, j = grid.cells(np.array([[1.5, 0.0]]))
    assert grid.occupied[i[0], j[0]] > 0
    i, j = grid.cells(np.array([[2.5, 0.0]]))
    assert grid.unknown_mask[i[0], j[0]]


def test_a_doorway_is_a_frontier_facing_out_of_the_room():
    poses, ranges = readings(room(door=True), (0.0, 0.0))
    grid = sonar_grid(poses, ranges, 0.075)
    found = frontiers(grid, min_width_m=0.3)
    assert len(found) == 1
    # beyond the doorway, around the fan of the readings through it (2.55 m from the middle)
    mid = found[0].mean(0)
    assert 1.5 < mid[0] <= CFG.max_range_m + 0.1 and abs(mid[1]) < 0.6
    # from the fan's far end, the unknown lies further east
    end = found[0][np.argmax(found[0][:, 0])]
    assert abs(toward_unknown(grid, end, CFG.max_range_m / 2)) < np.radians(45)
    assert toward_unknown(grid, np.zeros(2), 0.5) is None  # the room's middle is all known


def test_surface_distance_is_the_way_to_the_nearest_wall_the_beam_met():
    poses, ranges = readings(room(door=False), (0.0, 0.0))
    grid = sonar_grid(poses, ranges, 0.075)
    d = grid.surface_distance(np.array([[0.0, 0.0], [1.2, 0.0], [0.0, -1.4]]))
    assert abs(d[0] - 1.5) < 0.1 and abs(d[1] - 0.3) < 0.1 and d[2] < 0.15
    empty = sonar_grid(np.zeros((0, 3)), np.zeros(0), 0.075)
    assert np.isinf(empty.surface_distance(np.zeros((1, 2)))).all()


def test_bad_readings_are_skipped_and_no_reading_gives_an_empty_grid():
    poses, ranges = readings(room(door=False), (0.0, 0.0))
    ranges[3] = np.nan
    poses[5, 0] = np.inf
    grid = sonar_grid(poses, ranges, 0.075)
    assert grid.is_free(np.array([[0.0, 0.0]])).all()
    empty = sonar_grid(np.zeros((0, 3)), np.zeros(0), 0.075)
    assert empty.free_bounds() is None and frontiers(empty, 0.3) == []


def test_a_box_the_beam_met_blocks_the_sight_lines_through_it():
    """A 0.6 x 0.6 m box 1 m east of a robot turning in the middle of a closed room: the
    line from the robot to a point behind the box crosses the cells the beam met, so it is
    blocked; lines to points west of it, or to the box's near side from the north, are not."""
    box = shapely.box(0.7, -0.3, 1.3, 0.3)
    poses, ranges = readings(shapely.union(room(door=False), box.exterior), (-0.5, 0.0))
    grid = sonar_grid(poses, ranges, 0.075)
    here = np.array([-0.5, 0.0])
    behind = np.array([[1.0, 0.0], [1.2, 0.1], [1.4, -0.1]])
    clear = np.array([[0.3, 0.0], [-1.2, 0.5], [0.0, -1.0], [0.2, 1.0]])
    assert grid.blocks(np.tile(here, (3, 1)), behind).all()
    assert not grid.blocks(np.tile(here, (4, 1)), clear).any()
    assert grid.blocks(np.zeros((0, 2)), np.zeros((0, 2))).shape == (0,)


def test_a_reading_down_a_corridor_reveals_more_than_one_into_its_wall():
    """Apartment 7's corridor (1.35 m wide, 10 m long): the robot turned in place at its
    south end, so the grid is known for about 2.5 m around it. From 2 m up the corridor,
    0.3 m off its west wall, the reading straight up the corridor (nothing in range) makes
    more than 3 times as many unknown cells free as one at 100 degrees, which reads the wall
    under a metre away; a reading in the known part teaches the grid nothing. The count is
    the sensor model's own (`sonar_grid` run again with the reading added)."""
    walls = shapely.box(0.0, -1.0, 1.35, 9.0).exterior
    poses, ranges = readings(walls, (0.675, 0.0))
    grid = sonar_grid(poses, ranges, 0.075)
    up = np.array([0.3, 2.0, np.pi / 2])
    aside = np.array([0.3, 2.0, np.radians(100.0)])
    n_up, n_aside = revealed(grid, up, CFG.max_range_m, CFG), revealed(grid, aside, 0.88, CFG)
    assert n_up > 3 * n_aside > 0
    again = sonar_grid(np.r_[poses, up[None]], np.r_[ranges, CFG.max_range_m], 0.075)
    assert n_up == int((~again.unknown_mask).sum() - (~grid.unknown_mask).sum())  # the cells it made known
    assert revealed(grid, np.array([0.675, 0.0, 0.0]), 0.6, CFG) == 0
