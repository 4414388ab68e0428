"""The map's metric scale from what the robot knows (Foster et al. IV-A end): a synthetic
SfM model (the true scene in an arbitrary similarity frame) is brought back to metres by the
floor plane and the camera's height, within 1 %, and placed in the floor frame by the
compass and the dead reckoning, even when the odometry is biased."""

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from ibr.proxy.poisson import poisson_mesh
from ibr.synthetic import make_world
from robot.mission.coverage import surface_samples
from robot.mission.circles import place_models
from robot.mission.map_building import (MapConfig, RobotMap, capture_model, floor_depth, levelled_model,
                                         world_from_levelled)
from robot.protocol import robot_camera
from robot.sim_robot import SimRobot, SimRobotConfig


def synthetic_sfm(world_name: str, sfm_scale: float, seed: int = 0):
    """(centres, ups, points) in an SfM frame (world scaled by `sfm_scale`, turned, moved),
    the true camera centres (N, 3) m and the camera height: cameras on a few circles at the
    robot's camera height, points of the true mesh within 5 m of a camera (a tenth of the
    floor's: SfM finds fewer on it), 1 cm of noise."""
    world = make_world(world_name, 0)
    rng = np.random.default_rng(seed)
    robot = SimRobot(world, SimRobotConfig(image_size=(160, 120)), rng, start_pose=tuple(world.start_pose(rng)))
    centres = [np.array(r.polygon.representative_point().coords[0]) for r in world.rooms][:3]
    height = float(np.linalg.inv(robot.cam_from_robot)[2, 3])
    poses = [np.r_[c + 0.15 * np.array([np.cos(a), np.sin(a)]), a] for c in centres
             for a in np.linspace(-np.pi, np.pi, 12, endpoint=False)]
    cams = [robot_camera(p, robot.intrinsics, robot.image_size, robot.cam_from_robot) for p in poses]
    C = np.array([c.center for c in cams])
    s = surface_samples(world.mesh, 20000, rng)
    floor = s.points[:, 2] < 1e-6
    keep = (np.linalg.norm(s.points[:, None] - C[None], axis=2).min(1) < 5.0) & (~floor | (rng.random(len(floor)) < 0.1))
    P = s.points[keep] + rng.normal(0, 0.01, (keep.sum(), 3))
    R = Rotation.from_euler("xyz", rng.uniform(-np.pi, np.pi, 3)).as_matrix()
    t = rng.normal(0, 3, 3)
    to_sfm = lambda X: sfm_scale * X @ R.T + t  # noqa: E731
    ups = np.array([-c.world_from_cam[:3, 1] for c in cams]) @ R.T
    fwd = np.array([c.world_from_cam[:3, 2] for c in cams])
    return to_sfm(C), ups, to_sfm(P), C, height, fwd @ R.T, np.arctan2(fwd[:, 1], fwd[:, 0])


def test_scale_from_the_camera_height_is_within_one_percent():
    for name, sfm_scale in (("office", 0.37), ("apartment", 2.9)):
        centres, ups, points, true_c, height, fwd, _ = synthetic_sfm(name, sfm_scale)
        idx = np.arange(len(centres))
        model, frame = levelled_model(idx, centres, ups, fwd, points, height)
        assert abs(model.floor_scale * sfm_scale - 1) < 0.01, (name, model.floor_scale * sfm_scale)
        M = world_from_levelled(frame, model.floor_scale, 0.0, np.zeros(2), height)
        assert np.abs(centres @ M[:3, :3].T + M[:3, 3] - [0, 0, height])[:, 2].max() < 0.01
        # without points there is no floor, and no scale from it (the test can fail)
        assert levelled_model(idx, centres, ups, fwd, np.zeros((0, 3)), height)[0].floor_scale is None


