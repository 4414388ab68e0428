"""One simulated run of the Scenic Route Planner's loop (Mendez et al., Sec. 4.1.1): start
from one stereo pair, then every frame i) plan (goal from the SMC cost space, then the
scenic planner with opportunistic collaboration, or a PRM / RRT* baseline to the same goal),
ii) move every moving camera to the first pose of its plan and photograph the synthetic
world, iii) reconstruct the new stereo pairs into the map (the collaborative pair, if the
agents chose to collaborate, and each moved camera's SfM pair with its own previous view), iv) re-weight and resample the
SMC particles, v) score the reconstruction against the world's ground-truth mesh.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from explore.scenic.baselines import PRMConfig, RRTStarConfig, plan_prm, plan_rrt_star
from explore.scenic.collab import COLLABORATIVE, SFM, plan_agents
from explore.scenic.cost import NBVConfig
from explore.scenic.map import MapConfig, ScenicMap
from explore.scenic.metrics import GroundTruth, evaluate
from explore.scenic.planner import Plan, PlannerConfig
from explore.scenic.pose import CameraModel, camera_at
from explore.scenic.reconstruction import StereoConfig, reconstruct_pair
from explore.scenic.smc import CostSpace, SMCConfig
from explore.scenic.workspace import Workspace

PLANNERS = ("scenic", "prm", "rrtstar")


@dataclass(frozen=True)
class SessionConfig:
    agents: int = 2
    """Number of cameras (1 or 2)."""
    planner: str = "scenic"
    """'scenic' (Sec. 3.3), or the baselines 'prm' / 'rrtstar'."""
    inlier_m: float = 0.05
    """d_i: inlier / coverage distance of the metrics (metres)."""
    gt_samples: int = 20000
    """Ground-truth surface samples for the coverage."""
    goal_separation_m: float = 1.5
    """Two agents' goals are at least this far apart (metres)."""
    start_baseline_m: float = 0.5
    """Baseline of the initial stereo pair (metres)."""
    height_band_m: float = 0.4
    """Camera centres stay within this of the world's view height (metres)."""
    wall_margin_m: float = 0.35
    """The navigable region is the world's free floor shrunk by this (metres)."""
    camera: CameraModel = field(default_factory=CameraModel)
    map: MapConfig = field(default_factory=MapConfig)
    nbv: NBVConfig = field(default_factory=NBVConfig)
    smc: SMCConfig = field(default_factory=SMCConfig)
    plan: PlannerConfig = field(default_factory=PlannerConfig)
    prm: PRMConfig = field(default_factory=PRMConfig)
    rrt: RRTStarConfig = field(default_factory=RRTStarConfig)
    stereo: StereoConfig = field(default_factory=StereoConfig)


@dataclass
class FrameReport:
    """frame: index (0 = the initial pair); metrics: coverage / outlier_ratio / mean_error_m;
    poses (A, 4); mode: COLLABORATIVE or SFM; plans: per agent/tree; n_points in the map;
    n_pairs: stereo pairs reconstructed so far; goals (A, 4)."""

    frame: int
    metrics: dict
    poses: np.ndarray
    mode: str
    plans: dict
    n_points: int
    n_pairs: int
    goals: np.ndarray


def initial_poses(world, ws: Workspace, model: CameraModel, baseline_m: float) -> np.ndarray:
    """(2, 4) a parallel stereo pair at the world's view height: the first default camera
    that fits (with its partner baseline_m to its right) inside the workspace."""
    for cam in world.default_cameras(16, model.width, model.height, model.fov_deg):
        f = cam.forward
        yaw = float(np.arctan2(f[1], f[0]))
        right = np.array([np.sin(yaw), -np.cos(yaw), 0.0])
        z = np.clip(cam.center[2], ws.z_min, ws.z_max)
        a = np.r_[cam.center[:2], z]
        b = a + baseline_m * right
        if ws.contains(np.array([a, b])).all():
            return np.array([np.r_[a, yaw], np.r_[b, yaw]])
    raise ValueError(f"no default camera of world {world.name!r} fits its workspace")


