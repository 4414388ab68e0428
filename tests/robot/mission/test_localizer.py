"""The mission's particle filter (robot.mission.localizer) while a simulated robot follows a
path on the filter's own estimate: PnP-like fixes at the waypoints (the true pose plus known
noise; every third one fails), odometry and compass between them."""

import numpy as np

from ibr.synthetic import loop_route, make_world
from localization.motion_models import wrap_angle
from robot.mission.localizer import FilteredBody, MissionFilterConfig, MissionLocalizer
from robot.sim_robot import SimRobot, SimRobotConfig


def follow(seed: int):
    world = make_world("office", 0)
    route = loop_route(world)
    start = np.array([*route[0], 0.0])
    robot = SimRobot(world, SimRobotConfig(image_size=(24, 16), alphas=(0.03, 0.003, 0.06, 0.003)),
                     np.random.default_rng(seed), start_pose=tuple(start))
    rng = np.random.default_rng(seed + 100)
    loc = MissionLocalizer(start, route, MissionFilterConfig(), rng, np.array([0.05, 0.05, 0.02]))
    body = FilteredBody(robot, loc)
    errors, spreads = [], []
    for lap in range(2):
        for k, wp in enumerate(np.r_[route[1:], route[:1]]):
            for _ in range(8):  # legs of at most 0.6 m, re-aimed on the estimate
                d = wp - body.est.pose[:2]
                if np.hypot(*d) < 0.2:
                    break
                body.move(turn=float(wrap_angle(np.arctan2(d[1], d[0]) - body.est.pose[2])))
                body.move(drive=float(min(0.6, np.hypot(*d))))
            spreads.append(loc.spread_m)
            fixed = (k + lap) % 3 != 2
            if fixed:  # a PnP fix: the true pose with 5 cm / 1 degree noise, 60 inliers
                fix = robot.true_pose + rng.normal(size=3) * [0.05, 0.05, np.radians(1)]
                loc.update_pnp(fix, 60)
            errors.append((fixed, np.hypot(*(loc.pose[:2] - robot.true_pose[:2])),
                           np.hypot(*(loc.dead_reckoning.pose[:2] - robot.true_pose[:2]))))
    return np.array(errors), np.array(spreads), body


def test_filter_tracks_the_path_and_beats_dead_reckoning():
    for seed in (0, 1):
        errors, spreads, body = follow(seed)
        assert body.path_m > 30  # two laps of the office loop
        fixed, err, dr = errors[:, 0] == 1, errors[:, 1], errors[:, 2]
        assert err[fixed].max() < 0.15, err  # after a fix: within 15 cm of the truth
        assert err[~fixed].max() < 0.5, err  # ~5 m on odometry alone since the last fix
        assert err.mean() < 0.5 * dr.mean(), errors.mean(0)  # dead reckoning drifts
        assert spreads.max() > 2 * spreads.min()  # the spread grows on odometry and shrinks at fixes


def test_pnp_fix_pulls_a_wrong_estimate_back():
    """A prior 0.6 m off: the mixture proposal's particles around the fix take over."""
    rng = np.random.default_rng(3)
    loc = MissionLocalizer(np.array([0.6, 0.0, 0.0]), np.zeros((1, 2)), MissionFilterConfig(), rng,
                           np.array([0.05, 0.05, 0.02]))
    for _ in range(2):
        loc.update_pnp(np.array([0.0, 0.0, 0.05]), 100)
    assert np.hypot(*loc.pose[:2]) < 0.1 and abs(loc.pose[2] - 0.05) < np.radians(3)


def drive_east(loc: MissionLocalizer, metres: float) -> None:
    """Odometry of `metres` straight east in 0.5 m moves, compass 0."""
    for x in np.arange(0.0, metres, 0.5):
        loc.predict(np.array([x, 0.0, 0.0]), np.array([x + 0.5, 0.0, 0.0]), 0.0)