def test_a_photo_registered_far_off_moves_neither_the_floor_nor_the_cameras_height():
    """Three of the 12 photos SfM registered 40 model units away (a wrong registration): the
    floor's scale stays within 1 % and the other cameras at the camera's height (a mean of
    the centres would have lifted the cameras' reference by 10 units and moved both)."""
    centres, ups, points, true_c, height, fwd, _ = synthetic_sfm("office", 0.37)
    off = centres.copy()
    off[[2, 6, 9]] += 40.0 * ups[[2, 6, 9]]
    idx = np.arange(len(centres))
    model, frame = levelled_model(idx, off, ups, fwd, points, height)
    assert abs(model.floor_scale * 0.37 - 1) < 0.01, model.floor_scale * 0.37
    M = world_from_levelled(frame, model.floor_scale, 0.0, np.zeros(2), height)
    good = np.setdiff1d(idx, [2, 6, 9])
    assert np.abs((off[good] @ M[:3, :3].T + M[:3, 3])[:, 2] - height).max() < 0.01


def test_floor_depth_is_the_bottom_layer_below_the_cameras():
    rng = np.random.default_rng(1)
    walls = -rng.uniform(-1.4, 1.2, 3000)  # wall points at every height
    table = np.full(150, -0.45) + rng.normal(0, 0.005, 150)  # a table top
    floor = np.full(400, -1.2) + rng.normal(0, 0.005, 400)
    depth, n = floor_depth(np.r_[walls, table, floor])
    assert abs(depth - 1.2) < 0.012 and n >= 400
    assert floor_depth(rng.uniform(0, 1, 100)) is None  # nothing below the cameras


def robot_like_sfm(sfm_scale: float, seed: int):
    """An SfM model as the robot's random stage makes it: three circles of photos whose
    centres turn about the axle only by the mount offset (5 cm), 1 cm of noise on the
    centres, the camera's up known from its rotation; a floor that holds only as many
    points per cm of depth as twice the walls; and 1 % of the points triangulated wrongly
    deep below the floor. Returns the SfM centres, ups, points and optical axes, the true
    yaws and centres, the camera height, the robot's circle of each photo, the robot's and
    the camera's dead reckoning (drifting 8 % per metre driven), the distance driven before
    each photo and the camera's mount (xy m, yaw rad) on the robot."""
    rng = np.random.default_rng(seed)
    robot = SimRobot(make_world("office", 0), SimRobotConfig(image_size=(160, 120)), rng, start_pose=(0.0, -1.0, 0.0))
    height = float(np.linalg.inv(robot.cam_from_robot)[2, 3])
    stops = np.array([[0.0, -1.0], [1.2, 0.3], [-0.4, 1.5]])
    poses = [np.r_[c, a] for c in stops for a in np.linspace(-np.pi, np.pi, 36, endpoint=False)]
    cams = [robot_camera(p, robot.intrinsics, robot.image_size, robot.cam_from_robot) for p in poses]
    C = np.array([c.center for c in cams])
    walls = np.c_[rng.uniform(-3, 3, (3000, 2)), rng.uniform(0.0, 2.6, 3000)]
    floor = np.c_[rng.uniform(-3, 3, (120, 2)), np.zeros(120)]
    deep = np.c_[rng.uniform(-3, 3, (40, 2)), rng.uniform(-0.5, -0.3, 40)]
    P = np.r_[walls, floor, deep] + rng.normal(0, 0.01, (3160, 3))
    R = Rotation.from_euler("xyz", rng.uniform(-np.pi, np.pi, 3)).as_matrix()
    t = rng.normal(0, 3, 3)
    to_sfm = lambda X: sfm_scale * X @ R.T + t  # noqa: E731
    up_in_cam = robot.cam_from_robot[:3, :3] @ [0, 0, 1.0]
    ups = np.array([c.world_from_cam[:3, :3] @ up_in_cam for c in cams]) @ R.T
    fwd = np.array([c.world_from_cam[:3, 2] for c in cams])
    driven = np.repeat([0.0, 1.84, 3.7], 36)
    drift = 0.08 * driven[:, None] * np.array([1.0, -0.5])
    circle = np.repeat([0, 1, 2], 36)
    robot_from_cam = np.linalg.inv(robot.cam_from_robot)
    mount = robot_from_cam[:2, 3], float(np.arctan2(robot_from_cam[1, 2], robot_from_cam[0, 2]))
    return (to_sfm(C + rng.normal(0, 0.01, C.shape)), ups, to_sfm(P), fwd @ R.T, np.arctan2(fwd[:, 1], fwd[:, 0]),
            C, height, circle, stops[circle] + drift, C[:, :2] + drift, driven, mount)


