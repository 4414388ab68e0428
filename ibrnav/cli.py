"""`ibrnav`: one console script; each package keeps its own subcommands in its `cli.py`
(a `register(subparsers)` function) and this module only gathers them."""

from __future__ import annotations

import argparse
import sys

from explore import scenic_cli, vueplan_cli
from ibr import cli as ibr_cli
from ibr import render_cli
from ibr.errors import InputError
from ibr.gl import GLContextError
from localization import cli_localize
from ibrnav import bench
from robot import cli as robot_cli
from robot import cli_eval_track, cli_mission, cli_robot


PACKAGE_CLIS = (ibr_cli, render_cli, cli_localize, cli_eval_track, vueplan_cli, scenic_cli, robot_cli, cli_robot, cli_mission, bench)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ibrnav", description="Image-based rendering, localisation and view planning "
        "for robots that see with a camera. Every command records to rerun.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in PACKAGE_CLIS:
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (InputError, GLContextError) as e:  # they name the bad input: no traceback
        print(f"ibrnav {args.command}: error: {e}", file=sys.stderr)
        return 2
