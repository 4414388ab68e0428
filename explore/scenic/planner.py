"""The scenic path planner (Mendez et al., "Scenic Route Planner", Sec. 3.3.1-3.3.2,
Algorithm 1): an RRT grown from x_init (the camera's pose) until it comes within Δq of
x_goal (the peak of the NBV cost space), but with q_rand drawn from the SMC particles of
Sec. 3.2.1 (weighted by w = 1 - C) instead of uniformly from SE(3), so the tree grows through
areas rich in good views. Edges do not cost their length but the path-cost integral

    C_edge = (C_qnew + C_qnear) / 2 · |q_new - q_near|                (10)

with C_q the stereo-pair cost of eq. (9) of a node: against a fixed reference pose (the
other agent, a *collaborative stereo* tree) or against its parent (an *SfM* tree). As in
RRT*, a new node picks, among the collision-free tree nodes near it, the parent that gives
the cheapest path. Edges are checked against the map (`explore.scenic.workspace.segments_free`).
Poses are 4-DoF (x, y, z, yaw), metres and radians.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from explore.scenic.map import ScenicMap
from explore.scenic.pose import forward_axes, pose_distance, steer
from explore.scenic.stereo import StereoCostConfig, stereo_cost
from explore.scenic.workspace import Workspace, segments_free


@dataclass(frozen=True)
class PlannerConfig:
    step_m: float = 0.6
    """Δq: the tree's step (pose distance, metres) and the most a camera moves per frame."""
    max_nodes: int = 250
    """Tree size at which growth stops even if the goal was not reached."""
    goal_bias: float = 0.1
    """Probability that q_rand is the goal itself."""
    near_radius_m: float = 1.2
    """Nodes within this pose distance are candidate parents of q_new (RRT* choose-parent)."""
    yaw_weight_m: float = 1.0
    """Metres of pose distance per radian of yaw (so one step of Δq turns at most Δq / this)."""
    pitch_rad: float = -0.1
    """Camera pitch shared by all poses (radians)."""
    stereo: StereoCostConfig = field(default_factory=StereoCostConfig)
    """Weights and α of the stereo-pair cost."""


@dataclass
class Plan:
    """path (K, 4) poses from the start to the goal (or to the node nearest it); cost: the
    path-cost integral (unreached goals add the remaining distance times the mean node
    cost); reached: whether the tree got within Δq of the goal; nodes: all tree poses."""

    path: np.ndarray
    cost: float
    reached: bool
    nodes: np.ndarray

    @property
    def first_pose(self) -> np.ndarray:
        return self.path[1] if len(self.path) > 1 else self.path[0]

    def first_move(self, step_m: float, yaw_weight_m: float) -> np.ndarray:
        """The pose to execute: along the first edge, at most step_m (Δq) from the start
        (an RRT* edge from choose-parent can be longer than Δq)."""
        return steer(self.path[0].copy(), self.first_pose, step_m, yaw_weight_m)


def node_costs(q: np.ndarray, refs: np.ndarray, occupied: cKDTree | None,
               config: PlannerConfig) -> np.ndarray:
    """C_q (N,) of poses q (N, 4) paired with reference poses refs (N, 4), eq. (9)."""
    q, refs = np.atleast_2d(q), np.atleast_2d(refs)
    return stereo_cost(refs[:, :3], q[:, :3], forward_axes(refs, config.pitch_rad),
                       forward_axes(q, config.pitch_rad), occupied, config.stereo)


def occupied_tree(vmap: ScenicMap) -> cKDTree | None:
    """KD-tree of occupied voxel centres, for G in C_G (None when Vo is empty)."""
    c = vmap.occupied_centres()
    return cKDTree(c) if len(c) else None


def grow_scenic_tree(x_init: np.ndarray, x_goal: np.ndarray, particles: np.ndarray,
                     weights: np.ndarray, reference: np.ndarray | None, vmap: ScenicMap,
                     ws: Workspace, config: PlannerConfig, rng: np.random.Generator,
                     root_reference: np.ndarray | None = None) -> Plan:
    """Algorithm 1 with the stereo edge cost. reference (4,): the other agent's last pose
    (collaborative tree) or None (SfM tree: each node against its parent). root_reference:
    what the root is paired with in an SfM tree (the camera's previous pose; None: C = 0)."""
    occ = occupied_tree(vmap)
    p = np.clip(weights, 0, None)
    p = p / p.sum() if p.sum() > 0 else None
    if reference is not None:
        c_root = float(node_costs(x_init, reference, occ, config)[0])
    elif root_reference is not None:
        c_root = float(node_costs(x_init, root_reference, occ, config)[0])
    else:
        c_root = 0.0
    nodes, parent, c_node, to_come = [np.asarray(x_init, float)], [-1], [c_root], [0.0]
    for _ in range(4 * config.max_nodes):  # attempts; blocked samples add no node
        if len(nodes) >= config.max_nodes:
            break
        Q = np.array(nodes)
        if pose_distance(Q, x_goal, config.yaw_weight_m).min() < config.step_m:
            break
        if rng.random() < config.goal_bias:
            q_rand = x_goal
        else:
            q_rand = particles[rng.choice(len(particles), p=p)]
        i_near = int(np.argmin(pose_distance(Q, q_rand, config.yaw_weight_m)))
        q_new = steer(Q[i_near], q_rand, config.step_m, config.yaw_weight_m)
        d = pose_distance(Q, q_new, config.yaw_weight_m)
        near = np.flatnonzero(d <= max(config.near_radius_m, d[i_near] + 1e-9))
        near = near[segments_free(vmap, ws, Q[near], np.repeat(q_new[None], len(near), 0))]
        if len(near) == 0:
            continue
        refs = np.repeat(reference[None], len(near), 0) if reference is not None else Q[near]
        c_new = node_costs(np.repeat(q_new[None], len(near), 0), refs, occ, config)
        total = np.array(to_come)[near] + 0.5 * (c_new + np.array(c_node)[near]) * d[near]
        j = int(np.argmin(total))
        nodes.append(q_new)
        parent.append(int(near[j]))
        c_node.append(float(c_new[j]))
        to_come.append(float(total[j]))
    return _extract(np.array(nodes), parent, c_node, to_come, x_goal, reference, vmap, ws, occ, config)


def _extract(Q, parent, c_node, to_come, x_goal, reference, vmap, ws, occ, config) -> Plan:
    """Connect the goal to its nearest node (if the edge is free) and trace the path back."""
    d = pose_distance(Q, x_goal, config.yaw_weight_m)
    i = int(np.argmin(d))
    reached = bool(d[i] < config.step_m and segments_free(vmap, ws, Q[i:i + 1], x_goal[None])[0])
    idx = [i]
    while parent[idx[-1]] >= 0:
        idx.append(parent[idx[-1]])
    path = Q[idx[::-1]]
    cost = to_come[i]
    if reached and d[i] > 0:
        ref = reference if reference is not None else Q[i]
        c_goal = float(node_costs(x_goal, ref, occ, config)[0])
        cost += 0.5 * (c_goal + c_node[i]) * d[i]
        path = np.r_[path, x_goal[None]]
    elif not reached:
        cost += float(np.mean(c_node)) * d[i]
    return Plan(path, float(cost), reached, Q)
