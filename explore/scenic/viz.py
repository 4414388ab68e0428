"""Rerun logging for the Scenic Route Planner: the point map (`world/map/points`, coloured by
uncertainty), occupied voxels (`world/voxels`), SMC particles (`world/particles`), planned
paths (`world/plan/path`), the agents' cameras (`world/cameras/<agent>`) and the
reconstruction metrics (`plots/coverage`, `plots/outlier_ratio`, `plots/mean_error_m`)."""

from __future__ import annotations

import numpy as np
import rerun as rr

from explore.scenic.map import ScenicMap
from explore.scenic.pose import CameraModel, camera_at
from ibr.viz import log_camera

PATH_COLOURS = {"sfm": [160, 80, 220], "collab": [255, 200, 0], "prm": [80, 200, 255],
                "rrtstar": [255, 120, 80]}


def log_map(vmap: ScenicMap, max_voxels: int = 20000) -> None:
    """Points (red = uncertain, green = certain by their largest σ) and occupied voxels."""
    if len(vmap):
        lam, _ = vmap.principal_axes()
        s = np.clip(np.sqrt(lam) / 0.2, 0, 1)[:, None]
        colours = ((1 - s) * np.array([60, 220, 60]) + s * np.array([230, 40, 40])).astype(np.uint8)
        rr.log("world/map/points", rr.Points3D(vmap.means, colors=colours, radii=0.015))
    centres = vmap.occupied_centres()[:max_voxels]
    rr.log("world/voxels", rr.Boxes3D(centers=centres, half_sizes=np.full_like(centres, vmap.voxel_m / 2),
                                      colors=[[120, 120, 120, 80]]))


def log_particles(particles: np.ndarray, w: np.ndarray) -> None:
    """SMC particles as points coloured by weight (blue low, yellow high)."""
    s = np.clip(w, 0, 1)[:, None]
    colours = ((1 - s) * np.array([40, 60, 200]) + s * np.array([255, 230, 0])).astype(np.uint8)
    rr.log("world/particles", rr.Points3D(particles[:, :3], colors=colours, radii=0.03))


def log_plans(plans: dict, chosen: str | None = None) -> None:
    """Every tree's path at world/plan/path/<name>; the chosen one drawn thicker."""
    for name, plan in plans.items():
        kind = name.split("_")[0]
        rr.log(f"world/plan/path/{name}", rr.LineStrips3D(
            [plan.path[:, :3]], colors=[PATH_COLOURS.get(kind, [255, 255, 255])],
            radii=0.03 if name == chosen else 0.012))


def log_agents(poses: np.ndarray, images: list, model: CameraModel) -> None:
    """Each agent's camera and latest photo at world/cameras/agent<a>."""
    for a, (q, img) in enumerate(zip(poses, images)):
        log_camera(f"world/cameras/agent{a}", camera_at(q, model), img)


def log_metrics(metrics: dict) -> None:
    """Coverage, outlier ratio and mean inlier error as scalars under plots/."""
    for key, value in metrics.items():
        rr.log(f"plots/{key}", rr.Scalars(value))


def log_report(session, report) -> None:
    """One planning frame of a `ScenicSession`: map, particles, plans (the cheapest highlighted),
    agents and metrics at step `report.frame`."""
    rr.set_time("step", sequence=report.frame)
    log_map(session.map)
    log_particles(session.space.particles, session.space.w)
    plans = report.plans
    if plans:
        log_plans(plans, min(plans, key=lambda k: plans[k].cost))
    log_agents(session.poses, session.images, session.config.camera)
    log_metrics(report.metrics)
