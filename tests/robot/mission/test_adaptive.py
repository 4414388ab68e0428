"""Adaptive exploration (Foster et al. IV-B) on a map with known geometry: goal picking,
path following on the localiser's estimate, giving a goal up after k obstacles, rebuilding."""

import copy
from dataclasses import replace

import numpy as np
import pytest
import shapely

from explore.candidates import free_space_from_mesh, sample_candidates
from explore.frontier import frontiers, revealed
from explore.path_simplify import plan_path
from ibr.scene import load_scene
from ibr.synthetic import make_world
from localization.feature_localizer import FeatureMap, pose_errors
from robot.mission.adaptive import AdaptiveConfig, AdaptiveMission, pick_goals, start_filter
from robot.mission.bundle import BundleConfig
from robot.mission.coverage import surface_samples
from robot.mission.look_heading import heading_counts
from robot.mission.map_building import RobotMap
from robot.mission.observer import MissionObserver, MissionPhoto
from robot.mission.random_stage import Body, RandomExplorationConfig, random_exploration
from robot.protocol import MotionResult, robot_camera
from robot.sim_robot import SimRobot, SimRobotConfig

START = np.array([-1.5, -2.5, 0.0])


class Recorder(MissionObserver):
    def __init__(self):
        self.estimates, self.paths, self.particle_sets = [], [], []

    def estimate(self, pose, source):
        self.estimates.append((pose.copy(), source))

    def particles(self, particles, weights):
        self.particle_sets.append(particles.copy())

    def path(self, xy):
        self.paths.append(xy)


def mission(seed=0) -> tuple[AdaptiveMission, SimRobot, Recorder]:
    """A mission after 48 random-exploration photos, mapped with their TRUE poses and points
    sampled on the true mesh (so the test isolates the adaptive stage from SfM)."""
    world = make_world("office", 0)
    robot = SimRobot(world, SimRobotConfig(image_size=(320, 240)), np.random.default_rng(seed), start_pose=tuple(START))
    body = Body(robot, START)
    photos = []
    for shot in random_exploration(robot, START, RandomExplorationConfig(n_photos=40, circle_step_rad=np.radians(18)), np.random.default_rng(1), body):
        cam = robot_camera(robot.truth[-1]["pose"], robot.intrinsics, robot.image_size, robot.cam_from_robot,
                           name=f"photo_{shot.photo.index:05d}")
        photos.append(MissionPhoto(shot.photo, shot.estimate, "random", cam))
    s = surface_samples(world.mesh, 6000, np.random.default_rng(0))
    rmap = RobotMap({i: p.camera for i, p in enumerate(photos)}, s.points,
                    np.full((6000, 3), 128, np.uint8), s.normals, world.mesh, len(photos))
    obs = Recorder()
    cfg = AdaptiveConfig(n_candidates=120)
    rng = np.random.default_rng(2)
    body = start_filter(robot, body, photos, rmap, cfg, rng)  # the particle filter from here on
    return AdaptiveMission(robot, body, photos, rmap, cfg, rng, obs), robot, obs


@pytest.fixture(scope="module")
def office():
    return mission()


def test_pick_goals_takes_the_best_spread_apart():
    poses = np.array([[0, 0, 0], [0.1, 0, 0.1], [0.1, 0, 2.0], [3, 0, 0], [5, 0, 0.0]])
    scores = np.array([0.9, 0.8, 0.7, 0.5, 0.6])
    # pose 1 is too close in place and heading to pose 0; pose 2 is close but turned away
    assert pick_goals(poses, scores, 3, separation_m=1.0).tolist() == [0, 2, 4]


def test_goals_lie_in_the_free_space_and_score_best(office):
    m, robot, _ = office
    goals, best, grid = m.choose_goals()
    c = m.config
    assert 1 <= len(goals) <= c.goals_per_round + c.frontier_goals_per_round
    assert 1 <= m.n_frontier_goals <= c.frontier_goals_per_round  # 40 photos heard only part of the office
    assert best > 0
    world_free = robot.world.free_space
    assert shapely.contains_xy(world_free, goals[:, 0], goals[:, 1]).all()
    # every goal is reachable: A* finds a path to it on the round's grid
    assert all(plan_path(grid, m.body.est.pose[:2], g[:2], max_cost=m.config.max_path_cost) is not None
               for g in goals)


def test_goes_to_a_goal_on_the_localisers_estimate(office):
    m, robot, obs = office
    _, _, grid = m.choose_goals()
    free = robot.world.free_space
    # a goal 1-2.5 m away, where the map's photos saw enough to localise against
    cand = sample_candidates(free, 200, np.random.default_rng(5), 0.4)
    d = np.hypot(*(cand[:, :2] - m.body.est.pose[:2]).T)
    goal = cand[np.flatnonzero((d > 1.0) & (d < 2.5))[0]]
    fixes = m.fixes
    assert m.go_to(goal, grid)
    # reached by the estimate within reach_m; the truth is near too (vision fixes on the way)
    assert np.hypot(*(m.body.est.pose[:2] - goal[:2])) < m.config.reach_m + 0.05  # the arrival check
    assert np.hypot(*(robot.true_pose[:2] - goal[:2])) < 0.4
    assert m.fixes > fixes and obs.paths
    assert any(src == "pnp" for _, src in obs.estimates)
    # the filter's particles were reported on the way; its estimate is the one followed
    assert len(obs.particle_sets) > 2 and np.array_equal(m.body.est.pose, m.body.est.mean)
    assert np.hypot(*(m.body.est.pose[:2] - robot.true_pose[:2])) < 0.3
    shots = m.capture_at(goal, budget=2)
    assert np.hypot(*(shots[1].estimate[:2] - shots[0].estimate[:2])) > 0.25  # a stereo side step
    assert [p.stage for p in shots] == ["goal", "goal"] and all(p.camera is not None for p in shots)
    before = len(m.map.points)
    m.rebuild(shots)
    assert len(m.map.cameras) == 42
    # a goal photo PnP fixed adds its points; one posed at the estimate adds none (`unfixed`)
    fixed = [i for i, p in enumerate(m.photos) if any(p is q for q in shots) and i not in m.unfixed]
    assert (len(m.map.points) > before) == bool(fixed)