def test_a_robots_random_stage_is_put_in_metres_by_the_floor():
    """Levelled by the cameras' known up (the plane of 5 cm circles tilts by degrees), the
    floor found as the map's bottom (not lost behind outliers below it, nor beside walls
    as dense as itself): scale within 1 %; placed by the compass (2 degrees of noise) and
    the dead reckoning from the known start (it drifts): the cameras within 2 cm of the truth."""
    for seed, sfm_scale in ((0, 0.37), (1, 2.9)):
        centres, ups, points, fwd, yaw, true_c, height, circle, dr_xy, dr_cam, driven, mount = \
            robot_like_sfm(sfm_scale, seed)
        model, frame = levelled_model(np.arange(len(centres)), centres, ups, fwd, points, height)
        heading = yaw + np.radians(np.random.default_rng(seed).normal(0, 2, len(yaw)))
        placed = place_models([model], circle, heading, dr_xy, dr_cam, driven, *mount)
        s, a, t = placed.models[0]
        M = world_from_levelled(frame, s, a, t, height)
        mapped = centres @ M[:3, :3].T + M[:3, 3]
        assert abs(s * sfm_scale - 1) < 0.01, (seed, s * sfm_scale)
        assert np.median(np.linalg.norm(mapped - true_c, axis=1)) < 0.02, (seed, np.linalg.norm(mapped - true_c, axis=1))


def _square_room_photos(rng, scale: float, centre_m=(0.3, -0.2), half_m: float = 2.0, mount_m: float = 0.05):
    """A robot turning in place in a 4 x 4 m room: per photo its camera centre and axis and
    the wall points it saw (ahead, within 30 degrees), in a model frame of `scale` metres
    per unit; and the ultrasonic's reading (5 rays over +-10 degrees from the robot's centre,
    the nearest wall, 1 cm of noise), as `SimRobot.ultrasonic`."""
    t = np.linspace(-half_m, half_m, 81)
    walls = np.vstack([np.c_[np.full_like(t, x), t] for x in (-half_m, half_m)]
                      + [np.c_[t, np.full_like(t, y)] for y in (-half_m, half_m)])
    walls = np.vstack([np.c_[walls, np.full(len(walls), z)] for z in (0.3, 0.9, 1.5)])
    centres, forwards, seen, ranges = {}, {}, {}, []
    c = np.array(centre_m, float)
    for i, a in enumerate(np.radians(np.arange(0, 360, 10))):
        f = np.array([np.cos(a), np.sin(a)])
        cam = c + mount_m * f
        v = walls[:, :2] - cam
        ahead = v @ f
        see = (ahead > 0) & (np.abs(np.arctan2(v @ [-f[1], f[0]], ahead)) < np.radians(30))
        centres[i], forwards[i] = np.r_[cam, 0.4] / scale, np.r_[f, 0.0]
        seen[i] = (walls[see] + rng.normal(0, 0.01, (see.sum(), 3))) / scale
        hits = []
        for b in a + np.radians(np.linspace(-10, 10, 5)):
            u = np.array([np.cos(b), np.sin(b)])
            hits.append(min((half_m - c[k] * np.sign(u[k])) / abs(u[k]) for k in range(2) if abs(u[k]) > 1e-9))
        ranges.append(min(hits) + rng.normal(0, 0.01))
    return centres, forwards, seen, np.array(ranges), mount_m


def test_the_ultrasonic_gives_a_model_its_metres():
    """The ultrasonic's range straight ahead against the points a photo saw there: the
    model's metres per unit within 1.5 % (the robot's corner views see the wall obliquely),
    with an honest error; no scale from fewer than 5 readings in range."""
    from explore.frontier import SonarConfig
    from robot.mission.map_building import sonar_scale

    rng = np.random.default_rng(0)
    for scale in (0.2, 3.0):
        centres, forwards, seen, ranges, mount = _square_room_photos(rng, scale)
        s, sigma = sonar_scale(centres, forwards, seen, ranges, mount, SonarConfig())
        assert abs(s / scale - 1) < 0.015 and sigma < 0.02, (scale, s, sigma)
    far = np.full(len(ranges), SonarConfig().max_range_m)  # nothing in range
    far[:4] = ranges[:4]
    assert sonar_scale(centres, forwards, seen, far, mount, SonarConfig()) is None


