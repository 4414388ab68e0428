"""Placing an SfM model of all the photos onto the map's own photos (`robot.mission.repose`)."""

import shutil

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ibr.camera import Camera, rigid
from ibr.synthetic import make_world
from robot.mission.adaptive import AdaptiveConfig, AdaptiveMission, start_filter
from robot.mission.coverage import surface_samples
from robot.mission.map_building import MapConfig, RobotMap, forget_model, posed_images, run_sfm
from robot.mission.observer import MissionObserver, MissionPhoto
from robot.mission.random_stage import Body, RandomExplorationConfig, random_exploration
from robot.mission.repose import (ReposeConfig, anchored, odometry_held, repose_pairs, repose_photos, sfm_cameras,
                                  oriented_similarity)
from robot.protocol import robot_camera
from robot.sim_robot import SimRobot, SimRobotConfig

START = np.array([-1.5, -2.5, 0.0])

K = np.array([[200.0, 0, 80], [0, 200.0, 60], [0, 0, 1]])


def camera_at(centre, rotation=np.eye(3)) -> Camera:
    """A camera at `centre` whose world_from_cam rotation is `rotation`."""
    return Camera(K, 160, 120, np.linalg.inv(rigid(rotation, np.asarray(centre, float))))


def truth_and_sfm(n=12, seed=0):
    """Map cameras at camera height in a 4 m room and the same cameras in an SfM frame
    (rotated, scaled by 0.3, shifted): map = T_true(sfm)."""
    rng = np.random.default_rng(seed)
    centres = np.c_[rng.uniform(-2, 2, (n, 2)), np.full(n, 0.4)]
    yaws = Rotation.from_euler("z", rng.uniform(-180, 180, (n, 1)), degrees=True).as_matrix()
    R = Rotation.from_euler("zyx", [40, 5, -3], degrees=True).as_matrix()
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = (1 / 0.3) * R, [1.0, -2.0, 0.5]
    Tinv = np.linalg.inv(T)
    sfm = {i: camera_at(Tinv[:3, :3] @ c + Tinv[:3, 3], R.T @ yaws[i]) for i, c in enumerate(centres)}
    return {i: camera_at(c, yaws[i]) for i, c in enumerate(centres)}, sfm, T


def test_similarity_recovers_a_known_transform():
    anchors, sfm, T = truth_and_sfm()
    assert np.allclose(oriented_similarity(list(sfm.values()), list(anchors.values())), T, atol=1e-9)


def test_the_placed_model_is_level_though_the_anchors_stand_in_a_line():
    """Anchors in a row at the camera's height, their heights 1 cm noisy: the centres alone
    leave the roll about the row free (Umeyama's fit tilts the model by over half a degree), the
    cameras' orientations fix it: the placed model's up axis is the map's within 0.1 degree."""
    from robot.mission.map_building import umeyama

    anchors, sfm, T = truth_and_sfm()
    rng = np.random.default_rng(3)
    row = {i: camera_at([0.3 * i, 0.02 * i, 0.4 + rng.normal(0, 0.01)], c.world_from_cam[:3, :3])
           for i, c in anchors.items()}
    Tinv = np.linalg.inv(T)
    sfm = {i: camera_at(Tinv[:3, :3] @ [0.3 * i, 0.02 * i, 0.4] + Tinv[:3, 3], sfm[i].world_from_cam[:3, :3])
           for i in row}
    placed = anchored(sfm, row)
    assert placed is not None
    up = placed[0][:3, :3] @ (Tinv[:3, :3] @ [0, 0, 1.0])
    assert np.degrees(np.arccos(up[2] / np.linalg.norm(up))) < 0.1
    s, R, _ = umeyama(np.array([c.center for c in sfm.values()]), np.array([c.center for c in row.values()]))
    assert np.degrees(np.arccos((R @ Tinv[:3, :3] @ [0, 0, 1.0])[2] / np.linalg.norm(Tinv[:3, :3] @ [0, 0, 1.0]))) > 0.5


def test_a_model_that_agrees_with_the_anchors_is_placed_despite_a_bad_anchor():
    anchors, sfm, T = truth_and_sfm()
    anchors[3] = camera_at(anchors[3].center + [0.8, 0.0, 0.0])  # a wrong PnP fix among the anchors
    found = anchored(sfm, anchors)
    assert found is not None
    assert np.allclose(found[0], T, atol=1e-6) and found[1] < 1e-6