def test_gives_a_goal_up_after_k_obstacles(office, monkeypatch):
    m, robot, _ = office
    drives = []
    real_drive = robot.drive

    def always_bumps(distance_m):
        """Every forward leg hits something at once (front bumper); backing off works."""
        if distance_m > 0.25:
            drives.append(distance_m)
            return MotionResult(np.zeros(3), bumper_front=True)
        return real_drive(distance_m)

    monkeypatch.setattr(robot, "drive", always_bumps)
    # look=None: the localise photos between bumps keep the heading, so the robot backs off
    # the way it came; turned to the map, it can end walled in by its own 5 bumps ("no path past its bumps")
    monkeypatch.setattr(m, "config", replace(m.config, off_path_m=0.2, max_obstacles=5, look=None))
    goals, _, grid = m.choose_goals()
    far = goals[np.argmax(np.hypot(*(goals[:, :2] - m.body.est.pose[:2]).T))]
    # an open floor: the bumps alone block the plans, so no wall of the office closes the
    # gaps between them into "no path past its bumps" (which depended on where earlier tests left the robot)
    grid = replace(grid, cost=np.zeros_like(grid.cost))
    met = dict(m.obstacles_met)
    try:
        assert not m.go_to(far, grid) and m.give_up_reason == "obstacles"
        assert len(drives) == 6  # k = 5 obstacles survived, the 6th gives up
        assert m.obstacles_met["path"] == met["path"] + 6  # and counted
        # each contact was remembered and is blocked for every later plan
        assert len(m.bumps) == 6 and np.isinf(m._with_bumps(grid, m.bumps).cost_at(np.array(m.bumps))).all()
    finally:
        m.bumps = []


def test_a_goal_behind_its_own_bump_is_given_up_past_its_bumps(office, monkeypatch):
    """A goal just beyond what the robot bumps into on its way (the goal within the robot's
    radius of the contact, which stays blocked while that goal is tried) has no path after
    the bump: given up for "no path past its bumps", told apart from a goal the planner
    found no path to before the robot drove."""
    m, robot, _ = office
    real_drive = robot.drive
    monkeypatch.setattr(robot, "drive", lambda d: MotionResult(np.zeros(3), bumper_front=True) if d > 0.2
                        else real_drive(d))
    monkeypatch.setattr(m, "config", replace(m.config, look=None))
    est = m.body.est.pose
    # 0.22 m ahead: 0.07 m beyond the contact (the robot's radius ahead), so the goal's cell
    # lies within the radius of it wherever the grid's 0.09 m cells fall (half a diagonal: 0.064 m)
    goal = np.array([*(est[:2] + 0.22 * np.array([np.cos(est[2]), np.sin(est[2])])), est[2]])
    _, _, grid = m.choose_goals()
    try:
        assert not m.go_to(goal, replace(grid, cost=np.zeros_like(grid.cost)))
        assert m.give_up_reason == "no path past its bumps" and len(m.bumps) >= 1
    finally:
        m.bumps = []


def fenced(m: AdaptiveMission, radius_m: float, deaf: bool = True) -> AdaptiveMission:
    """The mission with a ring of dense map points (a fence 0.2-1.0 m high) around the robot's
    estimate: the navigation grid blocks it, so nothing outside is reachable. The photos'
    ultrasonic readings are dropped when `deaf` (a range of 0 is no reading): the real
    office's readings find the space beyond the fence free, and the grid trusts them over
    map points."""
    a = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    z = np.linspace(0.2, 1.0, 5)
    ring = np.array([[*(m.body.est.pose[:2] + radius_m * np.array([np.cos(t), np.sin(t)])), h] for t in a for h in z])
    pts = np.r_[m.map.points, ring]
    rmap = replace(m.map, points=pts, colors=np.zeros((len(pts), 3), np.uint8), normals=np.zeros((len(pts), 3)))
    photos = [replace(p, photo=replace(p.photo, range_m=0.0)) for p in m.photos] if deaf else list(m.photos)
    return AdaptiveMission(m.robot, m.body, photos, rmap, m.config, np.random.default_rng(4), MissionObserver())


def test_a_goal_behind_a_wall_is_not_drawn(office):
    """Candidates the robot cannot drive to (outside a fence of map points around it,
    whatever the slice of the mesh says) are never goals; inside the fence they are."""
    m, _, _ = office
    inside = fenced(m, 1.6)
    goals, _, _ = inside.choose_goals()
    assert len(goals) and np.hypot(*(goals[:, :2] - m.body.est.pose[:2]).T).max() < 1.6


def test_no_goal_is_drawn_where_the_robot_would_touch_a_surface_the_ultrasonic_met(office, monkeypatch):
    """A robot centre within its radius of a surface cannot stand there: goals keep clear of
    the surfaces the ultrasonic met (apartment 2: goals 0.09-0.14 m from furniture the map
    lacked, each given up after five bumps). A surface met 0.1 m behind each frontier goal
    (in the free space the frontier borders) moves it, and no goal of the next choice lies
    that near one."""
    m, _, _ = office
    _, _, grid = m.choose_goals()
    first = m.frontier_goals(grid)
    assert len(first)
    sonar = m._sonar
    touch = first[:, :2] - 0.1 * np.c_[np.cos(first[:, 2]), np.sin(first[:, 2])]
    occupied = sonar.occupied.copy()
    occupied[sonar.cells(touch)] += 100
    walled = replace(sonar, occupied=occupied)
    monkeypatch.setattr(m, "sonar", lambda: walled)
    goals, _, grid = m.choose_goals()
    assert len(m.frontier_goals(grid)) and len(goals)
    clearance = m.config.robot_radius_m + np.sqrt(2) / 2 * walled.cell_m
    assert walled.surface_distance(goals[:, :2]).min() > clearance
    assert np.linalg.norm(goals[:, None, :2] - touch[None], axis=2).min() > clearance - walled.cell_m


def test_a_given_up_goal_is_not_drawn_again(office):
    m, _, _ = office
    goals, _, _ = m.choose_goals()
    m.given_up_goals = list(goals)
    try:
        again, _, _ = m.choose_goals()
        d = np.linalg.norm(again[:, None, :2] - goals[None, :, :2], axis=2)
        assert len(again) and d.min() >= m.config.goal_separation_m
    finally:
        m.given_up_goals = []