class ScenicSession:
    """State of one run: map, SMC cost space, agents' poses and images."""

    def __init__(self, world, config: SessionConfig, rng: np.random.Generator, ctx=None):
        if config.planner not in PLANNERS:
            raise ValueError(f"planner must be one of {PLANNERS}, got {config.planner!r}")
        self.world, self.config, self.rng, self.ctx = world, config, rng, ctx
        lo, hi = world.bounds
        self.map = ScenicMap.covering(lo - 0.2, hi + 0.2, config.map)
        h = world.view_height_m
        self.ws = Workspace(world.free_space.buffer(-config.wall_margin_m),
                            h - config.height_band_m, h + config.height_band_m)
        self.gt = GroundTruth.from_mesh(world.mesh, config.gt_samples, seed=world.seed)
        start = initial_poses(world, self.ws, config.camera, config.start_baseline_m)
        if config.agents == 1:
            self.poses, self.prev = start[1:], start[:1]
        elif config.agents == 2:
            self.poses, self.prev = start.copy(), None
        else:
            raise ValueError(f"agents must be 1 or 2, got {config.agents}")
        for q in start:
            self.map.mark_empty_ball(q[:3], 0.3)
        self.images = [self._photo(q) for q in self.poses]
        self.n_pairs, self.frame = 0, 0
        self._reconstruct(start[0], self._photo(start[0]), start[1], self._photo(start[1]))
        self.space = CostSpace(self.map, self.ws, config.camera, config.nbv, config.smc, rng)

    def _photo(self, q: np.ndarray) -> np.ndarray:
        return self.world.photograph(camera_at(q, self.config.camera), self.ctx)

    def _reconstruct(self, qa, img_a, qb, img_b) -> None:
        if np.linalg.norm(qa[:3] - qb[:3]) < 0.02:
            return  # no baseline, nothing to triangulate
        ca, cb = camera_at(qa, self.config.camera), camera_at(qb, self.config.camera)
        X, cov = reconstruct_pair(ca, cb, img_a, img_b, self.config.stereo)
        self.map.carve(np.repeat(cb.center[None], len(X), 0), X)
        self.map.insert(np.repeat(ca.center[None], len(X), 0), X, cov)
        self.n_pairs += 1

    def report(self, mode: str = SFM, plans: dict | None = None, goals=None) -> FrameReport:
        m = evaluate(self.map.means, self.gt, self.config.inlier_m)
        return FrameReport(self.frame, m, self.poses.copy(), mode, plans or {}, len(self.map),
                           self.n_pairs, np.zeros((0, 4)) if goals is None else goals)

    def plan(self, goals: np.ndarray) -> tuple[str, int, np.ndarray, dict[str, Plan]]:
        """(mode, mover, next poses (A, 4), plans) of the configured planner."""
        c = self.config
        if c.planner == "scenic":
            d = plan_agents(self.poses, self.prev, goals, self.space.particles, self.space.w,
                            self.map, self.ws, c.plan, self.rng)
            return d.mode, d.mover, d.next_poses, d.plans
        plans, nxt = {}, self.poses.copy()
        for a, (q, g) in enumerate(zip(self.poses, goals)):
            if c.planner == "prm":
                plans[f"prm_{a}"] = p = plan_prm(q, g, self.map, self.ws, c.plan, c.prm, self.rng)
            else:
                plans[f"rrtstar_{a}"] = p = plan_rrt_star(q, g, self.map, self.ws, c.plan, c.rrt, self.rng)
            nxt[a] = p.first_move(c.plan.step_m, c.plan.yaw_weight_m)
        return SFM, -1, nxt, plans

    def step(self) -> FrameReport:
        """One frame: plan, move, photograph, reconstruct, resample; its report."""
        goals = self.space.goals(self.poses, self.config.goal_separation_m, self.config.plan.step_m)
        mode, mover, nxt, plans = self.plan(goals)
        images = [self._photo(q) if not np.allclose(q, p) else im
                  for q, p, im in zip(nxt, self.poses, self.images)]
        if mode == COLLABORATIVE:  # the collaborative stereo pair with the agent holding still
            stay = 1 - mover
            self._reconstruct(nxt[stay], images[stay], nxt[mover], images[mover])
        for a in range(len(nxt)):  # every camera that moved also pairs with its own last view (SfM)
            self._reconstruct(self.poses[a], self.images[a], nxt[a], images[a])
        self.prev, self.poses, self.images = self.poses, nxt, images
        self.space.update(self.map)
        self.frame += 1
        return self.report(mode, plans, goals)
