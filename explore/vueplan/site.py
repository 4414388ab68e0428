"""The site VuePlan plans on: its mesh, its 2-D floor plan, a renderer for the simulated
scanner and the scanner height. A site is a synthetic world (`synthetic:NAME[?seed=N]`: its
mesh, free space and view height) or a mesh file with a floor plan (a GeoJSON / WKT file, or
else a slice of the mesh). Metres."""

from __future__ import annotations

from pathlib import Path

import trimesh

from explore.floorplan import FloorPlan, floor_plan_from_mesh, load_floor_plan
from ibr.errors import InputError
from ibr.mesh_renderer import MeshRenderer
from ibr.scene import parse_scene_spec


class SiteError(InputError):
    """A SITE argument that names no synthetic world or readable mesh."""


def load_site(site: str, floorplan: str | None = None, cover_outer: bool = False, slice_height_m: float = 0.5,
              scan_height_m: float = 1.6) -> tuple[trimesh.Trimesh, FloorPlan, MeshRenderer, float]:
    """(mesh, floor plan, renderer, scanner height m) of `site`. A synthetic world's rooms
    have their exterior ring as a wall; `cover_outer` makes it a wall for any site.
    `floorplan`, `slice_height_m` and `scan_height_m` apply to a mesh file only."""
    if site.startswith("synthetic:"):
        from ibr.synthetic import make_world

        spec = parse_scene_spec(site, synthetic_only=True, allowed=("seed",))
        world = make_world(spec.world, spec.seed())
        indoor = world.look_outward  # rooms: the exterior ring is a wall
        plan = FloorPlan(world.free_space, exterior_is_wall=indoor or cover_outer)
        return world.mesh, plan, world.renderer(), world.view_height_m
    path = Path(site)
    if not path.is_file():
        raise SiteError(f"{site}: not a synthetic:NAME site and no such mesh file")
    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as e:  # trimesh raises many types for bad files
        raise SiteError(f"{site}: cannot read a mesh ({e})") from e
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise SiteError(f"{site}: mesh has no triangles")
    if floorplan:
        plan = load_floor_plan(floorplan, exterior_is_wall=cover_outer)
    else:
        plan = floor_plan_from_mesh(mesh, slice_height_m)
        plan = FloorPlan(plan.free_space, exterior_is_wall=cover_outer)
    return mesh, plan, MeshRenderer(mesh), scan_height_m
