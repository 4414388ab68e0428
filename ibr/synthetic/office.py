"""`office`: a 6 x 8 m room, 2.6 m high, with textured walls, floor and ceiling, furniture
boxes along the walls, a table in the middle and one shiny cabinet. A robot can drive a
loop around the table (x = +-1.5 m, y = +-2.5 m) clear of all furniture.
"""

from __future__ import annotations

import numpy as np
import shapely

from ibr.mesh_renderer import Light
from ibr.synthetic.builder import QuadMeshBuilder
from ibr.synthetic.world import Room, SyntheticWorld

ROOM_X, ROOM_Y, ROOM_H = 3.0, 4.0, 2.6  # half-width, half-length, height (m)

# name: (x0, y0, x1, y1, height, texture, specular); jittered by the seed
FURNITURE = {
    "desk": (-3.0, 1.0, -2.2, 2.6, 0.75, "furniture", 0.0),
    "cabinet": (2.45, -1.0, 3.0, 0.6, 1.8, "furniture", 1.0),  # the shiny surface
    "shelf": (-1.0, 3.6, 0.8, 4.0, 2.0, "furniture", 0.0),
    "sofa": (-2.5, -4.0, -1.2, -3.3, 0.8, "furniture", 0.0),
    "crate": (1.6, -4.0, 2.6, -3.4, 1.1, "furniture", 0.0),
    "table": (-0.5, -0.6, 0.5, 0.6, 0.7, "furniture", 0.3),
}


def make_office(seed: int = 0) -> SyntheticWorld:
    rng = np.random.default_rng(seed)
    b = QuadMeshBuilder()
    X, Y, H = ROOM_X, ROOM_Y, ROOM_H
    b.quad((-X, -Y, 0), (2 * X, 0, 0), (0, 2 * Y, 0), "wood_floor")
    b.quad((-X, Y, H), (2 * X, 0, 0), (0, -2 * Y, 0), "ceiling_tiles")
    for origin, edge in (((-X, -Y, 0), (0, 2 * Y, 0)), ((-X, Y, 0), (2 * X, 0, 0)),
                         ((X, Y, 0), (0, -2 * Y, 0)), ((X, -Y, 0), (-2 * X, 0, 0))):
        b.quad(origin, edge, (0, 0, H), "painted_wall")  # inward-facing walls
    footprints = []
    for x0, y0, x1, y1, h, tex, spec in FURNITURE.values():
        j = rng.uniform(-0.08, 0.08, 2)
        x0, x1 = np.clip([x0 + j[0], x1 + j[0]], -X, X)
        y0, y1 = np.clip([y0 + j[1], y1 + j[1]], -Y, Y)
        b.box((x0, y0, 0), (x1, y1, h * rng.uniform(0.95, 1.05)), tex, spec)
        footprints.append(shapely.box(x0, y0, x1, y1))
    free = shapely.box(-X, -Y, X, Y).difference(shapely.union_all(footprints))
    return SyntheticWorld("office", seed, b.build(rng, texels_per_m=160), free,
                          Light(position=(0.3, -0.5, H - 0.2), ambient=0.6, diffuse=0.4), background=(0.0, 0.0, 0.0),
                          view_height_m=1.2, rooms=[Room("office", shapely.box(-X, -Y, X, Y))])


def loop_route(world: SyntheticWorld) -> np.ndarray:
    """(5, 2) closed waypoint loop around the table, metres: the demo's drive."""
    return np.array([[-1.5, -2.5], [1.5, -2.5], [1.5, 2.5], [-1.5, 2.5], [-1.5, -2.5]])
