"""A synthetic world: ground-truth textured mesh, free-space floor plan and a light, with
a way to photograph it from any camera. Worlds are generated in code from a seed.

World frame: metres, z up, the floor/ground at z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
import trimesh

from ibr.camera import Camera, intrinsics_from_fov
from ibr.mesh_renderer import Light, MeshRenderer


@dataclass(frozen=True)
class Room:
    """One named region of a world's floor plan.

    name: unique in its world ("kitchen", "corridor", "site").
    polygon: its floor inside the walls, furniture included (z = 0 plane, metres).
    kind: "room", "corridor" or "outdoor".
    """

    name: str
    polygon: shapely.Polygon
    kind: str = "room"


@dataclass(frozen=True)
class Doorway:
    """An opening in a wall between two rooms.

    centre: (x, y) middle of the opening, half way through the wall (metres).
    width: clear width of the opening (metres).
    rooms: the names of the two rooms it joins.
    normal: (x, y) unit vector across the wall, from rooms[0] into rooms[1].
    thickness: the wall's thickness, i.e. the depth of the opening (metres).
    """

    centre: tuple[float, float]
    width: float
    rooms: tuple[str, str]
    normal: tuple[float, float]
    thickness: float

    def zone(self, depth_m: float, side_m: float = 0.0) -> shapely.Polygon:
        """The opening, and the floor `depth_m` in front of it on both sides widened by
        `side_m` to the left and right: the area a doorway needs kept clear."""
        n = np.asarray(self.normal)
        t = np.array([-n[1], n[0]])
        c = np.asarray(self.centre)

        def rect(a0, a1, b):  # from a0 to a1 across the wall, +-b along it
            return shapely.Polygon([c + a0 * n - b * t, c + a1 * n - b * t, c + a1 * n + b * t,
                                    c + a0 * n + b * t])

        half, w = self.thickness / 2, self.width / 2
        return shapely.union_all([rect(-half - depth_m, -half, w + side_m), rect(-half, half, w),
                                  rect(half, half + depth_m, w + side_m)])


@dataclass(eq=False)
class SyntheticWorld:
    """name, seed: what `make_world(name, seed)` was called with.
    mesh: ground-truth trimesh (textured; vertex attribute `specular`).
    free_space: shapely (Multi)Polygon of the floor a robot centre may occupy before
        inflating by its radius (z = 0 plane, metres): the rooms' floors and the doorways
        between them, less the furniture.
    light, background: how photographs are lit, and the RGB in [0, 1] behind the mesh.
    view_height_m: height of the default photo positions (metres).
    look_outward: default photos look out from the free space's centre (a room) rather than
        in at it from a ring around the site (an outdoor site).
    rooms: the floor plan's named regions (a single room, an outdoor site, or an
        apartment's rooms and corridor); empty: one room, the free space's outline.
    doorways: the openings that join the rooms (none in a single-room world).
    """

    name: str
    seed: int
    mesh: trimesh.Trimesh
    free_space: shapely.Polygon | shapely.MultiPolygon
    light: Light
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    view_height_m: float = 1.2
    look_outward: bool = True
    rooms: list[Room] = field(default_factory=list)
    doorways: list[Doorway] = field(default_factory=list)
    _renderers: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        if not self.rooms:
            outline = max(getattr(self.free_space, "geoms", [self.free_space]), key=lambda g: g.area)
            self.rooms = [Room("room", shapely.Polygon(outline.exterior))]

    def room(self, name: str) -> Room:
        """The room called `name`."""
        for r in self.rooms:
            if r.name == name:
                return r
        raise KeyError(f"{self.name} has no room {name!r}; it has {[r.name for r in self.rooms]}")

    def room_at(self, xy) -> str | None:
        """The name of the room whose floor holds the point (x, y), or None (a doorway's
        threshold, a wall, outside)."""
        for r in self.rooms:
            if shapely.contains_xy(r.polygon, float(xy[0]), float(xy[1])):
                return r.name
        return None

    def start_pose(self, rng: np.random.Generator, clearance_m: float = 0.35) -> np.ndarray:
        """A robot start (x, y, theta) drawn from `rng`: a room chosen uniformly (not the
        corridor when there are rooms), a position in its free space at least
        `clearance_m` from walls and furniture (a robot's radius and a margin; it does not
        depend on the world), and a uniform heading."""
        rooms = [r for r in self.rooms if r.kind != "corridor"] or self.rooms
        order = rng.permutation(len(rooms))
        free = self.free_space.buffer(-clearance_m)
        for i in order:
            region = free.intersection(rooms[i].polygon)
            if region.area < 1e-4:
                continue
            x0, y0, x1, y1 = region.bounds
            while True:
                x, y = rng.uniform((x0, y0), (x1, y1))
                if shapely.contains_xy(region, x, y):
                    return np.array([x, y, rng.uniform(-np.pi, np.pi)])
        raise ValueError(f"{self.name}: no room has free space {clearance_m} m from its walls")

    def renderer(self, ctx=None) -> MeshRenderer:
        """The mesh renderer of this world on `ctx` (the shared context by default), cached."""
        key = id(ctx)
        if key not in self._renderers:
            self._renderers[key] = MeshRenderer(self.mesh, ctx, background=self.background)
        return self._renderers[key]

    def photograph(self, camera: Camera, ctx=None) -> np.ndarray:
        """The lit photo (H, W, 3) uint8 that `camera` takes of this world."""
        return self.renderer(ctx).render(camera, self.light).color

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) axis-aligned bounds of the mesh, metres."""
        return self.mesh.bounds

    def _ring(self) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """An outdoor site's photo ring about the free space's centre: its radius (metres, 40 %
        of the site's size), the point (3,) its photos look at, and `_ring_depths`' headings
        and depths along it."""
        centre = np.array(self.free_space.centroid.coords[0])
        radius, look_at = 0.4 * np.ptp(self.bounds[:, :2], axis=0).max(), np.r_[centre, 0.25 * self.bounds[1, 2]]
        return (radius, look_at, *_ring_depths(self.mesh, centre, radius, look_at, self.view_height_m))

    def default_view_count(self) -> int:
        """Photos of `default_cameras` when a scene names no count: 24 indoors; outdoors as
        many as the ring needs for no step to turn the view ahead by more than
        `RING_STEP_DEG` (the courtyard's seeds 0-10: 54-59)."""
        if self.look_outward:
            return 24
        radius, _, headings, depth = self._ring()
        return int(np.ceil(_ring_turn(headings, depth, radius)[-1] / np.radians(RING_STEP_DEG)))

    def default_cameras(self, n: int, width: int = 640, height: int = 480,
                        fov_deg: float = 60.0) -> list[Camera]:
        """`n` photo cameras at `view_height_m`, with a little seeded jitter: overlapping
        neighbours, as a person walking around with a camera would take them. Indoors
        they stand in the free space looking out from its centre; outdoors they stand on
        a ring at 40% of the site's size about its centre, looking in at it, in steps
        that each turn the view of the surface ahead by the same angle (`_ring_headings`:
        short steps past a near building, long ones across open ground). Evenly spaced,
        the courtyard's old ring of 24 stood 3-6 m apart, some 2-4 m from a building, and
        10 of its photos saw the surface at their centre from no other photo within 30
        degrees, beyond which SIFT seldom matches (`localization.mapped_share` measures
        this per view); with `default_view_count` photos every one does. With several rooms
        the cameras are shared out over the rooms by floor area, and in each room they
        stand back from its middle and look across it at its walls."""
        rng = np.random.default_rng(self.seed + 1000)
        K = intrinsics_from_fov(fov_deg, width, height)
        if len(self.rooms) > 1:
            return self._room_cameras(n, K, width, height, rng)
        centre = np.array(self.free_space.centroid.coords[0])
        inner = self.free_space.buffer(-0.5)
        if self.look_outward:
            yaws = 2 * np.pi * np.arange(n) / n
        else:
            radius, look_at, headings, depth = self._ring()
            yaws = _ring_headings(headings, depth, radius, n)
        cams = []
        for i, yaw in enumerate(yaws):
            yaw = yaw + rng.normal(0, 0.05)
            d = np.array([np.cos(yaw), np.sin(yaw)])
            if self.look_outward:
                xy = _stand_point(inner, centre, d) + rng.normal(0, 0.05, 2)
                target = np.r_[xy + 3 * d, self.view_height_m - 0.2]
            else:
                xy = centre + radius * d + rng.normal(0, 0.05, 2)
                target = look_at
            eye = np.r_[xy, self.view_height_m + rng.normal(0, 0.05)]
            cams.append(Camera.look_at(eye, target, K, width, height, name=f"view_{i:03d}"))
        return cams

    def _room_cameras(self, n: int, K: np.ndarray, width: int, height: int,
                      rng: np.random.Generator) -> list[Camera]:
        """`default_cameras` of a world with several rooms: each room's share of `n`
        (by floor area, at least one while there are cameras left) on headings around the
        room, each standing 35% of the way from the room's middle to the wall behind it. In
        a long room (a corridor) the middles are spread along its length and the cameras
        look along it."""
        area = np.array([r.polygon.area for r in self.rooms])
        share = _apportion(n, area)
        cams = []
        for room, k in zip(self.rooms, share):
            floor = self.free_space.intersection(room.polygon)
            inners = [g for g in (floor.buffer(-m) for m in (0.5, 0.3)) if g.area > 1e-3] + [floor]
            ends, aspect = _long_axis(room.polygon)
            axis = np.arctan2(*(ends[1] - ends[0])[::-1])
            phase = rng.uniform(0, 2 * np.pi)
            for i in range(k):
                centre = ends[0] + (i + 0.5) / k * (ends[1] - ends[0])
                if aspect > 2:  # a corridor: look along it, both ways, not at the wall beside
                    yaw = axis + np.pi * (i % 2) + rng.uniform(-0.5, 0.5)
                else:
                    yaw = phase + 2 * np.pi * i / k + rng.normal(0, 0.05)
                d = np.array([np.cos(yaw), np.sin(yaw)])
                xy, inner = None, floor
                for inner in inners:  # the widest margin that leaves a place on the ray
                    try:
                        xy = _stand_point(inner, centre, -d)
                        break
                    except ValueError:
                        continue
                if xy is None:  # furniture covers the whole ray: anywhere in the room
                    xy = np.array(floor.representative_point().coords[0])
                jitter = rng.normal(0, 0.05, 2)
                if shapely.contains_xy(inner, *(xy + jitter)):
                    xy = xy + jitter
                target = np.r_[xy + 3 * d, self.view_height_m - 0.2]
                eye = np.r_[xy, self.view_height_m + rng.normal(0, 0.05)]
                cams.append(Camera.look_at(eye, target, K, width, height,
                                           name=f"view_{len(cams):03d}"))
        return cams


