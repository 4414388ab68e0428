"""`ibrnav sfm FOLDER`: pose the unposed photos of FOLDER/images with COLMAP (pycolmap); the
model is written to FOLDER/sparse/0, where every other command finds it."""

from __future__ import annotations

import argparse
from pathlib import Path


def run(args: argparse.Namespace) -> int:
    from ibr.proxy.sfm import load_unposed

    scene = load_unposed(args.folder)
    print(f"{args.folder}: {len(scene)} photos posed, {0 if scene.points is None else len(scene.points)} points "
          f"-> {Path(args.folder) / 'sparse' / '0'}")
    return 0


def register(subparsers) -> None:
    f = subparsers.add_parser("sfm", help="pose unposed photos (FOLDER/images) with COLMAP via pycolmap")
    f.add_argument("folder", help="a folder with images/; the model is written to FOLDER/sparse/0")
    f.set_defaults(func=run)