def test_a_model_that_disagrees_with_the_anchors_is_refused():
    anchors, sfm, _ = truth_and_sfm()
    rng = np.random.default_rng(1)  # the map's photos scattered by 0.5 m: not this model's shape
    moved = {i: camera_at(c.center + np.r_[rng.normal(0, 0.5, 2), 0.0]) for i, c in anchors.items()}
    assert anchored(sfm, moved) is None


def test_too_few_shared_photos_place_nothing():
    anchors, sfm, _ = truth_and_sfm()
    few = {i: anchors[i] for i in range(ReposeConfig().min_anchors - 1)}
    assert anchored(sfm, few) is None


def _walk(rng, n=40):
    """A robot's true poses (n, 3) along a walk of short legs and turns in place, and its
    odometry (n, 3): the same steps, 10 % long and turned 3 degrees (its own frame)."""
    true, odo = [np.zeros(3)], [np.array([0.5, -0.2, 0.3])]
    for _ in range(n - 1):
        turn, leg = rng.uniform(-1.0, 1.0), rng.uniform(0.0, 0.8)
        t, o = true[-1], odo[-1]
        true.append(np.r_[t[:2] + leg * np.array([np.cos(t[2] + turn), np.sin(t[2] + turn)]), t[2] + turn])
        a = o[2] + turn * 1.02
        odo.append(np.r_[o[:2] + 1.1 * leg * np.array([np.cos(a + 0.05), np.sin(a + 0.05)]), a])
    return np.array(true), np.array(odo)


def test_photos_the_odometry_does_not_tie_to_the_map_are_left_out():
    """SfM re-posed a walk of 40 photos right to 2 cm, except photos 20-27, which it put
    1 m off (one room's repeated texture taken for another's) and 33-39, whose map photos
    disagree with it. The run the map's photos hold is kept (across photo 10, which SfM did
    not pose); the others are left out, and so are 28-32: right, but cut off from the map's
    photos by the wrong run, nothing ties them to the map."""
    rng = np.random.default_rng(3)
    true, odo = _walk(rng)
    sfm = true + np.c_[rng.normal(0, 0.02, (40, 2)), np.zeros(40)]
    sfm[20:28, :2] += [1.0, 0.4]
    sfm[33:, :2] += [0.0, 0.6]
    poses = {i: sfm[i] for i in range(40) if i != 10}  # SfM did not pose photo 10
    agree = {0: True, 5: True, 15: True, 33: False, 36: False, 39: True}
    kept = odometry_held(poses, odo, agree, ReposeConfig())
    assert kept == set(range(20)) - {10}


def _mission_lacking_photos():
    """(mission, photos, robot): a random exploration of 40 photos whose photos 30-39 the
    map lacks (as SfM or PnP would leave photos of a room the map has no points of)."""
    world = make_world("office", 0)
    robot = SimRobot(world, SimRobotConfig(image_size=(320, 240)), np.random.default_rng(0), start_pose=tuple(START))
    body = Body(robot, START)
    photos = []
    for shot in random_exploration(robot, START, RandomExplorationConfig(n_photos=40, circle_step_rad=np.radians(18)),
                                   np.random.default_rng(1), body):
        cam = robot_camera(robot.truth[-1]["pose"], robot.intrinsics, robot.image_size, robot.cam_from_robot)
        photos.append(MissionPhoto(shot.photo, shot.estimate, "random", cam if shot.photo.index < 30 else None))
    s = surface_samples(world.mesh, 3000, np.random.default_rng(0))
    rmap = RobotMap({i: p.camera for i, p in enumerate(photos[:30])}, s.points, np.full((3000, 3), 128, np.uint8),
                    s.normals, world.mesh, 30)
    rng = np.random.default_rng(2)
    mission = AdaptiveMission(robot, start_filter(robot, body, photos, rmap, AdaptiveConfig(), rng), photos, rmap,
                              AdaptiveConfig(), rng, MissionObserver())
    return mission, photos, robot


