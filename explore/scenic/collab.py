"""Opportunistic collaboration of two cameras (Mendez et al., "Scenic Route Planner",
Sec. 3.3.3). Each agent knows only the other's current pose and grows two trees towards
its goal:

- a *collaborative stereo* tree, whose node costs pair every q_new with the other agent's
  last known pose (eq. 9): a path that keeps a good stereo pair with the standing agent;
- an *SfM* tree, whose node costs pair every q_new with its parent: a path whose
  successive poses make good stereo pairs.

Path costs are the edge-cost integrals (eq. 10). The agents share them and the cheapest
plan decides: a collaborative path means that agent moves while the other holds still
(they form a variable-baseline stereo pair); an SfM path means both move along their SfM
paths towards their own goals. Only the first pose of a path is executed, then everything
is re-planned. With one agent only the SfM tree is grown.
Poses (A, 4): x, y, z (metres), yaw (radians).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from explore.scenic.map import ScenicMap
from explore.scenic.planner import Plan, PlannerConfig, grow_scenic_tree
from explore.scenic.workspace import Workspace

COLLABORATIVE, SFM = "collaborative", "sfm"


@dataclass
class Decision:
    """mode: COLLABORATIVE (only `mover` moves) or SFM (every agent moves);
    next_poses (A, 4); plans: name -> Plan ("collab_<a>", "sfm_<a>"); chosen: the deciding plan."""

    mode: str
    mover: int
    next_poses: np.ndarray
    plans: dict[str, Plan]
    chosen: str


def plan_agents(poses: np.ndarray, prev_poses: np.ndarray | None, goals: np.ndarray,
                particles: np.ndarray, weights: np.ndarray, vmap: ScenicMap, ws: Workspace,
                config: PlannerConfig, rng: np.random.Generator) -> Decision:
    """Grow the collaborative and SfM trees of every agent and pick the cheapest plan.
    goals (A, 4): each agent's goal state; prev_poses (A, 4): where each agent was before
    (the reference of an SfM tree's root), or None."""
    n = len(poses)
    plans: dict[str, Plan] = {}
    for a in range(n):
        prev = None if prev_poses is None or np.allclose(prev_poses[a], poses[a]) else prev_poses[a]
        plans[f"sfm_{a}"] = grow_scenic_tree(poses[a], goals[a], particles, weights, None,
                                             vmap, ws, config, rng, root_reference=prev)
        if n == 2:
            plans[f"collab_{a}"] = grow_scenic_tree(poses[a], goals[a], particles, weights,
                                                    poses[1 - a], vmap, ws, config, rng)
    chosen = min(plans, key=lambda k: plans[k].cost)
    mode, agent = chosen.split("_")
    nxt = np.array(poses, float)
    if mode == "collab":
        nxt[int(agent)] = plans[chosen].first_move(config.step_m, config.yaw_weight_m)
        return Decision(COLLABORATIVE, int(agent), nxt, plans, chosen)
    for a in range(n):
        nxt[a] = plans[f"sfm_{a}"].first_move(config.step_m, config.yaw_weight_m)
    return Decision(SFM, -1, nxt, plans, chosen)