def test_the_far_goal_looks_across_the_room_and_is_not_taken_twice(office):
    """At the start (1.5 m from the office's south wall), facing north looks 6.4 m across
    the room, east 4.4 m, south 0.7 m: north is the far goal, then (once reached) east;
    a goal of the round with the same view rules north out as well. Off by default."""
    m, _, _ = office
    xy = np.array([p.camera.center[:2] for p in m.photos if p.camera is not None])
    free = free_space_from_mesh(m.map.mesh, m.cam_height, xy)
    north, east, south = (np.r_[START[:2], a] for a in (np.pi / 2, 0.0, -np.pi / 2))
    cand, none = np.array([south, east, north]), np.zeros((0, 3))
    assert m.config.far_goals_per_round == 0 and len(m.far_goals(cand, free, none)) == 0
    plain, reached = m.config, list(m.goals_reached)
    m.config = replace(plain, far_goals_per_round=1)
    try:
        goals, _, _ = m.choose_goals()  # with one far goal among the round's goals
        assert len(goals) >= 2
        assert m.far_goals(cand, free, none).tolist() == [north.tolist()]
        assert m.far_goals(cand, free, north[None] + [0.2, 0.0, 0.3]).tolist() == [east.tolist()]
        m.goals_reached.append(north)
        assert m.far_goals(cand, free, none).tolist() == [east.tolist()]
    finally:
        m.config, m.goals_reached = plain, reached


def test_a_mission_that_can_reach_no_goal_stops(office):
    """The robot fenced in tightly (and the spot inside given up before): no candidate is
    reachable, the adaptive stage stops at once with "no reachable goal" instead of giving
    goals up round after round."""
    from robot.mission.mission import MissionResult, adaptive_rounds

    m, _, _ = office
    trapped = fenced(m, 0.4)
    trapped.given_up_goals = [m.body.est.pose.copy()]  # the little room inside was tried before
    result = MissionResult(list(trapped.photos), trapped.map)
    n = len(trapped.photos)
    adaptive_rounds(trapped, result, photo_budget=n + 50)
    assert result.stopped_because == "no reachable goal" and result.rounds == 0
    assert len(trapped.photos) == n and trapped.given_up == 0


def penned_planner(m: AdaptiveMission):
    """(the mission fenced in 0.4 m around its estimate, the estimate xy, plan): plan() is the
    path from the estimate to a goal more than 1 m away on the fenced grid (None: none)."""
    est = m.body.est.pose[:2]
    pen = fenced(m, 0.4)
    goals, _, _ = m.choose_goals()
    far = goals[np.hypot(*(goals[:, :2] - est).T) > 1.0]
    assert len(far)
    grid = pen.nav_grid(shapely.Polygon([(-9, -9), (9, -9), (9, 9), (-9, 9)]))
    return pen, est, lambda: plan_path(pen._from_here(grid), est, far[0, :2], max_cost=m.config.max_path_cost)


def fence_crossing(path: np.ndarray, est: np.ndarray) -> np.ndarray:
    """Where the path (M, 2) first leaves the 0.4 m fence of `penned_planner` around `est`."""
    dense = np.concatenate([np.linspace(a, b, 50) for a, b in zip(path[:-1], path[1:])])
    return dense[np.argmax(np.hypot(*(dense - est).T) > 0.45)]


def test_after_a_side_step_the_way_back_is_open(office):
    """A stereo pair's side step that ended in cells the grid blocks (here: inside a fence of
    map points, the robot 0.6 m from where its plan brought it) leaves the drive back
    passable, and only that: from inside, the robot plans to goals outside through the gap,
    and without the side step on record nothing outside is reachable."""
    pen, est, plan = penned_planner(office[0])
    assert plan() is None
    pen.stepped_from = est + np.array([0.6, 0.0])  # it stood outside, then stepped in
    path = plan()
    assert path is not None
    assert pen._way_back(fence_crossing(path, est)[None])[0]  # out the way it came in
    back = pen._way_back(np.array([est + [0.4, 0.0], est + [-0.4, 0.0], est + [0.0, 0.4]]))
    assert back.tolist() == [True, False, False]  # the fence stays shut elsewhere


def test_the_robots_last_drives_stay_open(office):
    """A robot whose last drives ended in cells a rebuilt grid blocks (here: inside a fence of
    map points, after a recovery's two drives in from 0.8 m outside) plans out along those
    drives, and only there: without them on record nothing outside is reachable."""
    pen, est, plan = penned_planner(office[0])
    assert pen.trail == [] and plan() is None
    pen.trail = [np.array([est + [0.8, 0.0], est + [0.5, 0.1]]), np.array([est + [0.5, 0.1], est])]
    path = plan()
    assert path is not None
    assert pen._on_trail(fence_crossing(path, est)[None])[0]  # out the way it came in
    near = pen._on_trail(np.array([est + [0.4, 0.05], est + [-0.4, 0.0], est + [0.0, 0.4]]))
    assert near.tolist() == [True, False, False]  # the fence stays shut elsewhere


def test_space_driven_through_while_localised_stays_open(office, monkeypatch):
    """Where the robot drove, localised, a rebuilt grid stays passable (here: a fence of map
    points around it that it drove in through from 0.8 m outside): goals outside the fence
    are drawn and planned to again, through the drive. A drive made while the filter was
    lost is not kept (its estimate may lie anywhere within the spread)."""
    m, _, _ = office
    est = m.body.est.pose[:2]
    pen = fenced(m, 0.4)
    pen.swept = [np.array([est + [0.8, 0.0], est])]
    goals, _, grid = pen.choose_goals()
    far = goals[np.hypot(*(goals[:, :2] - est).T) > 1.0]
    assert len(far)
    path = plan_path(grid, est, far[0, :2], max_cost=m.config.max_path_cost)
    assert path is not None
    crossing = fence_crossing(path, est)
    assert abs(crossing[1] - est[1]) < m.config.robot_radius_m and crossing[0] > est[0]  # out the way it came in
    monkeypatch.setattr(pen, "lost", lambda: True)
    pen._drive(0.05)
    pen._drive(-0.05)
    assert len(pen.swept) == 1
    monkeypatch.setattr(pen, "lost", lambda: False)
    pen._drive(0.05)
    pen._drive(-0.05)
    assert len(pen.swept) == 3


def test_a_diagonal_drive_stays_open_on_a_coarse_grid(office):
    """On a grid whose cells are wider than half the robot's radius (a large explored area),
    a drive made localised across blocked cells at 45 degrees is still a way A* can take:
    the cells it crosses touch only at their corners, which A* does not cut."""
    from explore.nav_grid import NavGrid

    m, _, _ = office
    cost = np.full((20, 20), np.inf)
    grid = NavGrid(np.zeros(2), 0.2, np.zeros_like(cost), cost)
    swept = m.swept
    m.swept = [np.array([[0.3, 0.3], [3.5, 3.5]])]
    try:
        opened = m._swept_open(grid)
    finally:
        m.swept = swept
    assert plan_path(opened, (0.3, 0.3), (3.5, 3.5), max_cost=m.config.max_path_cost) is not None
    assert np.isinf(opened.cost[0, 19]) and np.isinf(opened.cost[19, 0])  # only along the drive


