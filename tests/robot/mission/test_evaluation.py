"""`robot.mission.evaluation.localisation_errors`: the estimate at the adaptive stage's
photos against known true poses, over all of them, over its model (goal) photos, split
by whether the random stage photographed the region where each was taken, and by whether
a vision fix was the filter's measurement at the photo."""

import numpy as np

from robot.mission.evaluation import localisation_errors, localisation_errors_by_fix, localisation_errors_by_region
from robot.mission.observer import MissionPhoto
from robot.protocol import Photo


def mission_photo(index: int, stage: str, estimate, fixed: bool | None = None) -> MissionPhoto:
    photo = Photo(np.zeros((2, 2, 3), np.uint8), float(index), np.zeros(3), 0.0, 1.0, index)
    return MissionPhoto(photo, np.asarray(estimate, float), stage, fixed=fixed)


def test_model_photos_are_reported_apart_from_the_localisation_looks():
    truth = {i: np.array([float(i), 0.0, 0.0]) for i in range(7)}
    photos = [mission_photo(0, "random", [5.0, 0.0, 0.0]),  # the random stage is not counted
              mission_photo(1, "goal", [1.03, 0.04, 0.0]),  # 5 cm off
              mission_photo(2, "goal", [2.0, 0.01, np.radians(2.0)]),  # 1 cm, 2 degrees
              mission_photo(3, "localise", [3.5, 0.0, 0.0]),  # 50 cm off
              mission_photo(4, "localise", [4.3, 0.0, 0.0]),  # 30 cm
              mission_photo(5, "goal", [5.0, 0.0, np.radians(-1.0)]),  # exact, 1 degree
              mission_photo(6, "localise", [6.0, 0.2, 0.0])]  # 20 cm
    err = localisation_errors(photos, truth)
    assert err["photos"] == 6 and np.isclose(err["median"], 0.125) and np.isclose(err["max"], 0.5)
    model = err["model"]
    assert model["photos"] == 3 and np.isclose(model["median"], 0.01) and np.isclose(model["max"], 0.05)
    assert np.isclose(model["heading_median_deg"], 1.0)
    assert localisation_errors(photos[:1], truth) is None  # no adaptive photo
    assert localisation_errors(photos[3:5], truth)["model"] is None  # no goal photo


class TwoRooms:
    """A floor plan of two rooms side by side, x < 0 and x > 0, with a threshold at |x| < 0.1 m."""

    @staticmethod
    def room_at(xy):
        return None if abs(xy[0]) < 0.1 else ("west" if xy[0] < 0 else "east")


def test_photos_in_regions_the_random_stage_never_saw_are_reported_apart():
    truth = {i: np.array([x, 0.0, 0.0]) for i, x in enumerate([-2.0, -1.0, -1.5, -0.5, 0.0, 1.0, 2.0])}
    photos = [mission_photo(0, "random", truth[0]), mission_photo(1, "random", truth[1]),
              mission_photo(2, "goal", [-1.49, 0.0, 0.0]),  # west, where the random stage was: 1 cm
              mission_photo(3, "localise", [-0.47, 0.0, 0.0]),  # west: 3 cm
              mission_photo(4, "localise", [0.1, 0.0, 0.0]),  # on the threshold: 10 cm
              mission_photo(5, "goal", [1.2, 0.0, 0.0]),  # east, first entered now: 20 cm
              mission_photo(6, "localise", [2.4, 0.0, 0.0])]  # east: 40 cm
    err = localisation_errors_by_region(TwoRooms(), photos, truth)
    first, later = err["random_stage_regions"], err["later_regions"]
    assert first["photos"] == 2 and np.isclose(first["median"], 0.02) and np.isclose(first["max"], 0.03)
    assert later["photos"] == 3 and np.isclose(later["median"], 0.2) and np.isclose(later["max"], 0.4)
    only_west = localisation_errors_by_region(TwoRooms(), photos[:4], truth)
    assert only_west["later_regions"] is None and only_west["random_stage_regions"]["photos"] == 2
    assert localisation_errors_by_region(TwoRooms(), photos[:2], truth) is None  # no adaptive photo


def test_photos_a_fix_localised_are_reported_apart_from_those_that_rode_the_odometry():
    truth = {i: np.array([float(i), 0.0, 0.0]) for i in range(7)}
    photos = [mission_photo(0, "random", truth[0]),  # the random stage is not counted
              mission_photo(1, "localise", [1.02, 0.0, 0.0], fixed=True),  # 2 cm
              mission_photo(2, "goal", [2.0, 0.04, 0.0], fixed=True),  # 4 cm
              mission_photo(3, "localise", [3.2, 0.0, 0.0], fixed=True),  # a wrong fix: 20 cm, lost
              mission_photo(4, "localise", [4.3, 0.0, 0.0], fixed=False),  # no fix: 30 cm, lost
              mission_photo(5, "goal", [5.0, 0.5, 0.0], fixed=False),  # 50 cm, lost
              mission_photo(6, "localise", [6.1, 0.0, 0.0])]  # not known: in neither part
    err = localisation_errors_by_fix(photos, truth)
    assert err["fixed"]["photos"] == 3 and np.isclose(err["fixed"]["median"], 0.04)
    assert err["unfixed"]["photos"] == 2 and np.isclose(err["unfixed"]["median"], 0.4)
    assert np.isclose(err["lost_unfixed"], 2 / 3)  # of the three lost photos, two had no fix
    only_fixed = localisation_errors_by_fix(photos[:3], truth)
    assert only_fixed["unfixed"] is None and only_fixed["lost_unfixed"] is None  # nothing lost
    assert localisation_errors_by_fix(photos[:1], truth) is None  # no adaptive photo