RING_STEP_DEG = 15.0
"""Largest turn (degrees) of the view of the surface ahead between neighbouring photos of an
outdoor ring: half of the 30 degrees beyond which SIFT seldom matches
(`localization.mapped_share.MappedShareConfig.max_angle_deg`), so that a point between two
neighbours is seen by photos on both sides within 30 degrees. A property of the descriptor,
not of a scene."""


def _ring_depths(mesh: trimesh.Trimesh, centre: np.ndarray, radius: float, look_at: np.ndarray,
                 height: float, samples: int = 720) -> tuple[np.ndarray, np.ndarray]:
    """(samples,) headings (radians) of places on a ring of `radius` (metres) about `centre`
    (x, y), and the depth (metres) from each place at `height` along its view to `look_at`
    (3,): to the first surface of `mesh`, or the ring's diameter where the view meets nothing."""
    a = 2 * np.pi * np.arange(samples) / samples
    eyes = np.c_[centre + radius * np.c_[np.cos(a), np.sin(a)], np.full(samples, height)]
    dirs = look_at - eyes
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    hits, rays, _ = mesh.ray.intersects_location(eyes, dirs, multiple_hits=False)
    depth = np.full(samples, 2.0 * radius)
    depth[rays] = np.linalg.norm(hits - eyes[rays], axis=1)
    return a, depth


