"""Regenerate docs/mission.png, the README's picture of `ibrnav demo`: the capture mission's
photo positions on the world's floor plan (random stage, adaptive stage, goals), the true
path against the robot's estimate, the coverage curve and two of its photos.

Run: ibrnav demo --session CAPTURE --save demo.rrd; python docs/make_mission_figure.py CAPTURE
It reads only the capture folder (robot.session's log.jsonl and photos/)."""

import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from PIL import Image

from ibr.synthetic import make_world

folder = Path(sys.argv[1])
records = [json.loads(line) for line in (folder / "log.jsonl").read_text().splitlines() if line.strip()]
photos = [r for r in records if r["kind"] == "photo"]
evals = [r for r in records if r["kind"] == "evaluation"]
goals = np.concatenate([np.asarray(r["goals"])[:, :2] for r in records if r["kind"] == "goals"] or [np.zeros((0, 2))])
meta = json.loads((folder / "session.json").read_text())["meta"]
world = make_world(meta.get("world", "office"), meta.get("seed", 0))  # the demo's world (an apartment by default)

fig, axes = plt.subplots(1, 4, figsize=(19, 4.4), gridspec_kw={"width_ratios": [1.1, 1.1, 1.3, 1.3]})
ax = axes[0]
for poly in getattr(world.free_space, "geoms", [world.free_space]):
    for ring in (poly.exterior, *poly.interiors):
        ax.plot(*np.asarray(ring.coords).T, "k-", lw=1)
for stage, colour, size in (("localise", "0.7", 2), ("random", "tab:orange", 5), ("goal", "tab:blue", 5)):
    xy = np.array([p["pose"][:2] for p in photos if p.get("stage") == stage] or np.zeros((0, 2)))
    ax.plot(*xy.T, ".", color=colour, ms=size, label=f"{stage} photos ({len(xy)})")
ax.plot(*goals.T, "r*", ms=9, label="goals")
ax.set_aspect("equal")
ax.legend(loc="upper right", fontsize=7)
ax.set_title("photo positions (robot's estimate, m)")

ax = axes[1]
truth = np.array([e["true_pose"][:2] for e in evals])
est = np.array([e["estimate"][:2] for e in evals])
for poly in getattr(world.free_space, "geoms", [world.free_space]):
    for ring in (poly.exterior, *poly.interiors):
        ax.plot(*np.asarray(ring.coords).T, "k-", lw=1)
ax.plot(*truth.T, "g-", lw=1, label="true path")
ax.plot(*est.T, "b.", ms=2, label="estimate")
ax.set_aspect("equal")
ax.legend(loc="upper right", fontsize=7)
ax.set_title("true path vs estimate (m)")

ax = axes[2]
curve = np.array([(e["model_photos"], e["coverage"]) for e in evals])
ax.plot(*curve.T, "b-")
ax.set_xlabel("photos in the model")
ax.set_ylabel("surface coverage")
ax.set_title("coverage of the true mesh")
ax.grid(alpha=0.3)

ax = axes[3]
first = next(p for p in photos if p.get("stage") == "random")
last = [p for p in photos if p.get("stage") == "goal"][-1:] or [photos[-1]]
ax.imshow(np.hstack([np.asarray(Image.open(folder / p["file"]).convert("RGB")) for p in (first, last[0])]))
ax.set_title("a random-stage photo | a goal photo")
ax.axis("off")
plt.tight_layout()
plt.savefig(Path(__file__).with_name("mission.png"), dpi=70)