def test_first_map_scale_is_measured_apart_from_photos_joined_later():
    """Six random photos mapped at exact scale, two more joined later 10 % out from the
    middle (as re-posed photos placed a few cm off): over all of them the map reads off in
    scale, over the first map's alone (`only`) it is exact."""
    import trimesh

    from ibr.camera import intrinsics_from_fov
    from robot.mission.evaluation import map_scale_error
    from robot.mission.map_building import RobotMap
    from robot.protocol import forward_camera_mount, robot_camera

    mount, K = forward_camera_mount(0.4), intrinsics_from_fov(60.0, 32, 24)
    true = [np.array([x, y, 0.3 * i]) for i, (x, y) in enumerate([(0, 0), (1, 0), (0, 1), (1, 1), (2, 0), (2, 1),
                                                                   (3, 0), (3, 1)])]
    mapped = [t.copy() for t in true]
    for t in mapped[6:]:
        t[:2] = np.array([1.5, 0.5]) + 1.1 * (t[:2] - np.array([1.5, 0.5]))
    cams = {i: robot_camera(p, K, (32, 24), mount) for i, p in enumerate(mapped)}
    rmap = RobotMap(cams, np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros((0, 3)), trimesh.Trimesh())
    photos = [mission_photo(i, "random", p) for i, p in enumerate(mapped)]
    truth = dict(enumerate(true))
    assert map_scale_error(rmap, truth, mount, photos) > 0.01
    assert map_scale_error(rmap, truth, mount, photos, frozenset(range(6))) < 1e-9
    assert map_scale_error(rmap, truth, mount, photos, frozenset(range(2))) is None  # under 3 photos


def test_facing_distance_is_the_level_run_to_the_first_true_surface():
    """Known answers in the office (walls at x = +-3 m and y = +-4 m): from (-1.5, -2.5)
    facing north the wall is 6.5 m ahead, facing east 4.5 m; a ray from outside the office
    pointing away meets nothing and is counted as open."""
    from ibr.synthetic import make_world
    from robot.mission.evaluation import facing_distances

    world = make_world("office", 0)
    truth = {0: np.array([-1.5, -2.5, np.pi / 2]), 1: np.array([-1.5, -2.5, 0.0]),
             2: np.array([-1.5, -2.5, np.pi / 2]), 3: np.array([10.0, 0.0, 0.0])}
    photos = [mission_photo(0, "random", truth[0]), mission_photo(1, "goal", truth[1]),
              mission_photo(2, "goal", truth[2]), mission_photo(3, "goal", truth[3]),
              mission_photo(4, "goal", [0.0, 0.0, 0.0])]  # no true pose: not counted
    out = facing_distances(world.mesh, photos, truth, 0.4)
    assert np.isclose(out["random"]["median"], 6.5, atol=1e-3) and out["random"]["photos"] == 1
    adaptive = out["adaptive"]
    assert adaptive["photos"] == 3 and adaptive["open"] == 1
    assert np.isclose(adaptive["p25"], 5.0, atol=1e-3) and np.isclose(adaptive["median"], 5.5, atol=1e-3)
    assert facing_distances(world.mesh, photos[:1], truth, 0.4)["adaptive"] is None


def test_photos_taken_lost_are_counted_in_runs():
    """Photos whose estimate is more than 15 cm off count as lost, and the runs of them in a
    row are the episodes, the longest reported; the random stage does not count."""
    from robot.mission.evaluation import lost_episodes

    off = [0.0, 0.2, 0.3, 0.0, 0.16, 0.0, 0.5, 0.5, 0.5, 0.1]  # metres, adaptive photos 1-10
    truth = {i: np.array([float(i), 0.0, 0.0]) for i in range(11)}
    photos = [mission_photo(0, "random", [9.0, 0.0, 0.0])]
    photos += [mission_photo(i + 1, "localise" if i % 2 else "goal", [i + 1.0, d, 0.0]) for i, d in enumerate(off)]
    assert lost_episodes(photos, truth) == {"photos": 10, "lost": 6, "episodes": 3, "longest": 3}
    assert lost_episodes(photos, truth, lost_m=1.0) == {"photos": 10, "lost": 0, "episodes": 0, "longest": 0}
    assert lost_episodes(photos[:1], truth) is None
