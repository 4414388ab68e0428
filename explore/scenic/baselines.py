"""The length-minimising planners the Scenic Route Planner is compared with (Mendez et al.,
Sec. 4.1.3): a probabilistic roadmap (PRM, Kavraki et al. 1996) and RRT* (Karaman &
Frazzoli 2011), both given the same goal state (the SMC peak) and the same collision check,
both minimising path length |q_a - q_b| (4-DoF pose distance) to that goal. They return a
`Plan` like the scenic planner, so one executor runs all three.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from explore.scenic.map import ScenicMap
from explore.scenic.planner import Plan, PlannerConfig
from explore.scenic.pose import pose_distance, steer
from explore.scenic.workspace import Workspace, positions_free, segments_free, uniform_positions


@dataclass(frozen=True)
class PRMConfig:
    n_samples: int = 250
    """Roadmap vertices sampled uniformly in the free workspace (besides start and goal)."""
    k_neighbours: int = 10
    """Each vertex is connected to its k nearest (collision-free) neighbours."""


def _sample_free(vmap: ScenicMap, ws: Workspace, n: int, rng: np.random.Generator) -> np.ndarray:
    """n poses (n, 4) uniform over the candidate voxels with uniform yaw."""
    return np.c_[uniform_positions(vmap, ws, n, rng), rng.uniform(-np.pi, np.pi, n)]


def plan_prm(x_init: np.ndarray, x_goal: np.ndarray, vmap: ScenicMap, ws: Workspace,
             planner: PlannerConfig, config: PRMConfig, rng: np.random.Generator) -> Plan:
    """Shortest roadmap path from x_init to x_goal (Dijkstra over k-nearest edges, all
    edges collision-checked in one batch). Unreachable goal: path to the roadmap vertex
    nearest the goal among those reachable."""
    S = _sample_free(vmap, ws, config.n_samples, rng)
    S = S[positions_free(vmap, ws, S)]  # vertices clear of geometry
    V = np.r_[x_init[None], x_goal[None], S]
    emb = np.c_[V[:, :3], planner.yaw_weight_m * np.cos(V[:, 3]), planner.yaw_weight_m * np.sin(V[:, 3])]
    _, nbr = cKDTree(emb).query(emb, k=min(config.k_neighbours + 1, len(V)))
    a = np.repeat(np.arange(len(V)), nbr.shape[1] - 1)
    b = nbr[:, 1:].ravel()
    free = segments_free(vmap, ws, V[a], V[b])
    a, b = a[free], b[free]
    w = pose_distance(V[a], V[b], planner.yaw_weight_m) + 1e-9
    graph = coo_matrix((np.r_[w, w], (np.r_[a, b], np.r_[b, a])), shape=(len(V), len(V))).tocsr()
    dist, pred = dijkstra(graph, indices=0, return_predecessors=True)
    target = 1
    if not np.isfinite(dist[1]):
        reach = np.flatnonzero(np.isfinite(dist))
        target = int(reach[np.argmin(pose_distance(V[reach], x_goal, planner.yaw_weight_m))])
    idx = [target]
    while idx[-1] != 0:
        idx.append(int(pred[idx[-1]]))
    path = V[idx[::-1]]
    return Plan(path, float(dist[target]), target == 1, V)


@dataclass(frozen=True)
class RRTStarConfig:
    max_nodes: int = 250
    """Tree size at which growth stops."""
    goal_bias: float = 0.1
    """Probability that q_rand is the goal."""


def plan_rrt_star(x_init: np.ndarray, x_goal: np.ndarray, vmap: ScenicMap, ws: Workspace,
                  planner: PlannerConfig, config: RRTStarConfig, rng: np.random.Generator) -> Plan:
    """RRT* with q_rand uniform over the free workspace, choose-parent and rewiring within
    `planner.near_radius_m`, edge cost = pose distance; stops once within Δq of the goal."""
    step, yw = planner.step_m, planner.yaw_weight_m
    nodes, parent, cost = [np.asarray(x_init, float)], [-1], [0.0]
    pool = _sample_free(vmap, ws, 4 * config.max_nodes, rng)
    for k in range(4 * config.max_nodes):
        Q = np.array(nodes)
        if len(nodes) >= config.max_nodes or pose_distance(Q, x_goal, yw).min() < step:
            break
        q_rand = x_goal if rng.random() < config.goal_bias else pool[k]
        q_new = steer(Q[int(np.argmin(pose_distance(Q, q_rand, yw)))], q_rand, step, yw)
        d = pose_distance(Q, q_new, yw)
        near = np.flatnonzero(d <= max(planner.near_radius_m, d.min() + 1e-9))
        near = near[segments_free(vmap, ws, Q[near], np.repeat(q_new[None], len(near), 0))]
        if len(near) == 0:
            continue
        total = np.array(cost)[near] + d[near]
        nodes.append(q_new)
        parent.append(int(near[np.argmin(total)]))
        cost.append(float(total.min()))
        better = np.array(cost)[near] > cost[-1] + d[near]            # rewire through q_new
        for j in near[better]:
            parent[j] = len(nodes) - 1
            _shift_subtree(parent, cost, int(j), cost[-1] + float(d[j]) - cost[j])
    Q = np.array(nodes)
    dg = pose_distance(Q, x_goal, yw)
    i = int(np.argmin(dg))
    reached = bool(dg[i] < step and segments_free(vmap, ws, Q[i:i + 1], x_goal[None])[0])
    idx = [i]
    while parent[idx[-1]] >= 0:
        idx.append(parent[idx[-1]])
    path = Q[idx[::-1]]
    if reached:
        path = np.r_[path, x_goal[None]]
    return Plan(path, cost[i] + float(dg[i]), reached, Q)


def _shift_subtree(parent: list, cost: list, root: int, delta: float) -> None:
    """Add delta to the cost-to-come of node `root` and all its descendants (after a rewire)."""
    par = np.array(parent)
    stack = [root]
    while stack:
        n = stack.pop()
        cost[n] += delta
        stack.extend(np.flatnonzero(par == n).tolist())
