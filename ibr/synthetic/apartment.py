"""`apartment`: 2-4 rooms of different sizes on both sides of a corridor, joined to it by
doorways 0.8-1.2 m wide (and, now and then, to a neighbour), generated from the seed.

Walls have a thickness: each room textures its own face of a wall, and a doorway shows the
wall's depth (jambs, the soffit under the lintel, a threshold). Each room has its own wall
and floor style (painted walls, wallpaper, wood, tiles, carpet) in its own colours; one wall
is plain paint with no texture at all, and one piece of furniture is shiny. Furniture boxes
of varied sizes stand against the walls or free in the room, never in front of a doorway,
and never so close to each other or to a wall that a gap too narrow for the robot forms.

Every seed gives a different layout: the number, sizes, names and sides of the rooms, the
corridor's width and length, the doors, the furniture, the textures, and the whole plan's
orientation (a multiple of 90 degrees). The floor plan is the world's ground truth:
`rooms`, `doorways` and `free_space` (see `SyntheticWorld`).

Local frame while building: the corridor runs along +x at y in [-w/2, w/2], rooms north
(+y) and south (-y) of it; the result is turned and centred on the origin.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import shapely

from ibr.mesh_renderer import Light
from ibr.synthetic import textures
from ibr.synthetic.builder import QuadMeshBuilder
from ibr.synthetic.world import Doorway, Room, SyntheticWorld

# Sizes that belong to the robot the worlds are made for (a disc of radius <= 0.25 m, the
# capture robot's), not to any one world:
ROBOT_DIAMETER_M = 0.5
DOOR_CLEARANCE_M = 0.8
"""Floor kept free of furniture in front of each doorway, on both sides (m): the robot's
diameter and 0.3 m to line up with the opening."""
DOOR_SIDE_M = 0.25
"""The kept-free zone reaches this far past each jamb (m)."""
FURNITURE_GAP_M = ROBOT_DIAMETER_M + 0.1
"""Furniture stands against a wall or at least this far from walls and other furniture
(m), so every gap lets the robot through and no unreachable pocket forms."""
JAMB_M = 0.3
"""Least wall between a doorway and a room's corner (m): room for the door's frame and
for the kept-free zone beside the jambs."""
TEXELS_PER_M = 120
"""Texture resolution (texels per metre): 4 cm marks span ~5 texels; an apartment's
surfaces fill a 4096-wide atlas about 1,000-2,100 texels high over seeds 0-19 (the
office's is 2,070 at 160 texels/m), for 110-290 triangles."""

ROOM_NAMES = ("living_room", "bedroom", "kitchen", "study")  # by decreasing floor area

# name: (width along the wall, depth from the wall, height) ranges in m, placement
# ("wall": its back against a wall, "free": standing in the room, "any": either), specular
FURNITURE = {
    "sofa": ((1.6, 2.4), (0.8, 0.95), (0.75, 0.9), "wall", 0.0),
    "table": ((0.8, 1.6), (0.8, 1.0), (0.7, 0.78), "free", 0.3),
    "shelf": ((0.8, 1.8), (0.3, 0.4), (1.6, 2.1), "wall", 0.0),
    "armchair": ((0.7, 0.9), (0.7, 0.9), (0.8, 1.0), "any", 0.0),
    "cabinet": ((0.5, 0.9), (0.5, 0.6), (1.7, 2.0), "wall", 1.0),  # lacquered: shiny
    "bed": ((1.4, 2.0), (1.9, 2.1), (0.45, 0.6), "wall", 0.0),
    "wardrobe": ((1.0, 1.8), (0.55, 0.65), (1.9, 2.2), "wall", 0.0),
    "desk": ((1.0, 1.6), (0.6, 0.8), (0.72, 0.78), "wall", 0.0),
    "crate": ((0.4, 0.8), (0.4, 0.8), (0.4, 1.0), "any", 0.0),
    "counter": ((1.6, 2.8), (0.6, 0.65), (0.88, 0.92), "wall", 0.2),
    "fridge": ((0.6, 0.7), (0.6, 0.7), (1.7, 1.9), "wall", 1.0),  # steel: shiny
}
ROOM_FURNITURE = {
    "living_room": ("sofa", "cabinet", "shelf", "table", "armchair", "crate"),
    "bedroom": ("bed", "wardrobe", "desk", "crate"),
    "kitchen": ("counter", "fridge", "table", "crate"),
    "study": ("desk", "shelf", "armchair", "crate"),
    "corridor": (),
}
WALL_KINDS = (textures.painted_wall, textures.wallpaper)
FLOOR_KINDS = (textures.wood_floor, textures.floor_tiles, textures.carpet)


@dataclass
class _Region:
    """A room or the corridor while building: its floor box (x0, y0, x1, y1), local frame."""

    name: str
    kind: str
    box: tuple[float, float, float, float]
    wall: object = None  # texture of its walls
    floor: object = None  # texture of its floor


@dataclass
class _Door:
    """A doorway while building: `axis` 0 if the wall runs along y (normal along x), 1 if
    along x; the opening spans `lo`..`hi` along the wall and `face0`..`face1` across it."""

    axis: int
    lo: float
    hi: float
    face0: float
    face1: float
    rooms: tuple[str, str]

    @property
    def width(self) -> float:
        return self.hi - self.lo

    def opening(self, reach: float = 0.0) -> shapely.Polygon:
        """The opening's floor, reaching `reach` into the rooms on both sides."""
        a, b = self.face0 - reach, self.face1 + reach
        return shapely.box(a, self.lo, b, self.hi) if self.axis == 0 else shapely.box(self.lo, a, self.hi, b)

    def doorway(self) -> Doorway:
        mid = (self.lo + self.hi) / 2, (self.face0 + self.face1) / 2
        centre = (mid[1], mid[0]) if self.axis == 0 else mid
        normal = (1.0, 0.0) if self.axis == 0 else (0.0, 1.0)
        return Doorway(centre, self.width, self.rooms, normal, self.face1 - self.face0)


def make_apartment(seed: int = 0, texels_per_m: float = TEXELS_PER_M) -> SyntheticWorld:
    """The apartment of `seed`. `texels_per_m` only sets the textures' resolution (a few
    texels per metre make a geometry-only world fast for tests); the layout, the floor plan
    and the light are the same at any value."""
    rng = np.random.default_rng(seed)
    height = rng.uniform(2.4, 2.8)
    door_height = rng.uniform(2.0, 2.15)
    regions, doors = _floor_plan(rng)
    _style(regions, rng)
    zones = {r.name: [] for r in regions}
    for d in doors:
        for name in d.rooms:
            zones[name].append(d.doorway().zone(DOOR_CLEARANCE_M, DOOR_SIDE_M))
    floor = shapely.union_all([shapely.box(*r.box) for r in regions]
                              + [d.opening(reach=0.01) for d in doors])
    pieces = _furnish(regions, zones, floor, rng)
    b = QuadMeshBuilder()
    plain = _plain_wall(regions, doors, rng)
    for r in regions:
        _room_shell(b, r, doors, height, door_height, plain)
    for d in doors:
        _door_reveal(b, d, regions, door_height)
    for box, h, spec, tex in pieces:
        b.box((box[0], box[1], 0.0), (box[2], box[3], h), tex, spec)
    # turn by a multiple of 90 degrees (exactly) and centre on the origin
    k = int(rng.integers(4))
    c, s = (1, 0, -1, 0)[k], (0, 1, 0, -1)[k]
    turn = np.array([[c, -s], [s, c]], float)
    corners = np.array(floor.bounds).reshape(2, 2) @ turn.T
    shift = -(corners.min(axis=0) + corners.max(axis=0)) / 2
    turn3 = np.eye(3)
    turn3[:2, :2] = turn
    for q in b.quads:
        q.origin = turn3 @ q.origin + np.r_[shift, 0.0]
        q.u_edge, q.v_edge = turn3 @ q.u_edge, turn3 @ q.v_edge

    def place(geom):
        return shapely.transform(geom, lambda xy: xy @ turn.T + shift)

    def place_doorway(d: Doorway) -> Doorway:
        centre, normal = turn @ d.centre + shift, turn @ d.normal
        return Doorway(tuple(centre.tolist()), d.width, d.rooms, tuple(normal.tolist()), d.thickness)

    free = floor.difference(shapely.union_all([shapely.box(*p[0]) for p in pieces]))
    azimuth = rng.uniform(0, 2 * np.pi)
    mesh = b.build(rng, texels_per_m=texels_per_m)
    sun = (0.4 * np.cos(azimuth), 0.4 * np.sin(azimuth), 0.92)  # high, from a seeded side
    return SyntheticWorld(
        "apartment", seed, mesh, place(free),
        Light(position=sun, directional=True, ambient=0.55, diffuse=0.45),
        background=(0.0, 0.0, 0.0), view_height_m=1.2,
        rooms=[Room(r.name, place(shapely.box(*r.box)), r.kind) for r in regions],
        doorways=[place_doorway(d.doorway()) for d in doors])


# --- floor plan ------------------------------------------------------------------

def _floor_plan(rng: np.random.Generator) -> tuple[list[_Region], list[_Door]]:
    """Rooms in one or two rows along a corridor, each with a doorway onto it, and now and
    then a doorway between two neighbours; all walls of one thickness. Returns the regions
    (rooms, then the corridor) and the doors."""
    n = int(rng.integers(2, 5))
    width = rng.uniform(1.2, 1.6)  # corridor
    t = rng.uniform(0.1, 0.2)  # wall thickness
    sizes = _room_sizes(rng, n)
    names = ROOM_NAMES[:n]
    north = int(rng.integers(max(0, n - 3), min(n, 3) + 1))
    side = rng.permutation([1] * north + [-1] * (n - north))
    order = rng.permutation(n)  # rooms along the corridor
    rows = {sgn: [i for i in order if side[i] == sgn] for sgn in (1, -1)}
    length = {sgn: sum(sizes[i][0] for i in row) + t * max(0, len(row) - 1) for sgn, row in rows.items()}
    longest = max(length.values())
    regions, doors = [], []
    for sgn, row in rows.items():
        x = rng.uniform(0, longest - length[sgn])
        y_near = width / 2 + t  # the room's wall on the corridor side
        prev = None
        for i in row:
            w, d = sizes[i]
            box = (x, y_near, x + w, y_near + d) if sgn > 0 else (x, -y_near - d, x + w, -y_near)
            regions.append(_Region(names[i], "room", box))
            dw = rng.uniform(0.8, 1.2)
            lo = rng.uniform(x + JAMB_M, x + w - JAMB_M - dw)
            if sgn > 0:  # rooms[0] -> rooms[1] runs along +y
                doors.append(_Door(1, lo, lo + dw, width / 2, y_near, ("corridor", names[i])))
            else:
                doors.append(_Door(1, lo, lo + dw, -y_near, -width / 2, (names[i], "corridor")))
            if prev is not None and rng.random() < 0.35:  # a door to the neighbour
                shared = min(d, sizes[prev][1])
                dw = rng.uniform(0.8, 1.2)
                off = rng.uniform(y_near + JAMB_M, y_near + shared - JAMB_M - dw)
                lo2, hi2 = (off, off + dw) if sgn > 0 else (-off - dw, -off)
                doors.append(_Door(0, lo2, hi2, x - t, x, (names[prev], names[i])))
            prev = i
            x += w + t
    x0 = -(rng.uniform(0.5, 1.5) if rng.random() < 0.5 else 0.0)
    x1 = longest + (rng.uniform(0.5, 1.5) if rng.random() < 0.5 else 0.0)
    regions.append(_Region("corridor", "corridor", (x0, -width / 2, x1, width / 2)))
    return regions, doors


def _room_sizes(rng: np.random.Generator, n: int) -> list[tuple[float, float]]:
    """n (width along the corridor, depth) pairs in metres, whose floor areas differ from
    each other by at least 15%, largest first."""
    while True:
        sizes = [(rng.uniform(2.6, 5.2), rng.uniform(2.6, 4.8)) for _ in range(n)]
        area = np.sort([w * d for w, d in sizes])
        if np.all(area[1:] >= 1.15 * area[:-1]):
            return sorted(sizes, key=lambda s: -s[0] * s[1])


def _style(regions: list[_Region], rng: np.random.Generator) -> None:
    """Each region's wall and floor texture: kinds dealt so neighbours in the list differ,
    colours drawn per region."""
    walls = rng.permutation(len(regions))
    floors = rng.permutation(len(regions))
    for i, r in enumerate(regions):
        wall_kind = WALL_KINDS[walls[i] % len(WALL_KINDS)]
        floor_kind = FLOOR_KINDS[floors[i] % len(FLOOR_KINDS)]
        r.wall = functools.partial(wall_kind, color=tuple(int(v) for v in rng.integers(140, 235, 3)))
        r.floor = functools.partial(floor_kind, color=tuple(int(v) for v in rng.integers(70, 200, 3)))


# --- furniture -------------------------------------------------------------------

def _furnish(regions: list[_Region], zones: dict, floor: shapely.Geometry,
             rng: np.random.Generator) -> list[tuple[tuple, float, float, object]]:
    """Furniture for every room: (footprint box, height, specular, texture) per piece.
    Each piece of the room's list is kept with probability 0.8 and tried at 30 random
    places; one that fits nowhere is left out. At least one piece is shiny."""
    pieces = []
    for r in regions:
        placed = []
        for kind in ROOM_FURNITURE[r.kind if r.kind == "corridor" else r.name]:
            if rng.random() > 0.8:
                continue
            (wmin, wmax), (dmin, dmax), (hmin, hmax), where, spec = FURNITURE[kind]
            size = rng.uniform(wmin, wmax), rng.uniform(dmin, dmax)
            for _ in range(30):
                box = _try_place(r.box, size, where, rng)
                if box is not None and _fits(box, r.box, placed, zones[r.name], floor, regions):
                    placed.append(box)
                    color = tuple(int(v) for v in rng.integers(40, 220, 3))
                    pieces.append((box, rng.uniform(hmin, hmax), spec,
                                   functools.partial(textures.furniture, color=color)))
                    break
    if pieces and max(p[2] for p in pieces) < 1.0:  # none shiny: lacquer the tallest
        i = int(np.argmax([p[1] for p in pieces]))
        pieces[i] = (*pieces[i][:2], 1.0, pieces[i][3])
    return pieces


def _try_place(room: tuple, size: tuple[float, float], where: str,
               rng: np.random.Generator) -> tuple | None:
    """A footprint box for a piece of `size` (along the wall, from the wall) in `room`:
    against a random wall (snapped into a corner when it would leave a gap narrower than
    FURNITURE_GAP_M), or free standing FURNITURE_GAP_M from every wall, turned at random.
    None when it cannot fit that way."""
    x0, y0, x1, y1 = room
    g = FURNITURE_GAP_M
    w, d = size
    if where == "free" or (where == "any" and rng.random() < 0.5):
        if rng.random() < 0.5:
            w, d = d, w
        if x1 - x0 - w < 2 * g or y1 - y0 - d < 2 * g:
            return None
        x, y = rng.uniform(x0 + g, x1 - g - w), rng.uniform(y0 + g, y1 - g - d)
        return (x, y, x + w, y + d)
    wall = int(rng.integers(4))  # 0 south, 1 east, 2 north, 3 west
    along = (x0, x1) if wall in (0, 2) else (y0, y1)
    across = (y1 - y0) if wall in (0, 2) else (x1 - x0)
    if across - d < g:  # it would (nearly) span the room
        return None
    spare = along[1] - along[0] - w
    if spare < 0 or 0 < spare < g:  # too long, or it would leave a sliver beside it
        return None
    s = rng.uniform(0, spare)
    if s < g:
        s = 0.0
    elif spare - s < g:
        s = spare
    a0, a1 = along[0] + s, along[0] + s + w
    return {0: (a0, y0, a1, y0 + d), 2: (a0, y1 - d, a1, y1),
            1: (x1 - d, a0, x1, a1), 3: (x0, a0, x0 + d, a1)}[wall]


def _fits(box: tuple, room: tuple, placed: list, zones: list, floor: shapely.Geometry,
          regions: list[_Region]) -> bool:
    """Whether a footprint keeps clear of the doorways' zones, FURNITURE_GAP_M from the
    other pieces, and leaves every room reachable by the robot."""
    fp = shapely.box(*box)
    if any(fp.intersection(z).area > 0 for z in zones):
        return False
    if any(fp.distance(shapely.box(*p)) < FURNITURE_GAP_M for p in placed):
        return False
    free = floor.difference(shapely.union_all([fp, *(shapely.box(*p) for p in placed)]))
    return _traversable(free, regions)


def _traversable(free: shapely.Geometry, regions: list[_Region]) -> bool:
    """The free space is one piece, and so is what a robot centre can reach (the free
    space less ROBOT_DIAMETER_M / 2 and a hair), which reaches into every room."""
    if free.geom_type != "Polygon":
        return False
    reach = free.buffer(-(ROBOT_DIAMETER_M / 2 + 0.01))
    return reach.geom_type == "Polygon" and all(reach.intersects(shapely.box(*r.box)) for r in regions)


# --- mesh ------------------------------------------------------------------------

def _plain_wall(regions: list[_Region], doors: list[_Door], rng: np.random.Generator) -> tuple[str, int]:
    """(room, side) of the textureless wall: a wall with no doorway in a random room."""
    rooms = [r for r in regions if r.kind == "room"]
    r = rooms[int(rng.integers(len(rooms)))]
    sides = [k for k in range(4) if not _doors_on(r, k, doors)] or list(range(4))
    return r.name, int(sides[int(rng.integers(len(sides)))])


def _doors_on(r: _Region, side: int, doors: list[_Door]) -> list[_Door]:
    """The doors in side `side` (0 south, 1 east, 2 north, 3 west) of a region's walls."""
    x0, y0, x1, y1 = r.box
    face = (y0, x1, y1, x0)[side]
    axis = 1 if side in (0, 2) else 0
    return [d for d in doors if d.axis == axis and r.name in d.rooms
            and min(abs(d.face0 - face), abs(d.face1 - face)) < 1e-9]


def _quad_facing(b: QuadMeshBuilder, origin, u, v, facing, texture, specular: float = 0.0) -> None:
    """A quad whose normal (u x v) points along `facing`: u is reversed if it would not."""
    origin, u = np.asarray(origin, float), np.asarray(u, float)
    if np.dot(np.cross(u, v), facing) < 0:
        origin, u = origin + u, -u
    b.quad(origin, u, v, texture, specular)


def _room_shell(b: QuadMeshBuilder, r: _Region, doors: list[_Door], height: float,
                door_height: float, plain: tuple[str, int]) -> None:
    """Floor, ceiling and the four inward faces of a region's walls, with the openings of
    its doorways cut out (a lintel above each)."""
    x0, y0, x1, y1 = r.box
    b.quad((x0, y0, 0), (x1 - x0, 0, 0), (0, y1 - y0, 0), r.floor)
    b.quad((x0, y1, height), (x1 - x0, 0, 0), (0, y0 - y1, 0), "ceiling_tiles")
    corners = ((x0, y0), (x1, y0), (x1, y1), (x0, y1))
    inward = ((0, 1, 0), (-1, 0, 0), (0, -1, 0), (1, 0, 0))
    for side in range(4):
        corner = np.array(corners[side], float)
        k = side % 2  # the coordinate that runs along this wall: x for south/north
        ends = sorted((corners[side][k], corners[(side + 1) % 4][k]))
        texture = (functools.partial(textures.plain_wall, color=r.wall.keywords["color"])
                   if (r.name, side) == plain else r.wall)
        pos = ends[0]
        for lo, hi in [*sorted((d.lo, d.hi) for d in _doors_on(r, side, doors)), (ends[1], ends[1])]:
            for z0, s0, s1 in ((0.0, pos, lo), (door_height, lo, hi)):  # wall, lintel
                if s1 - s0 > 1e-9:
                    p = corner.copy()
                    p[k] = s0
                    u = np.zeros(3)
                    u[k] = s1 - s0
                    _quad_facing(b, (*p, z0), u, (0, 0, height - z0), inward[side], texture)
            pos = hi


def _door_reveal(b: QuadMeshBuilder, d: _Door, regions: list[_Region], door_height: float) -> None:
    """The wall's depth inside a doorway: threshold, two jambs and the soffit."""
    room = next(r for r in regions if r.name == d.rooms[1])
    t = d.face1 - d.face0
    along = np.zeros(3)
    across = np.zeros(3)
    along[1 - d.axis] = 1.0  # the wall runs along y when its normal is x (axis 0)
    across[d.axis] = 1.0

    def point(s, f, z):
        p = np.zeros(3)
        p[1 - d.axis], p[d.axis], p[2] = s, f, z
        return p

    w = d.hi - d.lo
    _quad_facing(b, point(d.lo, d.face0, 0), w * along, t * across, (0, 0, 1), room.floor)
    _quad_facing(b, point(d.lo, d.face0, door_height), w * along, t * across, (0, 0, -1), room.wall)
    _quad_facing(b, point(d.lo, d.face0, 0), t * across, (0, 0, door_height), along, room.wall)
    _quad_facing(b, point(d.hi, d.face0, 0), t * across, (0, 0, door_height), -along, room.wall)
