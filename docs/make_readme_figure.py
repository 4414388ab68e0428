"""Regenerate docs/overview.png, the README's picture: photos of the two synthetic worlds
and the demo robot's drive round the office. Run: python docs/make_readme_figure.py"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from ibr.synthetic import loop_route, make_world
from robot.sim_robot import SimRobot
from robot.waypoint_follower import follow_waypoints

office, courtyard = make_world("office", 0), make_world("courtyard", 0)
fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
axes[0].imshow(office.photograph(office.default_cameras(24)[5]))
axes[0].set_title("synthetic:office, a default photo")
axes[1].imshow(courtyard.photograph(courtyard.default_cameras(8)[1]))
axes[1].set_title("synthetic:courtyard")
for ax in axes[:2]:
    ax.axis("off")
route = loop_route(office)
start = np.array([*route[0], 0.0])
robot = SimRobot(office, rng=np.random.default_rng(0), start_pose=start)
legs = [(leg.estimate, robot.true_pose.copy()) for leg in follow_waypoints(robot, route, start)]
est, truth = (np.array(x) for x in zip(*legs))
for poly in getattr(office.free_space, "geoms", [office.free_space]):
    for ring in (poly.exterior, *poly.interiors):
        axes[2].plot(*np.asarray(ring.coords).T, "k-", lw=1)
axes[2].plot(*truth[:, :2].T, "g.-", label="true path")
axes[2].plot(*est[:, :2].T, "b.-", label="compass dead reckoning")
axes[2].set_aspect("equal")
axes[2].legend(loc="upper right", fontsize=8)
axes[2].set_title("ibrnav demo: the robot's loop (m)")
plt.tight_layout()
plt.savefig(Path(__file__).with_name("overview.png"), dpi=80)
