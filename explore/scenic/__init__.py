"""explore.scenic: the Scenic Route Planner (Mendez et al.): a voxel map of points with
covariances, the SMC approximation of the next-best-view cost space, the RRT*-style scenic
planner with stereo-pair costs, two-camera collaboration, the PRM / RRT* baselines, and the
session that runs them with simulated cameras and scores the reconstruction."""

from explore.scenic.baselines import PRMConfig, RRTStarConfig, plan_prm, plan_rrt_star
from explore.scenic.collab import plan_agents
from explore.scenic.cost import NBVConfig, view_costs
from explore.scenic.map import MapConfig, ScenicMap
from explore.scenic.planner import Plan, PlannerConfig, grow_scenic_tree
from explore.scenic.pose import CameraModel
from explore.scenic.reconstruction import StereoConfig, reconstruct_pair
from explore.scenic.session import PLANNERS, ScenicSession, SessionConfig
from explore.scenic.smc import CostSpace, SMCConfig
from explore.scenic.stereo import StereoCostConfig, stereo_cost
from explore.scenic.workspace import Workspace

__all__ = ["PLANNERS", "CameraModel", "CostSpace", "MapConfig", "NBVConfig", "PRMConfig", "Plan", "PlannerConfig",
           "RRTStarConfig", "SMCConfig", "ScenicMap", "ScenicSession", "SessionConfig", "StereoConfig",
           "StereoCostConfig", "Workspace", "grow_scenic_tree", "plan_agents", "plan_prm", "plan_rrt_star",
           "reconstruct_pair", "stereo_cost", "view_costs"]
