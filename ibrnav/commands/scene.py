"""`ibrnav scene show SCENE`: log a scene's cameras, images and geometry to rerun."""

from __future__ import annotations

import argparse

from ibrnav import recording

SCENE_HELP = ("a Strecha folder, a COLMAP model folder, a capture folder (ibrnav demo --session) or "
              "synthetic:NAME[?seed=N&views=N&width=W&height=H]")


def run(args: argparse.Namespace) -> int:
    from ibr import viz
    from ibr.scene import load_scene

    scene = load_scene(args.scene)
    recording.rerun_setup(args, "ibrnav_scene_show", "scene.rrd")
    viz.log_scene(scene)
    recording.rerun_teardown(args)
    n_pts = 0 if scene.points is None else len(scene.points)
    print(f"{scene.name}: {len(scene)} views, mesh: {'yes' if scene.mesh is not None else 'no'}, "
          f"{n_pts} points")
    return 0


def register(subparsers) -> None:
    scene = subparsers.add_parser("scene", help="inspect scenes")
    scene_sub = scene.add_subparsers(dest="scene_command", required=True)
    show = scene_sub.add_parser("show", help="log a scene's cameras, images and geometry to rerun")
    show.add_argument("scene", help=SCENE_HELP)
    recording.add_rerun_args(show)
    show.set_defaults(func=run)