def test_grown_prior_keeps_the_track_beyond_the_first_box():
    """The box prior is the start +- 3 m: driving 5 m east leaves it and the filter restarts
    uniformly unless the prior was grown to where the robot is sent."""
    start, std = np.zeros(3), np.array([0.05, 0.05, 0.02])
    lost = MissionLocalizer(start, np.zeros((1, 2)), MissionFilterConfig(), np.random.default_rng(0), std)
    drive_east(lost, 5.0)
    kept = MissionLocalizer(start, np.zeros((1, 2)), MissionFilterConfig(), np.random.default_rng(0), std)
    kept.grow_prior(np.array([[0.0, 0.0], [5.0, 0.0]]))
    drive_east(kept, 5.0)
    assert np.hypot(kept.pose[0] - 5.0, kept.pose[1]) < 0.3 and kept.spread_m < 0.5
    assert np.hypot(lost.pose[0] - 5.0, lost.pose[1]) > 1.0 and lost.spread_m > 1.0


def test_a_fix_outside_the_prior_particles_moves_the_estimate_as_bayes_says():
    """Prior 0.2 m off with a 5 cm spread (its particles barely reach the fix), a fix with
    100 inliers (sigma 2.5 cm): the posterior of two Gaussians, belief widened by 5 cm,
    lies 2.2 cm from the fix. Per-part weights mixed 80:20 had left the estimate 8 cm off."""
    errs = []
    for seed in range(4):
        loc = MissionLocalizer(np.array([0.2, 0.0, 0.0]), np.zeros((1, 2)), MissionFilterConfig(),
                               np.random.default_rng(seed), np.array([0.05, 0.05, 0.02]))
        loc.update_pnp(np.zeros(3), 100)
        errs.append(np.hypot(*loc.pose[:2]))
    s2, p2 = 0.025 ** 2, 0.05 ** 2 + 0.05 ** 2
    assert abs(np.mean(errs) - 0.2 * s2 / (s2 + p2)) < 0.02, errs


def test_turning_in_place_leaves_the_estimate_where_the_robot_is():
    """A robot that only turns in place stays where it is, but its odometry reads the wheels'
    slip as translation (the simulator's trans-from-rot noise): 40 turns of 45-180 degrees
    walk the odometry's position 0.2-0.8 m off. The dead reckoning takes a commanded turn as
    a turn and stays put, and so does the filter: its mean is not carried along with the slip
    (on the odometry's translation it was off by 0.13-1.1 m, as far as the odometry), its
    particles spread by the slip of a turn in place (`in_place_alpha4`, 1 cm per radian), not
    by the noise of the odometry's reading (alpha4: 0.64-0.83 m of spread after the 40 turns),
    and the compass does not resample them at every turn (`_turn_with_compass`: the mean
    walked 6-10 cm in the 40 turns, 0.4-1.3 cm so)."""
    world = make_world("office", 0)
    start = np.array([*loop_route(world)[0], 0.0])
    odo, est, spread = [], [], []
    for seed in range(6):
        robot = SimRobot(world, SimRobotConfig(image_size=(24, 16)), np.random.default_rng(seed),
                         start_pose=tuple(start))
        rng = np.random.default_rng(seed + 100)
        body = FilteredBody(robot, MissionLocalizer(start, start[None, :2], MissionFilterConfig(), rng,
                                                    np.array([0.01, 0.01, 0.02])))
        turns = np.random.default_rng(seed + 200)  # the same turns whatever the filter draws
        for _ in range(40):
            body.move(turn=float(turns.uniform(np.pi / 4, np.pi) * turns.choice([-1.0, 1.0])))
        odo.append(np.hypot(*robot.odometry()[:2]))
        est.append(np.hypot(*(body.est.pose[:2] - start[:2])))
        spread.append(body.est.spread_m)
        assert np.hypot(*(body.est.dead_reckoning.pose[:2] - start[:2])) < 1e-9
        assert abs(wrap_angle(body.est.pose[2] - robot.true_pose[2])) < np.radians(5)
    assert min(odo) > 0.1, odo
    assert np.median(est) < 0.3 * np.median(odo), (est, odo)
    assert max(est) < 0.03 and max(spread) < 0.3, (est, spread)
