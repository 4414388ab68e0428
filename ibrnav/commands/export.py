"""`ibrnav export SCENE --colmap DIR --mesh FILE.ply|.obj`: the scene's model in formats
users already have tools for (`ibr.export`): a COLMAP model folder (cameras, images, points
with tracks, the photos and the mesh) and the proxy mesh, textured from the photos. A JSON
summary goes to stdout; `--refine` bundle-adjusts the poses first and reports how far they
moved."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from ibr.errors import InputError
from ibrnav import jsonout
from ibrnav.commands.scene import SCENE_HELP

log = logging.getLogger(__name__)
MAX_ATLAS_PX = 8192
"""Widest texture atlas written (texels): what common GPUs and viewers load; not a scene length."""


def check_outputs(args: argparse.Namespace) -> None:
    """Reject a missing or unwritable output before any heavy work (one clear line)."""
    if not args.colmap and not args.mesh:
        raise InputError("ibrnav export: give --colmap DIR, --mesh FILE.ply|.obj, or both")
    if args.colmap:
        out = Path(args.colmap)
        if out.exists() and not out.is_dir():
            raise InputError(f"--colmap {out}: a file is there; the COLMAP export is a folder")
        if not out.parent.is_dir():
            raise InputError(f"--colmap {out}: its parent folder {out.parent} does not exist")
    if args.mesh:
        from ibr.export import MESH_SUFFIXES

        out = Path(args.mesh)
        if out.suffix.lower() not in MESH_SUFFIXES:
            raise InputError(f"--mesh {out}: unknown mesh type; use one of {', '.join(MESH_SUFFIXES)}")
        if not out.parent.is_dir():
            raise InputError(f"--mesh {out}: folder {out.parent} does not exist")


def textured(mesh, scene):
    """The mesh textured from the scene's photos (`PhotoTexture`), its atlas at most
    MAX_ATLAS_PX wide."""
    import numpy as np

    from localization.photo_texture import PhotoTexture, PhotoTextureConfig

    cols = int(np.ceil(np.sqrt(len(scene))))
    width = min(max(v.camera.width for v in scene.views), MAX_ATLAS_PX // cols)
    texture = PhotoTexture(mesh, scene.cameras, [v.image for v in scene.views], PhotoTextureConfig(cell_width=width))
    return texture.textured_mesh()


def run(args: argparse.Namespace) -> int:
    from ibr.export import export_colmap, export_mesh
    from ibr.proxy.proxy_geometry import build_proxy
    from ibr.scene import load_scene

    check_outputs(args)
    scene = load_scene(args.scene, refine=args.refine)
    summary = {"scene": str(args.scene), "views": len(scene), "poses": scene.meta.get("poses", "given")}
    if "refinement" in scene.meta:
        summary["refinement"] = scene.meta["refinement"]
    mesh, points, colors = scene.mesh, scene.points, scene.point_colors
    if mesh is None or points is None or len(points) == 0:
        log.info(f"{scene.name}: proxy geometry from {len(scene)} photos (cached beside the scene after the first run)")
        proxy = build_proxy(scene)
        mesh = proxy.mesh if mesh is None else mesh
        if points is None or len(points) == 0:
            points, colors = proxy.points, proxy.colors
    summary["faces"], summary["points"] = len(mesh.faces), len(points)
    if args.colmap:
        export_colmap(scene, args.colmap, mesh, points, colors)
        summary["colmap"] = str(args.colmap)
    if args.mesh:
        out = textured(mesh, scene) if not args.no_texture else mesh
        export_mesh(out, args.mesh)
        summary.update(mesh=str(args.mesh), textured=not args.no_texture)
    print(jsonout.dumps(summary))
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("export", help="write a scene as a COLMAP model and/or a (textured) mesh file")
    p.add_argument("scene", help=SCENE_HELP)
    p.add_argument("--colmap", metavar="DIR", help="write a COLMAP model folder here (cameras, images, points, "
                   "photos, mesh.ply); pycolmap.Reconstruction(DIR) and `ibrnav` commands read it")
    p.add_argument("--mesh", metavar="FILE", help="write the mesh (the scene's, else the proxy) as .ply or .obj")
    p.add_argument("--refine", action="store_true", help="bundle-adjust the poses first (pycolmap) and report "
                   "how far they moved")
    p.add_argument("--no-texture", action="store_true", help="write the mesh with vertex colours, not textured "
                   "from the photos")
    p.set_defaults(func=run)