def _ring_turn(headings: np.ndarray, depth: np.ndarray, radius: float) -> np.ndarray:
    """(samples + 1,) cumulative turn (radians) of the view of the surface ahead along the
    ring (`_ring_depths`), from heading 0 to a full circle: each step of length s turns it
    by s / depth."""
    step = radius * np.diff(np.r_[headings, 2 * np.pi])
    return np.concatenate([[0.0], np.cumsum(step / depth)])


def _ring_headings(headings: np.ndarray, depth: np.ndarray, radius: float, n: int) -> np.ndarray:
    """(n,) headings (radians) of `n` photos on the ring (`_ring_depths`), spaced so that every
    step turns the view of the surface ahead by the same angle: a step's length is
    proportional to the depth ahead, as a person walks in shorter steps past a near wall.
    Only ratios of depths enter, no scale of the scene."""
    turn = _ring_turn(headings, depth, radius)
    return np.interp((np.arange(n) + 0.5) / n * turn[-1], turn, np.r_[headings, 2 * np.pi])


def _long_axis(polygon: shapely.Polygon) -> tuple[np.ndarray, float]:
    """(2, 2) ends of a polygon's middle line: the long centre line of its minimum rotated
    rectangle, less half the short side at each end (both the centre for a square); and
    the rectangle's aspect ratio (long side / short side)."""
    corners = np.array(polygon.minimum_rotated_rectangle.exterior.coords)[:4]
    e1, e2 = corners[1] - corners[0], corners[2] - corners[1]
    long, short = (e1, e2) if np.linalg.norm(e1) >= np.linalg.norm(e2) else (e2, e1)
    L, S = np.linalg.norm(long), np.linalg.norm(short)
    u = long / L
    centre = corners.mean(axis=0)
    half = (L - S) / 2
    return np.array([centre - half * u, centre + half * u]), L / S


def _apportion(n: int, weights: np.ndarray) -> np.ndarray:
    """`n` split into integers proportional to `weights` (largest remainders), every
    entry at least 1 while n allows, the largest weights served first."""
    share = np.zeros(len(weights), int)
    order = np.argsort(-weights, kind="stable")
    first = order[: min(n, len(weights))]
    share[first] = 1
    rest = n - share.sum()
    if rest > 0:
        exact = rest * weights / weights.sum()
        share += np.floor(exact).astype(int)
        left = rest - int(np.floor(exact).sum())
        share[np.argsort(-(exact - np.floor(exact)), kind="stable")[:left]] += 1
    return share


def _stand_point(free: shapely.Geometry, centre: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """A point 35% along the outermost free stretch of the ray centre + r * direction."""
    r = np.linspace(0, 60, 1201)
    pts = centre + r[:, None] * direction
    inside = shapely.contains_xy(free, pts[:, 0], pts[:, 1])
    if not inside.any():
        raise ValueError("no free space along a default camera ray")
    last = np.flatnonzero(inside)[-1]
    first = last
    while first > 0 and inside[first - 1]:
        first -= 1
    return pts[first] + 0.35 * (pts[last] - pts[first])