def test_a_mission_reposes_the_photos_its_map_lacks():
    """`repose` poses most of the photos the map lacks by SfM over all the photos, within a
    few cm of the truth (0.6-4 cm when written), and they join the map's tracks."""
    mission, photos, robot = _mission_lacking_photos()
    tracks_before = len(mission.tracks.points)
    joined = mission.repose()
    truth = [robot_camera(t["pose"], robot.intrinsics, robot.image_size, robot.cam_from_robot) for t in robot.truth]
    posed = [i for i in range(30, 40) if photos[i].camera is not None]
    assert joined >= 6 and len(posed) >= 6  # most of them: a plain wall close by leaves a view unposed
    err = [np.linalg.norm(photos[i].camera.center - truth[i].center) for i in posed]
    assert np.median(err) < 0.03 and max(err) < 0.1  # the bar is 5 cm at the median
    assert len(mission.tracks.points) > tracks_before
    mission.repose()  # again, from the kept features and matches: what joined stays
    assert all(photos[i].camera is not None for i in posed)


def test_photos_whose_points_lie_where_the_map_saw_empty_space_do_not_join():
    """A re-posing whose new points lie where the map's photos saw empty space placed its
    photos wrong (apartment 2: 30 photos 0.3 m off at the median, their points filled the
    kitchen and no goal was reachable): it joins nothing."""
    mission, photos, _ = _mission_lacking_photos()
    mission._seen_free = lambda points, margin_m: np.ones(len(points), bool)  # every point seen through
    points_before = len(mission.map.points)
    assert mission.repose() == 0
    assert all(photos[i].camera is None for i in range(30, 40))
    assert len(mission.map.points) == points_before


def test_a_gap_of_unposed_photos_does_not_cut_a_run_from_the_map():
    """A walk of two turns and drives between photos; SfM left photos 12-15 unposed (2-3 m
    driven across the gap) and put 30-39 1 m off. The odometry's heading errs by 15 % of
    each turn (as the simulated robot's: 0.14 x the turn), so its steps across the gap
    miss by most of a metre; the compass-aided dead reckoning (2 degrees, drives 2 % long)
    measures them. With it every photo SfM posed right is kept, across the gap; the wrong
    run is left out either way, and the odometry alone loses the photos after the gap."""
    rng = np.random.default_rng(3)
    n = 40
    true, odo, dr = [np.zeros(3)], [np.array([0.5, -0.2, 0.3])], [np.zeros(3)]
    for _ in range(n - 1):
        t, o, d = true[-1].copy(), odo[-1].copy(), dr[-1].copy()
        for _ in range(2):
            turn, leg = rng.uniform(-2.5, 2.5), rng.uniform(0.2, 0.4)
            t[2] += turn
            t[:2] += leg * np.array([np.cos(t[2]), np.sin(t[2])])
            o[2] += turn * (1 + rng.normal(0, 0.15))
            o[:2] += leg * np.array([np.cos(o[2]), np.sin(o[2])])
            d[2] = t[2] + rng.normal(0, np.radians(2))
            d[:2] += 1.02 * leg * np.array([np.cos(d[2]), np.sin(d[2])])
        true.append(t)
        odo.append(o)
        dr.append(d)
    true, odo, dr = np.array(true), np.array(odo), np.array(dr)
    sfm = true + np.c_[rng.normal(0, 0.02, (n, 2)), np.zeros(n)]
    sfm[30:, :2] += [1.0, 0.4]
    gap = {12, 13, 14, 15}
    poses = {i: sfm[i] for i in range(n) if i not in gap}
    agree = {0: True, 4: True, 8: True}
    right = set(range(30)) - gap
    with_dr = odometry_held(poses, odo, agree, ReposeConfig(), dr)
    assert with_dr == right
    assert odometry_held(poses, odo, agree, ReposeConfig()) < with_dr


@pytest.fixture(scope="module")
def two_rooms():
    """The robot's first circles (40 photos each, as the random stage takes them) in two
    rooms of an apartment: (robot, photos, compass headings (N,) rad, first room's count)."""
    world = make_world("apartment", 0)
    rooms = [r.name for r in world.rooms if r.kind == "room"][:2]
    images, headings = [], []
    for k, room in enumerate(rooms):
        start = next(p for p in (world.start_pose(np.random.default_rng(j)) for j in range(100))
                     if world.room_at(p[:2]) == room)
        robot = SimRobot(world, SimRobotConfig(image_size=(320, 240)), np.random.default_rng(k + 1), start_pose=tuple(start))
        for shot in random_exploration(robot, start, RandomExplorationConfig(n_photos=40, circle_step_rad=np.radians(18)),
                                       np.random.default_rng(k + 1), Body(robot, start)):
            images.append(shot.photo.image)
            headings.append(shot.photo.compass_rad)
    return robot, images, np.array(headings), 40