def test_the_ultrasonic_outranks_stray_map_points(office):
    """Map points the ultrasonic's readings contradict (the fence of `fenced`, where the real
    office is empty) make the grid dear, not blocked: the robot is not trapped by them."""
    m, _, _ = office
    heard = fenced(m, 0.4, deaf=False)
    goals, _, grid = heard.choose_goals()
    far = goals[np.hypot(*(goals[:, :2] - m.body.est.pose[:2]).T) > 0.6]
    assert len(far) and plan_path(heard._from_here(grid), m.body.est.pose[:2], far[0, :2],
                                  max_cost=m.config.max_path_cost) is not None


def test_a_goal_given_up_rules_out_its_cells_not_its_frontier(office):
    """A frontier whose goal was given up still gets a goal, at its cells away from the one
    given up (apartment 7: the kitchen door and the corridor's far end were one frontier)."""
    m, _, _ = office
    _, _, grid = m.choose_goals()
    first = m.frontier_goals(grid)[0]
    cells = next(f for f in frontiers(m._sonar, 2 * m.config.robot_radius_m)
                 if np.linalg.norm(f - first[:2], axis=1).min() < 1e-9)
    assert np.linalg.norm(cells - first[:2], axis=1).max() > m.config.goal_separation_m  # room for another
    m.given_up_goals.append(first.copy())
    try:
        again = m.frontier_goals(grid)
    finally:
        m.given_up_goals.pop()
    on_it = [g for g in again if np.linalg.norm(cells - g[:2], axis=1).min() < 1e-9]
    assert len(on_it) == 1
    assert np.hypot(*(on_it[0][:2] - first[:2])) >= m.config.goal_separation_m


def test_a_frontier_sweep_reads_a_full_circle_into_the_ultrasonics_grid(office):
    """`sweep_ultrasonic` (`sweep_frontiers` on): one reading per cone width round the
    circle, each kept for the ultrasonic's grid, which then knows every cell they reached
    (the office's sweep is open some way: they teach it something); the robot does not
    move. With `sweep_frontiers` off (the default) nothing is read."""
    m, robot, _ = office
    m.choose_goals()
    before, n0, kept = m.sonar(), len(m.sonar_readings), m.config
    where = robot.true_pose[:2].copy()
    try:
        m.config = replace(kept, sweep_frontiers=True)
        taught = m.sweep_ultrasonic()
        sweep = np.array(m.sonar_readings[n0:])
        assert len(sweep) == int(np.ceil(np.pi / m.config.sonar.half_cone_rad))
        step = 2 * m.config.sonar.half_cone_rad
        turns = np.diff(np.unwrap(sweep[:, 2]))  # the estimate's, with the compass's noise
        assert (turns > step / 2).all() and (turns < 3 * step / 2).all()
        assert abs(turns.sum() - step * len(turns)) < np.radians(10)
        assert taught == sum(revealed(before, r[:3], r[3], m.config.sonar) for r in sweep) > 0
        assert (~m.sonar().unknown_mask).sum() > (~before.unknown_mask).sum()
        assert np.allclose(robot.true_pose[:2], where)
        m.config = kept
        assert m.sweep_ultrasonic() == 0 and len(m.sonar_readings) == n0 + len(sweep)
    finally:
        m.config = kept
        del m.sonar_readings[n0:]


def committed(m: AdaptiveMission, robot: SimRobot, tmp_path, key: str) -> list[np.ndarray]:
    """The mission's list `key` as a round's commit (`SessionJournal.round_done`) holds it
    and a resumed mission reads it back (`mission._resume_adaptive`)."""
    from robot.mission.journal import SessionJournal
    from robot.mission.mission import MissionResult
    from robot.session import CaptureSession

    with CaptureSession.create(tmp_path / "s", robot.intrinsics, robot.image_size, robot.cam_from_robot) as s:
        SessionJournal(s, robot, replayable=True).round_done(m, MissionResult(m.photos, m.map, rounds=1))
    return [np.asarray(r, float) for r in CaptureSession.open(tmp_path / "s").last_commit["state"][key]]


def test_the_sweeps_readings_are_committed_with_the_round(office, tmp_path):
    """A round's commit holds the readings taken without a photo, as a resumed mission reads them back."""
    m, robot, _ = office
    n0 = len(m.sonar_readings)
    m.sonar_readings += [np.array([0.5, -1.0, 0.3, 1.27]), np.array([0.5, -1.0, 0.65, 2.55])]
    try:
        back = committed(m, robot, tmp_path, "sonar_readings")
        assert len(back) == len(m.sonar_readings) and all(np.array_equal(a, b) for a, b in zip(back, m.sonar_readings))
    finally:
        del m.sonar_readings[n0:]


def test_the_space_driven_through_is_committed_with_the_round(office, tmp_path):
    """A round's commit holds the drives made while localised (`swept`), as a resumed
    mission reads them back: its grids stay open there too."""
    m, robot, _ = office
    swept = m.swept
    m.swept = [*swept, np.array([[0.5, -1.0], [0.9, -0.8]])]
    try:
        back = committed(m, robot, tmp_path, "swept")
        assert len(back) == len(m.swept) and all(np.array_equal(a, b) for a, b in zip(back, m.swept))
    finally:
        m.swept = swept


def test_points_in_the_open_room_are_seen_through_and_points_on_its_surfaces_are_not(office):
    """`seen_through`, the check of a re-posing's new points: a point on the room's surfaces
    lies behind what the photos saw; one in the open room, at the camera's height, in front."""
    m, robot, _ = office
    m.choose_goals()
    rng = np.random.default_rng(5)
    on_surfaces = surface_samples(robot.world.mesh, 1000, rng).points
    in_the_open = sample_candidates(robot.world.free_space, 1000, rng, 0.3)[:, :2]
    assert m.seen_through(on_surfaces) < 0.1
    assert m.seen_through(np.c_[in_the_open, np.full(len(in_the_open), m.cam_height)]) > 0.5
    assert m.seen_through(np.zeros((0, 3))) == 0.0


