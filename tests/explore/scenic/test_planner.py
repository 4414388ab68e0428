"""Scenic tree (Algorithm 1 with stereo edge costs), opportunistic collaboration and the
PRM / RRT* baselines on hand-made maps."""

import numpy as np
import pytest
import shapely

from explore.scenic.baselines import PRMConfig, RRTStarConfig, plan_prm, plan_rrt_star
from explore.scenic.collab import COLLABORATIVE, SFM, plan_agents
from explore.scenic.map import EMPTY, OCCUPIED, MapConfig, ScenicMap
from explore.scenic.planner import PlannerConfig, grow_scenic_tree
from explore.scenic.pose import pose_distance
from explore.scenic.workspace import Workspace, segments_free

WS = Workspace(shapely.box(-3, -3, 3, 3), 0.8, 1.6, clearance_m=0.1)
CFG = PlannerConfig(step_m=0.5, max_nodes=300, pitch_rad=0.0)


def room(wall: bool) -> ScenicMap:
    """Empty 6 x 6 m room; with `wall`, a wall at x = 0 from y = -3 to y = 1."""
    m = ScenicMap.covering([-3, -3, 0], [3, 3, 2.5], MapConfig(voxel_m=0.1))
    m.state[:] = EMPTY
    if wall:
        m.insert(np.repeat([[-2.0, 0, 1.2]], 40, 0),
                 np.c_[np.full(40, 0.05), np.linspace(-2.95, 0.95, 40), np.full(40, 1.2)],
                 np.repeat(1e-4 * np.eye(3)[None], 40, 0))
        m.state[30, :40, :] = OCCUPIED
    return m


START, GOAL = np.array([-2.0, -2.0, 1.2, 0.0]), np.array([2.0, -2.0, 1.2, 0.0])


def test_segments_blocked_by_the_wall():
    m = room(True)
    free = segments_free(m, WS, np.array([START, [-2, 2, 1.2, 0]]), np.array([GOAL, [2, 2, 1.2, 0]]))
    assert free.tolist() == [False, True]


@pytest.mark.parametrize("planner", ["prm", "rrtstar", "scenic"])
def test_planners_go_around_the_wall(planner):
    m = room(True)
    rng = np.random.default_rng(0)
    if planner == "prm":
        plan = plan_prm(START, GOAL, m, WS, CFG, PRMConfig(n_samples=300), rng)
    elif planner == "rrtstar":
        plan = plan_rrt_star(START, GOAL, m, WS, CFG, RRTStarConfig(max_nodes=600), rng)
    else:
        particles = np.c_[rng.uniform(-2.8, 2.8, (400, 2)), np.full(400, 1.2), rng.uniform(-np.pi, np.pi, 400)]
        plan = grow_scenic_tree(START, GOAL, particles, np.ones(400), None, m, WS,
                                PlannerConfig(step_m=0.5, max_nodes=600, pitch_rad=0.0), rng)
    assert plan.reached
    np.testing.assert_allclose(plan.path[0], START)
    np.testing.assert_allclose(plan.path[-1], GOAL)
    assert np.all(segments_free(m, WS, plan.path[:-1], plan.path[1:]))
    assert np.max(plan.path[:, 1]) > 0.95  # it passed the wall's end at y = 1
    if planner != "scenic":  # length minimisers: close to the shortest way round (~8.5 m)
        length = pose_distance(plan.path[:-1], plan.path[1:], CFG.yaw_weight_m).sum()
        assert length < 12.0


def test_scenic_tree_samples_only_particles_and_the_goal():
    """With the particles on one side, the tree grows there: q_rand comes from the SMC set."""
    m = room(False)
    rng = np.random.default_rng(1)
    particles = np.c_[rng.uniform(-2.5, 2.5, 300), rng.uniform(1.5, 2.5, 300), np.full(300, 1.2),
                      rng.uniform(-np.pi, np.pi, 300)]
    plan = grow_scenic_tree(START, np.array([2.0, 2.0, 1.2, 0.0]), particles, np.ones(300), None,
                            m, WS, CFG, rng)
    assert plan.reached
    assert np.mean(plan.nodes[:, 1] > 0.0) > 0.5


def test_collaboration_prefers_the_ideal_stereo_partner():
    """Agent 1 stands where agent 0's goal view makes an ideal pair (d_LI = d_RI = 3 d_B
    on a point of the map): the chosen plan is agent 0 moving while agent 1 holds still."""
    m = room(False)
    target = np.array([0.0, 2.9, 1.2])
    m.insert(np.array([[0.0, 0.0, 1.2]]), target[None], 1e-4 * np.eye(3)[None])
    d_b = 0.5
    h = np.sqrt((3 * d_b) ** 2 - (d_b / 2) ** 2)
    yaw = lambda p: np.arctan2(target[1] - p[1], target[0] - p[0])
    p1, g0 = np.array([d_b / 2, 2.9 - h, 1.2]), np.array([-d_b / 2, 2.9 - h, 1.2])
    agent1 = np.r_[p1, yaw(p1)]
    goal0 = np.r_[g0, yaw(g0)]
    agent0 = goal0 + [-0.3, -0.2, 0, 0]
    goals = np.array([goal0, np.array([2.5, -2.5, 1.2, 0.0])])
    rng = np.random.default_rng(2)
    particles = np.r_[goals, goals]
    d = plan_agents(np.array([agent0, agent1]), None, goals, particles, np.ones(len(particles)),
                    m, WS, CFG, rng)
    assert d.mode == COLLABORATIVE and d.mover == 0 and d.chosen == "collab_0"
    np.testing.assert_allclose(d.next_poses[1], agent1)  # the partner holds still
    assert set(d.plans) == {"sfm_0", "sfm_1", "collab_0", "collab_1"}
    assert d.plans["collab_0"].cost < min(d.plans["sfm_0"].cost, d.plans["sfm_1"].cost)


def test_one_agent_grows_only_the_sfm_tree():
    m = room(False)
    rng = np.random.default_rng(3)
    d = plan_agents(START[None], None, GOAL[None], GOAL[None], np.ones(1), m, WS, CFG, rng)
    assert d.mode == SFM and set(d.plans) == {"sfm_0"}
    assert pose_distance(d.next_poses[0], START, CFG.yaw_weight_m) <= CFG.step_m + 1e-9