def test_sfm_grows_the_last_model_alone_and_keeps_it_when_stopped(two_rooms, tmp_path):
    """A re-posing's SfM (`run_sfm(grow_only=True)`) continues the last call's model of the
    first room's photos and starts no other: with the second room's photos added, one
    model comes back (without it, a second model of the other room: 44 and 11 photos when
    written), grown and holding the last one's photos; and COLMAP stopped after its
    `max_seconds` keeps the model it has instead of losing it."""
    robot, images, headings, n = two_rooms
    cfg = MapConfig()
    first = set(posed_images(run_sfm(images[:n], robot.intrinsics, headings[:n], cfg, tmp_path / "a")[0]))
    assert len(first) >= 10
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    grown = run_sfm(images, robot.intrinsics, headings, cfg, tmp_path / "a", grow_only=True)
    assert len(grown) == 1
    posed = set(posed_images(grown[0]))
    assert len(posed) > len(first) and len(first & posed) >= 0.9 * len(first)  # COLMAP may drop a photo it re-judges
    stopped = run_sfm(images, robot.intrinsics, headings, cfg, tmp_path / "b", grow_only=True, max_seconds=1)
    assert len(stopped) == 1 and len(first & set(posed_images(stopped[0]))) >= 0.9 * len(first)


def test_a_model_that_does_not_fit_the_map_is_not_grown_again(two_rooms, tmp_path):
    """A re-posing whose SfM model the map's photos do not fit is refused, and the next one
    maps afresh rather than grow that model further; a model that fits is kept, to grow."""
    robot, images, headings, n = two_rooms
    images, headings, cfg = images[:n], headings[:n], MapConfig()
    in_model = np.ones(n, bool)
    pairs = repose_pairs(headings, in_model, cfg.match_heading_rad, ReposeConfig().window)
    cams, _ = sfm_cameras(images, robot.intrinsics, pairs, cfg, tmp_path)
    bent = {i: camera_at(c.center + np.r_[np.random.default_rng(i).normal(0, 0.5, 2), 0]) for i, c in cams.items()}
    refused = repose_photos(images, robot.intrinsics, headings, in_model, bent, cfg, tmp_path)
    assert isinstance(refused, str) and "do not fit" in refused
    assert not (tmp_path / "model").exists()
    placed = repose_photos(images, robot.intrinsics, headings, in_model, cams, cfg, tmp_path)
    assert not isinstance(placed, str) and placed[2] < 0.01  # the same photos, mapped afresh, fit
    assert (tmp_path / "model").is_dir()


def _database(work):
    """What SfM's database in `work` holds: its number of cameras, each photo's number of
    features {name: count} and each matched pair's verdict {(name, name): (config, inliers)}."""
    import pycolmap

    db = pycolmap.Database.open(work / "database.db")
    try:
        names = {im.image_id: im.name for im in db.read_all_images()}
        features = {name: db.num_keypoints_for_image(i) for i, name in names.items()}
        pair_ids, geometries = db.read_two_view_geometries()
        pairs = {tuple(sorted(names[i] for i in pycolmap.pair_id_to_image_pair(p))):
                 (int(g.config), len(g.inlier_matches)) for p, g in zip(pair_ids, geometries)}
        return db.num_cameras(), features, pairs
    finally:
        db.close()