def test_an_unlocalised_robot_is_sent_to_no_frontier(office):
    """Frontier goals lead where the map has no points to fix the pose by; the robot takes
    them only while its filter's spread is within `relocalise_std_m`."""
    m, _, _ = office
    _, _, grid = m.choose_goals()
    assert len(m.frontier_goals(grid)) >= 1
    est = m.body.est
    particles, log_w = est.pf.particles.copy(), est.pf.log_w.copy()
    try:
        spread = particles + np.c_[np.random.default_rng(0).normal(0, 0.6, (len(particles), 2)), np.zeros(len(particles))]
        est.set_particles(spread, np.zeros(len(spread)))
        assert est.spread_m > m.config.filter.relocalise_std_m
        assert len(m.frontier_goals(grid)) == 0
    finally:
        est.set_particles(particles, log_w)


def test_a_fix_tilted_out_of_level_is_rejected(office, monkeypatch):
    """The robot's camera is level: a PnP pose at the right place and heading but pitched by
    2 degrees (beyond `max_fix_tilt_px`, 1.2 degrees at this focal length) is a wrong fix
    (their tilt gave away wrong fixes 0.15-2.8 m off in an apartment); the level one passes."""
    from localization.feature_localizer import PnPResult
    from scipy.spatial.transform import Rotation

    m, robot, _ = office
    true = robot_camera(robot.true_pose, robot.intrinsics, robot.image_size, robot.cam_from_robot)
    pitched = true.cam_from_world.copy()
    pitched[:3, :3] = Rotation.from_euler("x", 2.0, degrees=True).as_matrix() @ pitched[:3, :3]
    pitched[:3, 3] = -pitched[:3, :3] @ true.center  # the same camera centre
    for T, accepted in ((true.cam_from_world, True), (pitched, False)):
        monkeypatch.setattr(m.fmap, "localize", lambda image, template, tilts=None, T=T: PnPResult(T, 40, 30, true.with_pose(T)))
        fixes, tilted = m.fixes, m.failure_reasons["tilt"]
        assert (m.localise_photo(robot.capture()) is not None) == accepted
        assert m.fixes == fixes + accepted
        assert m.failure_reasons["tilt"] == tilted + (not accepted)


def test_a_fix_turned_from_the_compass_held_heading_is_rejected(office, monkeypatch):
    """The compass holds the filter's heading: a PnP pose at the estimate's place but turned
    12 degrees from its heading (beyond `max_fix_turn_deg`) is a wrong fix (apartment 6's
    drift began with fixes turned 14-21 degrees), counted under "heading", however wide the
    particles' headings spread; one turned 3 degrees passes. Without the compass, the
    filter's heading spread widens the gate."""
    from localization.feature_localizer import PnPResult

    m, robot, _ = office
    no_compass = replace(m.config, filter=replace(m.config.filter, compass_sigma_rad=0.0))
    wide = np.radians(6.0)
    for turn_deg, spread, config, accepted in ((3.0, 0.0, m.config, True), (12.0, 0.0, m.config, False),
                                               (12.0, wide, m.config, False), (12.0, wide, no_compass, True)):
        pose = m.body.est.pose + [0.0, 0.0, np.radians(turn_deg)]
        cam = robot_camera(pose, robot.intrinsics, robot.image_size, robot.cam_from_robot)
        fix = PnPResult(cam.cam_from_world, 40, 30, cam)
        monkeypatch.setattr(m.fmap, "localize", lambda image, template, tilts=None, fix=fix: fix)
        monkeypatch.setattr(m, "heading_spread", lambda spread=spread: spread)
        monkeypatch.setattr(m, "config", config)
        turned = m.failure_reasons["heading"]
        assert (m.localise_photo(robot.capture()) is not None) == accepted
        assert m.failure_reasons["heading"] == turned + (not accepted)


def test_a_failed_fix_is_counted_by_its_reason(office, monkeypatch):
    """No PnP pose, a camera at the wrong height, a pose far from the estimate: each failed
    fix is counted under its own reason, so a mission's report tells a map that posed
    nothing from checks that threw poses away."""
    from localization.feature_localizer import PnPResult

    m, robot, _ = office
    true = robot_camera(robot.true_pose, robot.intrinsics, robot.image_size, robot.cam_from_robot)
    raised = true.with_pose(true.cam_from_world @ np.linalg.inv(np.r_[np.c_[np.eye(3), [0, 0, 0.3]], [[0, 0, 0, 1]]]))
    moved = robot_camera(robot.true_pose + [3.0, 0.0, 0.0], robot.intrinsics, robot.image_size, robot.cam_from_robot)
    assert abs(raised.center[2] - true.center[2] - 0.3) < 1e-9
    for res, reason in ((None, "no pose"), (PnPResult(raised.cam_from_world, 40, 30, raised), "height"),
                        (PnPResult(moved.cam_from_world, 40, 30, moved), "jump")):
        monkeypatch.setattr(m.fmap, "localize", lambda image, template, tilts=None, res=res: res)
        before, failed = dict(m.failure_reasons), m.failed
        assert m.localise_photo(robot.capture()) is None
        assert m.failed == failed + 1
        assert m.failure_reasons == {**before, reason: before[reason] + 1}


def test_a_fix_that_jumps_past_a_confident_filter_is_refused(office, monkeypatch):
    """A pose 0.4 m from the estimate is refused while the filter's spread is 5 cm (past both
    `max_fix_jump_m` and 3 spreads), believed once the filter is lost (a spread of 0.3 m)."""
    from localization.feature_localizer import PnPResult

    m, robot, _ = office
    moved = robot_camera(m.body.est.pose + [0.4, 0.0, 0.0], robot.intrinsics, robot.image_size, robot.cam_from_robot)
    fix = PnPResult(moved.cam_from_world, 40, 30, moved)
    monkeypatch.setattr(m.fmap, "localize", lambda image, template, tilts=None: fix)
    for spread, believed in ((0.05, False), (0.3, True)):
        monkeypatch.setattr(m, "spread", lambda spread=spread: spread)
        assert (m.localise_photo(robot.capture()) is not None) == believed


