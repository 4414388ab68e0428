"""The 2-D site map VuePlan starts from (Blaer & Allen 2009, Sec. 3.1): the free space on
the ground plane as a shapely polygon with holes (obstacle footprints), and the obstacle
boundary whose walls Phase I must see.

Loaders: GeoJSON (a Polygon / MultiPolygon geometry, Feature or FeatureCollection of the
free space), WKT, or a horizontal slice of a mesh (`trimesh.section`): the slice's closed
outlines become obstacle holes in the site's bounding rectangle.

Frame: world metres, z up; the map lies in the z = 0 plane.

Which edges are *walls* (to be covered) is a choice per site: the holes (obstacle
footprints) always are. The exterior ring is a wall for an interior plan (a church floor
plan, a room) but only a site limit for an outdoor site such as `synthetic:courtyard`,
where nothing stands on it; `FloorPlan.exterior_is_wall` says which.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import shapely
import trimesh

from ibr.errors import InputError


class FloorPlanError(InputError):
    """A floor plan file or mesh slice that gives no usable free-space polygon."""


@dataclass(frozen=True)
class FloorPlan:
    """A 2-D site map.

    free_space: shapely Polygon or MultiPolygon of the ground a scanner may stand on
        (metres, z = 0 plane); holes are obstacle footprints.
    exterior_is_wall: true when the exterior ring(s) are walls to be imaged (interiors);
        false when they only limit the site (outdoors).
    """

    free_space: shapely.Polygon | shapely.MultiPolygon
    exterior_is_wall: bool = False

    def polygons(self) -> list[shapely.Polygon]:
        return list(getattr(self.free_space, "geoms", [self.free_space]))

    def boundary_segments(self) -> tuple[np.ndarray, np.ndarray]:
        """All boundary edges of the free space: segments (E, 2, 2) metres and a bool (E,)
        that is true for walls (hole edges, and exterior edges when `exterior_is_wall`)."""
        segs, wall = [], []
        for poly in self.polygons():
            for k, ring in enumerate((poly.exterior, *poly.interiors)):
                c = np.asarray(ring.coords)[:, :2]
                s = np.stack([c[:-1], c[1:]], axis=1)
                s = s[np.linalg.norm(s[:, 1] - s[:, 0], axis=1) > 1e-9]
                segs.append(s)
                wall.append(np.full(len(s), k > 0 or self.exterior_is_wall))
        return np.concatenate(segs), np.concatenate(wall)

    def wall_segments(self) -> np.ndarray:
        """(W, 2, 2) the wall edges Phase I must cover, metres."""
        segs, wall = self.boundary_segments()
        return segs[wall]


def as_free_space(geom: shapely.Geometry, source: str) -> shapely.Polygon | shapely.MultiPolygon:
    """`geom` made a valid 2-D (multi)polygon of free space; FloorPlanError naming `source`
    when nothing of area is left."""
    geom = shapely.make_valid(shapely.force_2d(geom))
    if isinstance(geom, shapely.GeometryCollection) and not isinstance(geom, shapely.MultiPolygon):
        polys = [g for g in geom.geoms if isinstance(g, (shapely.Polygon, shapely.MultiPolygon))]
        geom = shapely.union_all(polys) if polys else shapely.Polygon()
    if not isinstance(geom, (shapely.Polygon, shapely.MultiPolygon)) or geom.is_empty or geom.area <= 0:
        raise FloorPlanError(f"{source}: no free-space polygon with positive area")
    return geom


def load_wkt(path: str | Path, exterior_is_wall: bool = False) -> FloorPlan:
    """A floor plan from a WKT file holding the free-space (Multi)Polygon, metres."""
    try:
        geom = shapely.from_wkt(Path(path).read_text().strip())
    except (OSError, shapely.errors.GEOSException) as e:
        raise FloorPlanError(f"{path}: cannot read a WKT polygon ({e})") from e
    return FloorPlan(as_free_space(geom, str(path)), exterior_is_wall)


def load_geojson(path: str | Path, exterior_is_wall: bool = False) -> FloorPlan:
    """A floor plan from GeoJSON: a (Multi)Polygon geometry, a Feature or a
    FeatureCollection whose polygons are unioned into the free space, metres."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise FloorPlanError(f"{path}: cannot read GeoJSON ({e})") from e
    geoms = data.get("features", [data]) if isinstance(data, dict) else []
    shapes = []
    for g in geoms:
        g = g.get("geometry", g) if isinstance(g, dict) else None
        try:
            shapes.append(shapely.geometry.shape(g))
        except (AttributeError, KeyError, TypeError, ValueError, shapely.errors.GEOSException) as e:
            raise FloorPlanError(f"{path}: not a GeoJSON geometry ({e})") from e
    if not shapes:
        raise FloorPlanError(f"{path}: no GeoJSON geometry found")
    return FloorPlan(as_free_space(shapely.union_all(shapes), str(path)), exterior_is_wall)


def load_floor_plan(path: str | Path, exterior_is_wall: bool = False) -> FloorPlan:
    """GeoJSON (.geojson / .json) or WKT (.wkt / .txt) by extension."""
    suffix = Path(path).suffix.lower()
    if not Path(path).is_file():
        raise FloorPlanError(f"{path}: floor plan file not found")
    if suffix in (".geojson", ".json"):
        return load_geojson(path, exterior_is_wall)
    if suffix in (".wkt", ".txt"):
        return load_wkt(path, exterior_is_wall)
    raise FloorPlanError(f"{path}: floor plan must be .geojson, .json or .wkt")


def floor_plan_from_mesh(mesh: trimesh.Trimesh, height_m: float = 0.5,
                         margin_m: float = 0.0) -> FloorPlan:
    """Slice `mesh` with the plane z = height_m (`trimesh.section`); the closed outlines of
    the slice become obstacle footprints inside the mesh's xy bounding rectangle (grown by
    margin_m), which is the site limit (not a wall)."""
    section = mesh.section(plane_origin=(0.0, 0.0, height_m), plane_normal=(0.0, 0.0, 1.0))
    lo, hi = mesh.bounds[0, :2] - margin_m, mesh.bounds[1, :2] + margin_m
    site = shapely.box(*lo, *hi)
    if section is None:
        return FloorPlan(site, exterior_is_wall=False)
    planar, _ = section.to_2D(to_2D=np.eye(4))  # identity: keep world x, y
    obstacles = [p for p in planar.polygons_full if p.area > 1e-6]
    free = site.difference(shapely.union_all(obstacles)) if obstacles else site
    return FloorPlan(as_free_space(free, "mesh slice"), exterior_is_wall=False)