def test_sfm_killed_at_its_limit_leaves_the_workspace_to_the_next_call(two_rooms, tmp_path):
    """A re-posing's SfM runs in a child process killed at its time limit
    (`sfm_cameras(limit_s=)`, `robot.mission.sfm_process`): the call says so (None) within
    the limit instead of running on, and the next call in the same workspace maps the
    photos as one that was never stopped does: its database holds the same features and
    verified pairs (features missing are extracted for the one camera already there, pairs
    not matched are matched, with a seeded RANSAC) and its model has the same photos (the
    last model is whole or absent)."""
    import time

    robot, images, headings, n = two_rooms
    cfg = MapConfig()
    pairs = repose_pairs(headings, np.ones(len(images), bool), cfg.match_heading_rad, ReposeConfig().window)
    t0 = time.perf_counter()
    never, _ = sfm_cameras(images, robot.intrinsics, pairs, cfg, tmp_path / "b", limit_s=600.0)
    whole = time.perf_counter() - t0
    # killed part way, wherever this machine's speed puts that; on a machine whose load
    # falls the same work can finish sooner than before (it did, at 0.6, under a sweep of
    # missions), so a call that finished is tried again in a new workspace with less time
    for k, part in enumerate((0.6, 0.3, 0.15)):
        work, limit = tmp_path / f"a{k}", part * whole
        t0 = time.perf_counter()
        killed = sfm_cameras(images, robot.intrinsics, pairs, cfg, work, limit_s=limit) is None
        assert time.perf_counter() - t0 < limit + 10.0
        if killed:
            break
    assert killed
    cams, support = sfm_cameras(images, robot.intrinsics, pairs, cfg, work, limit_s=600.0)
    resumed = _database(work)
    assert resumed == _database(tmp_path / "b")
    assert resumed[0] == 1 and len(resumed[1]) == len(images)
    assert set(cams) == set(never) and len(never) >= n / 2
    assert set(support) == set(cams) and min(support.values()) > 0


def test_sfm_of_the_same_photos_is_the_same_map(two_rooms, tmp_path):
    """Two SfM runs of the same photos in fresh workspaces give the same database, image ids
    included (numbered in name order before the extraction's threads number them as they
    finish: unordered, COLMAP's mapping visited the photos in another order and the same
    108 photos gave 1586 or 1584 points), and the same model to the last digit (matching
    and mapping on `MapConfig.mapping_threads`, one)."""
    import pycolmap

    robot, images, headings, n = two_rooms
    images, headings, cfg = images[:n], headings[:n], MapConfig()
    runs = [run_sfm(images, robot.intrinsics, headings, cfg, tmp_path / w)[0] for w in "ab"]
    for w in "ab":
        db = pycolmap.Database.open(tmp_path / w / "database.db")
        try:
            ids = sorted((im.image_id, im.name) for im in db.read_all_images())
        finally:
            db.close()
        assert [name for _, name in ids] == sorted(name for _, name in ids)
    assert _database(tmp_path / "a") == _database(tmp_path / "b")
    _assert_same_model(*runs)


def _assert_same_model(a, b):
    """Two SfM models (pycolmap.Reconstruction) hold the same photos and points, each photo's
    pose equal to the last digit."""
    assert a.num_points3D() == b.num_points3D() and set(a.reg_image_ids()) == set(b.reg_image_ids())
    for i in a.reg_image_ids():
        np.testing.assert_array_equal(a.images[i].cam_from_world().matrix(), b.images[i].cam_from_world().matrix())


def test_a_first_map_built_again_in_its_workspace_is_the_same_map(two_rooms, tmp_path):
    """The mission builds its first map again, a circle of photos more each time, while the
    floor cannot check its scale (`mission._first_map`), every build in one SfM workspace
    (`initial_map(work=)`: the model forgotten, the features and matches kept, so a build
    extracts and matches only the new photos). The second build there is the build a fresh
    workspace gives: the same database and the same model to the last digit."""
    robot, images, headings, n = two_rooms
    cfg, more = MapConfig(), n + 20
    run_sfm(images[:n], robot.intrinsics, headings[:n], cfg, tmp_path / "kept")
    forget_model(tmp_path / "kept")
    kept = run_sfm(images[:more], robot.intrinsics, headings[:more], cfg, tmp_path / "kept")[0]
    fresh = run_sfm(images[:more], robot.intrinsics, headings[:more], cfg, tmp_path / "fresh")[0]
    assert _database(tmp_path / "kept") == _database(tmp_path / "fresh")
    _assert_same_model(kept, fresh)


def test_sfm_in_a_child_process_reports_its_error(tmp_path):
    """SfM's own error (`MapError`) crosses from the child process with its message."""
    from robot.mission.map_building import MapError
    from robot.mission.sfm_process import run_sfm_within

    blank = [np.full((120, 160, 3), 128, np.uint8) for _ in range(3)]
    with pytest.raises(MapError, match="registered none"):
        run_sfm_within(blank, K, MapConfig(), tmp_path, np.array([[0, 1], [1, 2]]), True, None, 120.0)