def test_a_fix_that_relocalises_a_lost_filter_moves_it_but_seeds_no_track(office, monkeypatch):
    """Lost (spread above `relocalise_std_m`), a fix is the filter's measurement, but its goal
    photo is posed at the estimate and kept out of the tracks (`unfixed`), and its localise
    photo gets no pose; localised, the same fix poses both."""
    from localization.feature_localizer import PnPResult

    m, robot, _ = office
    here = robot_camera(m.body.est.pose, robot.intrinsics, robot.image_size, robot.cam_from_robot)
    fix = PnPResult(here.cam_from_world, 40, 30, here, None, points_in_view(here, 1.0, 1.0))
    monkeypatch.setattr(m.fmap, "localize", lambda image, template, tilts=None: fix)
    for spread, seeds in ((m.config.filter.relocalise_std_m + 0.1, False), (0.0, True)):
        monkeypatch.setattr(m, "spread", lambda spread=spread: spread)
        fixes, n = m.fixes, len(m.photos)
        goal, look = m.take_photo("goal"), m.take_photo("localise")
        assert m.fixes == fixes + 2
        assert (n in m.unfixed) != seeds and goal.camera is not None
        assert (look.camera is not None) == seeds


def points_in_view(cam, depth_m: float, share: float, n: int = 30) -> np.ndarray:
    """(n, 3) world points `depth_m` in front of `cam` over the central `share` of its image."""
    rng = np.random.default_rng(0)
    uv = np.c_[cam.width, cam.height] * (0.5 + share * rng.uniform(-0.5, 0.5, (n, 2)))
    rays = np.c_[uv, np.ones(n)] @ np.linalg.inv(cam.K).T
    return (depth_m * rays) @ cam.world_from_cam[:3, :3].T + cam.center


def test_a_fix_its_map_points_could_move_far_moves_the_filter_but_poses_no_photo(office, monkeypatch):
    """With `--precise-seeds`, localised, a fix whose inliers lie in a far, narrow patch (a
    shared pixel of their error moves it beyond `max_seed_m_per_px`) is the filter's
    measurement, but its goal photo is posed at the estimate (`unfixed`) and its localise
    photo gets no pose, and it is counted in `weak_fixes`; the same fix on near points
    spread over the view poses both, and so does the far one without the flag."""
    from localization.feature_localizer import PnPResult
    from robot.mission.adaptive import PRECISE_SEEDS_M_PER_PX

    m, robot, _ = office
    monkeypatch.setattr(m, "spread", lambda: 0.0)
    # the fixture is shared: the photos go to copies, the camera gives the last photo again (its
    # noise draws untouched), the filter's measurements are recorded, not made (a later test
    # places surfaces by the estimate, on a grid over the photos' poses)
    for name in ("photos", "unfixed", "_last_view"):
        monkeypatch.setattr(m, name, copy.copy(getattr(m, name)))
    monkeypatch.setattr(m.robot, "capture", lambda photo=m.photos[-1].photo: photo)
    measured = []
    monkeypatch.setattr(m.body.est, "update_pnp", lambda pose, n_inliers: measured.append(pose))
    precise = replace(m.config, max_seed_m_per_px=PRECISE_SEEDS_M_PER_PX)
    moved = m.body.est.pose + [0.03, 0.0, 0.0]
    there = robot_camera(moved, robot.intrinsics, robot.image_size, robot.cam_from_robot)
    for depth, share, config, seeds in ((6.0, 0.1, precise, False), (1.0, 1.0, precise, True),
                                        (6.0, 0.1, m.config, True)):
        monkeypatch.setattr(m, "config", config)
        fix = PnPResult(there.cam_from_world, 40, 30, there, None, points_in_view(there, depth, share))
        monkeypatch.setattr(m.fmap, "localize", lambda image, template, tilts=None, fix=fix: fix)
        weak, n = m.weak_fixes, len(m.photos)
        measured.clear()
        goal, look = m.take_photo("goal"), m.take_photo("localise")
        assert m.weak_fixes == weak + 2 * (not seeds)
        assert (n in m.unfixed) != seeds and (look.camera is not None) == seeds
        assert len(measured) == 2 and all(np.allclose(p, moved, atol=1e-6) for p in measured)


def test_a_photo_plain_sift_cannot_fix_is_tried_again_at_simulated_tilts(office, monkeypatch):
    """PnP with plain SIFT finds no pose; the same photo described at `retry_tilts` is fixed,
    counted as a fix and as a tilted one. A retry that also fails counts one failure."""
    from localization.feature_localizer import PnPResult

    from robot.mission.adaptive import ASIFT_TILTS

    m, robot, _ = office
    true = robot_camera(robot.true_pose, robot.intrinsics, robot.image_size, robot.cam_from_robot)
    calls = []
    monkeypatch.setattr(m, "config", replace(m.config, retry_tilts=ASIFT_TILTS))

    def localize(image, template, tilts=None, found=True):
        calls.append(tuple(tilts))
        return PnPResult(true.cam_from_world, 40, 30, true) if found and tilts != (1.0,) else None

    monkeypatch.setattr(m.fmap, "localize", localize)
    fixes, tilted, failed = m.fixes, m.tilted_fixes, m.failed
    assert m.localise_photo(robot.capture()) is not None
    assert calls == [(1.0,), ASIFT_TILTS]
    assert (m.fixes, m.tilted_fixes, m.failed) == (fixes + 1, tilted + 1, failed)
    monkeypatch.setattr(m.fmap, "localize", lambda image, template, tilts=None: localize(image, template, tilts, False))
    assert m.localise_photo(robot.capture()) is None
    assert (m.fixes, m.tilted_fixes, m.failed) == (fixes + 1, tilted + 1, failed + 1)
    monkeypatch.setattr(m, "config", replace(m.config, retry_tilts=()))  # --no-retry-tilts: plain SIFT only
    calls.clear()
    assert m.localise_photo(robot.capture()) is None and calls == [(1.0,)]


def test_fixed_localise_photos_join_the_localisers_tracks_not_the_map(office):
    """Localise photos a fix posed add their tracks to what PnP matches against at the next
    rebuild, even with no new model photo; the map's points (mesh, grid) stay the model's."""
    m, robot, _ = office
    n_map, n_tracks, start = len(m.map.points), len(m.tracks.points), len(m.photos)
    for _ in range(4):
        m.body.move(turn=np.pi / 2)
        m.localise_here()
    fixed = [i for i in range(start, len(m.photos)) if m.photos[i].camera is not None]
    assert fixed and all(m.photos[i].stage == "localise" for i in fixed)
    m.rebuild([])
    assert len(m.map.points) == n_map
    assert len(m.tracks.points) > n_tracks and len(m.fmap) == len(m.tracks.points)
    n = len(m.tracks.points)
    m.rebuild([])  # nothing new since: nothing added twice
    assert len(m.tracks.points) == n


