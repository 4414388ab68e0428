"""`courtyard`: an outdoor site 40 x 40 m with two buildings of different heights
(6 m and 12 m) on paved ground, under a sun; for view planning (VuePlan, scenic routes).
"""

from __future__ import annotations

import numpy as np
import shapely

from ibr.mesh_renderer import Light
from ibr.synthetic.builder import QuadMeshBuilder
from ibr.synthetic.world import Room, SyntheticWorld

HALF = 20.0  # half-size of the site (m)
BUILDINGS = {"low": (-12.0, -6.0, -4.0, 6.0, 6.0), "tall": (4.0, -10.0, 10.0, 2.0, 12.0)}


def make_courtyard(seed: int = 0) -> SyntheticWorld:
    rng = np.random.default_rng(seed)
    b = QuadMeshBuilder()
    b.quad((-HALF, -HALF, 0), (2 * HALF, 0, 0), (0, 2 * HALF, 0), "ground")
    footprints = []
    for x0, y0, x1, y1, h in BUILDINGS.values():
        j = rng.uniform(-0.5, 0.5, 2)
        x0, x1, y0, y1 = x0 + j[0], x1 + j[0], y0 + j[1], y1 + j[1]
        b.box((x0, y0, 0), (x1, y1, h), "facade")
        footprints.append(shapely.box(x0, y0, x1, y1))
    free = shapely.box(-HALF, -HALF, HALF, HALF).difference(shapely.union_all(footprints))
    # the ground is sampled at 20 texels/m through its own (large) quad; facades at 40
    mesh = b.build(rng, texels_per_m=25)
    return SyntheticWorld("courtyard", seed, mesh, free,
                          Light(position=(0.45, 0.3, 0.84), directional=True, ambient=0.5,
                                diffuse=0.55),
                          background=(0.62, 0.76, 0.95), view_height_m=1.6,
                          look_outward=False,
                          rooms=[Room("site", shapely.box(-HALF, -HALF, HALF, HALF), "outdoor")])