def test_the_ultrasonic_scale_is_not_pulled_by_surfaces_without_points():
    """Over half the photos face plain furniture (no points) nearer than the wall they saw:
    their ultrasonic reads 75-90 % of the wall's distance and their scales are too low, so
    the photos' median is about 10 % off. The largest group of agreeing photos is still the
    wall's: within 1.5 %, inside three of its sigmas; and one circle's photos count as one
    (a larger sigma than 36 independent photos give)."""
    from explore.frontier import SonarConfig
    from robot.mission.map_building import sonar_scale

    rng = np.random.default_rng(1)
    scale = 0.5
    centres, forwards, seen, ranges, mount = _square_room_photos(rng, scale)
    boxed = rng.permutation(len(ranges))[:20]
    ranges[boxed] = mount + (ranges[boxed] - mount) * rng.uniform(0.75, 0.9, len(boxed))
    s, sigma = sonar_scale(centres, forwards, seen, ranges, mount, SonarConfig(), {i: 0 for i in centres})
    assert abs(s / scale - 1) < 0.015 and abs(np.log(s / scale)) < 3 * sigma, (s, sigma)
    _, independent = sonar_scale(centres, forwards, seen, ranges, mount, SonarConfig())
    assert sigma > 3 * independent


def test_points_across_circles_are_those_two_circles_saw():
    """A point seen only by the photos of one circle (triangulated over the mount's
    centimetres) is left out; one seen from two circles is kept."""
    from ibr.camera import Camera
    from ibr.colmap import to_reconstruction
    from robot.mission.map_building import points_across_circles

    K = np.array([[200.0, 0, 160], [0, 200, 120], [0, 0, 1]])
    cams = [Camera.look_at((x, -3.0, 0.0), (x, 0.0, 0.0), K, 320, 240) for x in (0.0, 0.05, 1.0, 1.05)]
    points = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.1], [0.5, 0.2, -0.1]])
    seen = [np.array([0, 1, 2]), np.array([0, 1]), np.array([1, 2]), np.array([2])]
    rec = to_reconstruction(cams, [f"{i:05d}.png" for i in range(4)], points, seen=seen)
    ids = {tuple(np.round(p.xyz, 3)): pid for pid, p in rec.points3D.items()}
    across = points_across_circles(rec, np.array([0, 0, 1, 1]))
    assert across == {ids[(0.3, 0.0, 0.1)], ids[(0.5, 0.2, -0.1)]}


def test_photos_sfm_posed_off_the_mounts_height_stay_out_of_the_map():
    """A robot on a flat floor takes every photo at its camera's height: SfM poses 0.5 m low
    (apartment 3 had seven) are wrong registrations; a few centimetres are SfM's noise."""
    from ibr.camera import Camera
    from robot.mission.map_building import MapConfig, at_mount_height

    K = np.array([[100.0, 0, 80], [0, 100.0, 60], [0, 0, 1]])
    cams = {i: Camera(K, 160, 120, np.linalg.inv(np.block([[np.eye(3), np.array([[0.0], [0.0], [z]])],
                                                            [np.zeros((1, 3)), np.ones((1, 1))]])))
            for i, z in enumerate([0.40, 0.43, -0.10, 0.38, 0.90])}
    kept = at_mount_height(cams, 0.4, MapConfig().max_camera_height_err_m)
    assert sorted(kept) == [0, 1, 3]