def test_a_fixed_goal_photo_joins_the_tracks_after_its_goal_and_the_map_at_the_rebuild(office):
    """`grow_tracks` (after every goal) puts the photos fixed since its last call into what
    PnP matches against; the round's rebuild meshes the goal photos' tracks, adding none twice."""
    m, robot, _ = office
    m.rebuild([])
    n_map, n_tracks = len(m.map.points), len(m.tracks.points)
    here = m.body.est.pose
    nearest = min(m._map_cameras().values(), key=lambda c: np.hypot(*(c.center[:2] - here[:2])))
    f = nearest.world_from_cam[:3, 2]  # a heading a map photo looked along, near where the robot stands
    shots = m.capture_at(np.r_[here[:2], np.arctan2(f[1], f[0])], budget=2)
    assert [i for i, p in enumerate(m.photos) if any(p is q for q in shots) and i not in m.unfixed]
    m.grow_tracks()
    meshed = len(m._mesh_tracks.points)
    assert meshed > 0 and len(m.tracks.points) >= n_tracks + meshed and len(m.fmap) == len(m.tracks.points)
    assert len(m.map.points) == n_map  # the mesh waits for the round's end
    n = len(m.tracks.points)
    m.rebuild(shots)
    assert n_map < len(m.map.points) <= n_map + meshed and len(m.tracks.points) == n  # the mesh drops a few


def test_the_rebuild_adjusts_the_fixed_photos_and_triangulates_the_tracks_again(office, monkeypatch):
    """With `bundle` on, the rebuild adjusts the photos the fixes posed (the random stage's, on
    their true poses here, held; `test_bundle` measures the gain), writes them into the map,
    and makes the localiser's tracks again on them; nothing new since: no second adjustment."""
    m, robot, _ = office
    monkeypatch.setattr(m, "config", replace(m.config, bundle=BundleConfig()))
    m.rebuild([])
    here = m.body.est.pose
    for turn in (0.0, np.pi / 2, np.pi, -np.pi / 2):
        shots = m.capture_at(np.r_[here[:2], here[2] + turn], budget=2)
    grown = [i for i, p in enumerate(m.photos) if p.stage != "random" and p.camera is not None and i not in m.unfixed]
    before = {i: m.photos[i].camera for i in grown}
    m.rebuild(shots)
    truth = {int(t["index"]): t["pose"] for t in robot.truth}
    err = {i: np.linalg.norm(c.center - robot_camera(truth[m.photos[i].photo.index], robot.intrinsics,
                                                     robot.image_size, robot.cam_from_robot).center)
           for i, c in before.items()}
    moved = [i for i in grown if np.linalg.norm(m.photos[i].camera.center - before[i].center) > 1e-6]
    assert moved and all(m.photos[i].stage != "random" for i in moved)
    after = [np.linalg.norm(m.photos[i].camera.center - robot_camera(truth[m.photos[i].photo.index], robot.intrinsics,
                            robot.image_size, robot.cam_from_robot).center) for i in moved]
    assert max(after) < max(0.02, max(err.values()))  # fixes on the true mesh's points are right to mm: no drift
    assert all(m.map.cameras[i] is m.photos[i].camera for i in moved if i in m.map.cameras)
    assert len(m.tracks.points) == len(m._localiser_tracks().points) == len(m.fmap)
    cams = {i: m.photos[i].camera for i in moved}
    m.rebuild([])
    assert all(m.photos[i].camera is cams[i] for i in moved)


def test_bumps_of_earlier_goals_are_dear_not_walls(office):
    """Contacts marked on the way to earlier goals (a ring of them around the robot, as
    misplaced marks can seal a doorway) make the grid dear: goals beyond them are still
    drawn and planned to. As walls (the goal being tried treats its own bumps so), they
    would cut the robot off (its last drives and side step forgotten: the earlier tests'
    drives, which cross the ring, would stay open, `_on_trail`, `_way_back`)."""
    m, _, _ = office
    est = m.body.est.pose[:2]
    a = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    trail, stepped_from = m.trail, m.stepped_from
    m.bumps, m.trail, m.stepped_from = list(est + 0.6 * np.c_[np.cos(a), np.sin(a)]), [], None
    try:
        goals, _, grid = m.choose_goals()
        far = goals[np.hypot(*(goals[:, :2] - est).T) > 0.8]
        assert len(far)
        assert plan_path(m._from_here(grid), est, far[0, :2], max_cost=m.config.max_path_cost) is not None
        walls = m._with_bumps(grid, m.bumps)
        assert plan_path(m._from_here(walls), est, far[0, :2], max_cost=m.config.max_path_cost) is None
    finally:
        m.bumps, m.trail, m.stepped_from = [], trail, stepped_from


def test_a_localise_photo_first_turns_to_the_map(office):
    """Turned to the heading whose view holds the fewest matchable map points, the robot
    turns to the one with the most before its localise photo, and PnP finds its pose there
    (whether the mission accepts the fix is its checks' business)."""
    m, robot, _ = office
    pose = m.body.est.pose
    headings, counts = heading_counts(pose, m.tracks.points, m.tracks.seen_from, robot.intrinsics,
                                      robot.image_size, robot.cam_from_robot, m.config.look)
    assert counts.max() > m.config.look.min_gain * counts.min()  # a turn is worth it
    m._face(headings[np.argmin(counts)])
    m._last_view = None
    n, k = len(robot.truth), len(m.photos)
    m.localise_here()
    taken = robot.truth[n]["pose"]  # the first photo after the turn
    _, seen = heading_counts(taken, m.tracks.points, m.tracks.seen_from, robot.intrinsics,
                             robot.image_size, robot.cam_from_robot, m.config.look)
    assert seen[0] > 0.5 * counts.max()  # it looks where the most points are, give or take a step
    res = m.fmap.localize(m.photos[k].photo.image, m.template)
    assert res is not None and res.n_inliers >= m.config.localizer.min_inliers
    truth = robot_camera(taken, robot.intrinsics, robot.image_size, robot.cam_from_robot)
    assert np.linalg.norm(res.camera.center - truth.center) < 0.1


