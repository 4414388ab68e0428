"""`ibrnav`: the one console script. Each command is one module of `ibrnav.commands` with
`register(subparsers)` (its flags) and `run(args)`; a command module imports the heavy
library code inside `run`, so `ibrnav --help` stays quick. Global flags: -q / -v set how much
goes to stderr (`ibrnav.log`), --version."""

from __future__ import annotations

import argparse
import importlib
import logging
from importlib.metadata import PackageNotFoundError, version

from ibr.errors import InputError
from ibrnav.log import setup_logging

COMMANDS = ("scene", "render", "sfm", "eval_ibr", "localize", "eval_loc", "eval_track", "drive", "demo",
            "explore", "vueplan", "scenic", "robot_check", "bench", "export")
log = logging.getLogger("ibrnav")


def _version() -> str:
    try:
        return version("ibrnav")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "unknown"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ibrnav", description="Image-based rendering, localisation and view planning "
        "for robots that see with a camera. Every command records to rerun.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    parser.add_argument("-q", "--quiet", action="count", default=0, help="only warnings and errors on stderr")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="debug lines on stderr too")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"ibrnav.commands.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    setup_logging(args.command, args.verbose - args.quiet)
    from ibr.gl import GLContextError

    try:
        return int(args.func(args) or 0)
    except (InputError, GLContextError) as e:  # they name the bad input: no traceback
        log.error("%s", e)
        return 2