def test_the_floor_comes_from_points_two_circles_saw():
    """Points that only one circle saw rest on the mount's few centimetres of baseline: far
    wall points whose depth SfM overestimated sink below the floor (apartment 5: 179 of them
    0.2-0.8 m under a floor of 78 points; in three SfM runs of 5 its model's scale came out
    12-63 % low, its first map 7-30 % off). The floor is found among the points that photos
    of two circles saw. Without that, this model's floor is the sunk layer (scale 0.48)."""
    from ibr.colmap import to_reconstruction
    from robot.mission.map_building import MapConfig, _levelled, _Rig

    world = make_world("apartment", 0)
    rng = np.random.default_rng(1)
    robot = SimRobot(world, SimRobotConfig(image_size=(160, 120)), rng, start_pose=tuple(world.start_pose(rng)))
    poses = np.array([(x, 0.0, a) for x in (0.0, 1.5) for a in np.linspace(-np.pi, np.pi, 12, endpoint=False)])
    cams = [robot_camera(p, robot.intrinsics, robot.image_size, robot.cam_from_robot) for p in poses]
    walls = np.c_[rng.uniform(-3, 4.5, 200), rng.choice([-3.0, 3.0], 200), rng.uniform(0, 2, 200)]
    both = np.vstack([walls, np.c_[rng.uniform(-2, 3.5, (60, 2)), np.zeros(60)]])  # two circles saw these
    sunk = np.c_[rng.uniform(-3, 4.5, (150, 2)), rng.uniform(-0.5, -0.3, 150)]  # one circle's, too deep
    points = np.vstack([both, sunk]) + rng.normal(0, 0.005, (len(both) + len(sunk), 3))

    def seen(cam, ids):
        _, z = cam.project(points[ids])
        return ids[z > 0.1]
    obs = [seen(c, np.arange(len(points)) if i < 12 else np.arange(len(both))) for i, c in enumerate(cams)]
    rec = to_reconstruction(cams, [f"{i:05d}.png" for i in range(len(cams))], points, seen=obs)
    rig = _Rig(poses, poses[:, 2], robot.cam_from_robot, MapConfig())
    model = _levelled(rec, rig)[0]
    assert model.floor_scale is not None and abs(model.floor_scale - 1.0) < 0.02, model.floor_scale


def test_the_captures_model_keeps_the_walls_its_map_saw_sparsely():
    """The capture's model (`capture_model`, what new views are rendered from) keeps a surface
    the map holds only sparse points of, where the map's coarse proxy cuts it away: a room
    whose one textured wall is dense pair tracks (each feature triangulated from several
    pairs, millimetres apart, as the mission's map has them) and whose other walls, floor
    and ceiling are points 0.3 m apart."""
    rng = np.random.default_rng(0)
    box = trimesh.creation.box(extents=(6.0, 4.0, 2.5))
    box.apply_translation((0.0, 0.0, 1.25))
    samples, faces = trimesh.sample.sample_surface_even(box, 1000, seed=1)
    plain = samples[:, 0] > -2.99
    seen = rng.uniform((-3.0, -2.0, 0.0), (-3.0, 2.0, 2.5), (1500, 3))
    tracks = np.repeat(seen, 8, axis=0) + rng.normal(0.0, 0.002, (8 * len(seen), 3))
    points = np.vstack([tracks, samples[plain]])
    normals = np.vstack([np.tile((1.0, 0.0, 0.0), (len(tracks), 1)), -box.face_normals[faces[plain]]])
    colors = np.full((len(points), 3), 128, np.uint8)
    config = MapConfig()
    rmap = RobotMap({}, points, colors, normals, poisson_mesh(points, normals, colors, config.poisson))
    model = capture_model(rmap, config)
    assert model.points is rmap.points and model.cameras is rmap.cameras
    plain_area = box.area - 4.0 * 2.5

    def kept(mesh):
        on_plain = mesh.triangles_center[:, 0] > -2.9
        return mesh.area_faces[on_plain].sum() / plain_area, mesh.triangles_center[on_plain]

    coarse_share, _ = kept(rmap.mesh)
    share, centres = kept(model.mesh)
    assert coarse_share < 0.3, "the map's proxy cuts the sparse walls (why the capture needs its own mesh)"
    assert share > 0.8
    # on the walls, within a third of the points' spacing (Poisson bows between the points)
    assert np.median(np.abs(trimesh.proximity.signed_distance(box, centres))) < 0.1