def test_a_lower_sift_contrast_threshold_localises_on_faint_paint():
    """The office with its textures at a fifth of their contrast (the faint walls a 320 x 240
    photo of a room often shows), the mission's PnP map of 24 photos and 8 photos between
    them: at OpenCV's default SIFT contrast threshold (0.04) none is localised; at the
    mission's 0.02, threaded through both the map's and the query's features, every one
    is, within 3 cm."""
    scene = load_scene("synthetic:office?views=48&width=320&height=240")
    faint = replace(scene, views=[replace(v, image=(v.image * 0.2 + 128 * 0.8).astype(np.uint8))
                                  for v in scene.views])
    mission_cfg = AdaptiveConfig().localizer
    assert mission_cfg.triangulation.contrast_threshold == 0.02
    for threshold, expect in ((0.04, False), (0.02, True)):
        cfg = replace(mission_cfg, triangulation=replace(mission_cfg.triangulation, contrast_threshold=threshold))
        fmap = FeatureMap.from_scene(faint, cfg, exclude=[v.name for v in faint.views[1::2]])
        for v in faint.views[1::2][::3]:
            res = fmap.localize(v.image, v.camera.with_pose(np.eye(4)))
            assert (res is not None) == expect, (threshold, v.name)
            if res is not None:
                assert pose_errors(res.cam_from_world, v.camera.cam_from_world)[0] < 0.03


def walled_sonar(m: AdaptiveMission, a: np.ndarray, b: np.ndarray, alone: bool = False):
    """The mission's ultrasonic grid with a surface met all along the segment a-b (2,) (m);
    `alone`: that surface only."""
    sonar = m.sonar()
    occupied = np.zeros_like(sonar.occupied) if alone else sonar.occupied.copy()
    line = a + np.linspace(0, 1, 60)[:, None] * (b - a)
    occupied[sonar.cells(line)] += 100
    return replace(sonar, occupied=occupied, free=np.zeros_like(sonar.free) if alone else sonar.free)


def test_paths_keep_off_the_surfaces_the_ultrasonic_met(monkeypatch):
    """With `keep_off_surfaces`, where the ultrasonic met a surface the map has no point of
    (a plain wall, a bed's side: on apartment 5, 45 of 50 bumps on a planned drive), the
    grid's cells where the robot would touch it are dear: a wall of such surfaces across the
    way to a goal, 1.2 m long, is gone round; off (the default), the plan crosses where it
    stands. (A mission of its own: where the module's has driven to, a wall there is not
    always one a detour can clear.)"""
    m, _, _ = mission()
    m.config = replace(m.config, keep_off_surfaces=True)
    goals, _, grid = m.choose_goals()
    est = m.body.est.pose[:2]
    far = goals[np.hypot(*(goals[:, :2] - est).T) > 1.5]
    assert len(far)
    path = plan_path(m._from_here(grid), est, far[0, :2], max_cost=m.config.max_path_cost)
    dense = np.concatenate([np.linspace(p, q, 50) for p, q in zip(path[:-1], path[1:])])
    mid = dense[np.argmin(np.abs(np.hypot(*(dense - est).T) - 0.8))]  # where the plan is 0.8 m out
    d = (mid - est) / np.hypot(*(mid - est))
    across = np.array([-d[1], d[0]])
    walled = walled_sonar(m, mid - 0.6 * across, mid + 0.6 * across)
    wall = walled_sonar(m, mid - 0.6 * across, mid + 0.6 * across, alone=True)
    reach = m.config.robot_radius_m + np.sqrt(2) / 2 * wall.cell_m  # as `clear_of_surfaces`
    assert wall.surface_distance(dense).min() < reach  # the old plan would touch the wall
    monkeypatch.setattr(m, "sonar", lambda: walled)
    monkeypatch.setattr(m, "_sonar", walled)
    # the relaxed grid: the strict one also blocks what the photos saw only through the wall
    free = free_space_from_mesh(m.map.mesh, m.cam_height, est[None])
    grid = m.nav_grid(free, strict=False)
    path = plan_path(m._from_here(grid), est, far[0, :2], max_cost=m.config.max_path_cost)
    assert path is not None
    dense = np.concatenate([np.linspace(p, q, 50) for p, q in zip(path[:-1], path[1:])])
    assert wall.surface_distance(dense).min() > reach
    m.config = replace(m.config, keep_off_surfaces=False)  # the default: only the goals keep off
    grid = m.nav_grid(free, strict=False)
    path = plan_path(m._from_here(grid), est, far[0, :2], max_cost=m.config.max_path_cost)
    dense = np.concatenate([np.linspace(p, q, 50) for p, q in zip(path[:-1], path[1:])])
    assert wall.surface_distance(dense).min() < reach


def test_a_side_step_turns_to_the_side_clear_of_the_ultrasonics_surfaces(office, monkeypatch):
    """With `keep_off_surfaces`, a stereo pair's side step, and a recovery's drive off the
    path, go to the side whose drive keeps clear of the surfaces the ultrasonic met (office 0:
    12 of 15 side steps that bumped went toward one); the drawn side when both or neither are
    clear."""
    m, _, _ = office
    monkeypatch.setattr(m, "config", replace(m.config, keep_off_surfaces=True))
    est = m.body.est.pose.copy()
    left, right = est[2] + np.pi / 2, est[2] - np.pi / 2

    def beside(h: float):  # a surface 0.6 m long, 0.35 m to the side h of the robot
        side, along = np.array([np.cos(h), np.sin(h)]), np.array([np.cos(est[2]), np.sin(est[2])])
        return walled_sonar(m, est[:2] + 0.35 * side - 0.3 * along, est[:2] + 0.35 * side + 0.3 * along, alone=True)

    monkeypatch.setattr(m, "_sonar", beside(left))
    assert m._flip_side(left, right, 0.6) and not m._flip_side(right, left, 0.6)
    assert not m._flip_side(left, right, 0.1)  # a short drive stays clear of it
    m._sonar = replace(m._sonar, occupied=m._sonar.occupied + beside(right).occupied)
    assert not m._flip_side(left, right, 0.6) and not m._flip_side(right, left, 0.6)  # neither clear
    m._sonar = beside(left)
    faced = []
    monkeypatch.setattr(m, "_face", faced.append)
    monkeypatch.setattr(m, "take_photo", lambda stage: None)
    monkeypatch.setattr(m, "localise_here", lambda: None)
    monkeypatch.setattr(m, "_drive", lambda d: MotionResult(np.zeros(3)))
    m.capture_at(est, budget=2)
    assert faced == pytest.approx([est[2], right, est[2]])  # the side step went right, away from the surface
    m.config, faced[:] = replace(m.config, keep_off_surfaces=False), []
    m.capture_at(est, budget=2)
    assert faced == pytest.approx([est[2], left, est[2]])  # off (the default): always to the left
